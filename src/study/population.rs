//! The population table: one study per acetabulum (a sweep), summarised per mesh and overall,
//! per method and level: mean MAE, runs that failed, fell back or restarted, catastrophic runs
//! (MAE over 3 mm, the cup more than 5 mm off, or no result), the cup within 1 mm, at the exact
//! catalogue size and within one size; the worst mesh per method; and srvf against its better
//! baseline per mesh and level, paired run by run (`compare`); per method where the cup's
//! error lies (`cup_spread`) and where the results lie as a whole (`frame_shift`). Written as
//! population.csv, population.json and (with the `plots` feature) population.png.

use super::compare::{compare, Comparison, TOLERANCE};
use super::method::StudyMethod;
use super::{Row, StudyError};
use crate::io::write_atomic;
use crate::report::CupCatalogue;
use serde::Serialize;
use std::path::Path;

/// A run is catastrophic above this MAE, mm ...
pub const CATASTROPHIC_MAE_MM: f64 = 3.0;
/// ... or with its cup this far off, mm (or with no result at all).
pub const CATASTROPHIC_CUP_MM: f64 = 5.0;

/// One mesh (or "all") at one method and level.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PopulationRow {
    /// The mesh's name, or "all" for the whole population.
    pub mesh: String,
    /// The method.
    pub method: StudyMethod,
    /// The start's noise level.
    pub level: u32,
    /// Runs.
    pub runs: usize,
    /// Runs with no result (the error says why in the mesh's runs.csv).
    pub failed: usize,
    /// Runs whose result came from a fallback.
    pub fallbacks: usize,
    /// Runs that restarted (from tilted starts or the limb sphere; runs.csv's `restart` and
    /// `restart_cause` say which and why).
    pub restarted: usize,
    /// Mean MAE of the runs with a result, mm.
    pub mae_mean: f64,
    /// Catastrophic runs (MAE over 3 mm, cup over 5 mm off, or failed).
    pub catastrophic: usize,
    /// Runs with the cup within 1 mm of the truth's.
    pub cup_within_1mm: usize,
    /// Runs whose cup's nearest catalogue size is the truth's.
    pub cup_exact_size: usize,
    /// Runs whose cup's nearest catalogue size is the truth's or a neighbour of it.
    pub cup_within_one_size: usize,
}

/// Is this run catastrophic?
pub fn catastrophic(r: &Row) -> bool {
    !(r.error.is_empty()
        && r.mae_mm <= CATASTROPHIC_MAE_MM
        && r.cup_error_mm().abs() <= CATASTROPHIC_CUP_MM)
}

fn summarise(mesh: &str, method: StudyMethod, level: u32, rows: &[&Row]) -> PopulationRow {
    let cat = CupCatalogue::default();
    let ok: Vec<&&Row> = rows.iter().filter(|r| r.error.is_empty()).collect();
    let maes: Vec<f64> = ok.iter().map(|r| r.mae_mm).collect();
    // Runs whose cup's nearest size is at most `steps` catalogue sizes from the truth's.
    let apart = |steps: usize| {
        ok.iter()
            .filter(|r| {
                cat.sizes_apart(r.cup_diameter_mm, r.gt_cup_diameter_mm)
                    .is_some_and(|k| k <= steps)
            })
            .count()
    };
    PopulationRow {
        mesh: mesh.to_string(),
        method,
        level,
        runs: rows.len(),
        failed: rows.len() - ok.len(),
        fallbacks: rows.iter().filter(|r| !r.fallback.is_empty()).count(),
        restarted: rows.iter().filter(|r| !r.restart.is_empty()).count(),
        mae_mean: crate::geom::mean(&maes),
        catastrophic: rows.iter().filter(|r| catastrophic(r)).count(),
        cup_within_1mm: ok.iter().filter(|r| r.cup_error_mm().abs() <= 1.0).count(),
        cup_exact_size: apart(0),
        cup_within_one_size: apart(1),
    }
}

/// Per mesh, method and level, then the same over all meshes ("all"), in that order.
pub fn population_rows(meshes: &[(String, Vec<Row>)]) -> Vec<PopulationRow> {
    let mut keys: Vec<(StudyMethod, u32)> = meshes
        .iter()
        .flat_map(|(_, rows)| rows.iter().map(|r| (r.method, r.level)))
        .collect();
    keys.sort();
    keys.dedup();
    let mut out = Vec::new();
    for (name, rows) in meshes {
        for &(m, l) in &keys {
            let sel: Vec<&Row> = rows
                .iter()
                .filter(|r| r.method == m && r.level == l)
                .collect();
            if !sel.is_empty() {
                out.push(summarise(name, m, l, &sel));
            }
        }
    }
    for &(m, l) in &keys {
        let sel: Vec<&Row> = meshes
            .iter()
            .flat_map(|(_, rows)| rows.iter())
            .filter(|r| r.method == m && r.level == l)
            .collect();
        out.push(summarise("all", m, l, &sel));
    }
    out
}

/// Per mesh (not "all"), in table order, the mean over its levels of `method`'s mean MAE.
fn mesh_means(rows: &[PopulationRow], method: StudyMethod) -> Vec<(String, f64)> {
    let mut out: Vec<(String, Vec<f64>)> = Vec::new();
    for r in rows
        .iter()
        .filter(|r| r.method == method && r.mesh != "all")
    {
        match out.iter_mut().find(|(n, _)| *n == r.mesh) {
            Some((_, v)) => v.push(r.mae_mean),
            None => out.push((r.mesh.clone(), vec![r.mae_mean])),
        }
    }
    out.into_iter()
        .map(|(n, v)| (n, crate::geom::mean(&v)))
        .collect()
}

/// The methods of the table, in order.
fn methods_of(rows: &[PopulationRow]) -> Vec<StudyMethod> {
    let mut methods: Vec<StudyMethod> = rows.iter().map(|r| r.method).collect();
    methods.sort();
    methods.dedup();
    methods
}

/// Per method, the mesh with the highest mean MAE over its levels, and that MAE.
pub fn worst_meshes(rows: &[PopulationRow]) -> Vec<(StudyMethod, String, f64)> {
    methods_of(rows)
        .into_iter()
        .filter_map(|m| {
            mesh_means(rows, m)
                .into_iter()
                // A mesh with no result at some level is counted by its failed runs, not here.
                .filter(|(_, v)| v.is_finite())
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(n, v)| (m, n, v))
        })
        .collect()
}

/// A mesh's name in a sweep, its comparisons and its folder: the file name without the
/// extension and the LibHip "_ac_wo_gap" suffix.
pub fn mesh_name(path: &Path) -> String {
    path.file_stem()
        .map(|s| {
            s.to_string_lossy()
                .trim_end_matches("_ac_wo_gap")
                .to_string()
        })
        .unwrap_or_default()
}

/// Every mesh's comparisons of srvf (and srvf-paper) with its better baseline, mesh by mesh.
pub fn comparisons(meshes: &[(String, Vec<Row>)]) -> Vec<Comparison> {
    meshes
        .iter()
        .flat_map(|(name, rows)| compare(name, rows))
        .collect()
}

/// Write population.csv, population.json (with the comparisons) and then (with `plots`)
/// population.png into `dir`: the rows, and the warning when the picture could not be drawn (the
/// tables are written anyway).
pub fn write_population(
    dir: &Path,
    meshes: &[(String, Vec<Row>)],
    meta: &serde_json::Value,
) -> Result<(Vec<PopulationRow>, Option<String>), StudyError> {
    let rows = population_rows(meshes);
    let werr = |path: &Path, e: String| StudyError::Write {
        path: path.to_path_buf(),
        source: std::io::Error::other(e),
    };
    let p = dir.join("population.csv");
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in &rows {
        w.serialize(r).map_err(|e| werr(&p, e.to_string()))?;
    }
    let bytes = w.into_inner().map_err(|e| werr(&p, e.to_string()))?;
    write_atomic(&p, &bytes).map_err(|e| werr(&p, e.to_string()))?;
    let worst: Vec<serde_json::Value> = worst_meshes(&rows)
        .into_iter()
        .map(|(m, n, v)| serde_json::json!({"method": m, "mesh": n, "mae_mean": v}))
        .collect();
    let p = dir.join("population.json");
    let json = serde_json::json!({
        "study": meta, "meshes": meshes.len(), "rows": rows, "worst": worst,
        "comparison_tolerance": TOLERANCE, "comparisons": comparisons(meshes),
        "cup_spread": super::cup_spread::cup_spread(meshes),
        "frame_shift": super::frame_shift::frame_shifts(meshes),
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| werr(&p, e.to_string()))?;
    write_atomic(&p, text.as_bytes()).map_err(|e| werr(&p, e.to_string()))?;
    #[allow(unused_mut)]
    let mut warning = None;
    #[cfg(feature = "plots")]
    {
        let p = dir.join("population.png");
        let names: Vec<String> = meshes.iter().map(|(n, _)| n.clone()).collect();
        // Per method, each mesh's MAE averaged over its levels (NaN where it has none).
        let series: Vec<(String, Vec<f64>)> = methods_of(&rows)
            .into_iter()
            .map(|m| {
                let means = mesh_means(&rows, m);
                let v = names
                    .iter()
                    .map(|n| means.iter().find(|(x, _)| x == n).map_or(f64::NAN, |p| p.1))
                    .collect();
                (m.name().to_string(), v)
            })
            .collect();
        if let Err(e) =
            crate::report::plots::per_mesh(&names, &series, "mean MAE over levels (mm)", &p)
        {
            warning = Some(format!("population.png not drawn: {e}"));
        }
    }
    Ok((rows, warning))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::Task;

    fn row(method: StudyMethod, level: u32, mae: f64, cup: f64) -> Row {
        let t = Task {
            method,
            level,
            run: 0,
            seed: 1,
        };
        Row {
            mae_mm: mae,
            cup_diameter_mm: cup,
            gt_cup_diameter_mm: 50.0,
            error: String::new(),
            ..Row::failed(&t, "")
        }
    }

    #[test]
    fn a_mesh_is_named_by_its_file_without_the_libhip_suffix() {
        assert_eq!(mesh_name(Path::new("d/m1_lhip_ac_wo_gap.stl")), "m1_lhip");
        assert_eq!(mesh_name(Path::new("d/a02_lhip.stl")), "a02_lhip");
        assert_eq!(mesh_name(Path::new("phantom")), "phantom");
        // Companion: the suffix only counts at the end of the name.
        assert_eq!(mesh_name(Path::new("x_ac_wo_gap_y.stl")), "x_ac_wo_gap_y");
    }

    #[test]
    fn the_comparisons_are_every_meshs_own_and_skip_a_mesh_without_a_baseline() {
        let at = |method, run, mae| Row {
            run,
            ..row(method, 5, mae, 50.0)
        };
        let a: Vec<Row> = (0..3)
            .flat_map(|k| {
                [
                    at(StudyMethod::Srvf, k, 0.9 + 0.01 * k as f64),
                    at(StudyMethod::IcpNormvec, k, 0.5 + 0.01 * k as f64),
                ]
            })
            .collect();
        let b: Vec<Row> = (0..3).map(|k| at(StudyMethod::Srvf, k, 0.4)).collect();
        let c = comparisons(&[("a".into(), a), ("b".into(), b)]);
        assert_eq!(c.len(), 1);
        assert_eq!((c[0].mesh.as_str(), c[0].level, c[0].pairs), ("a", 5, 3));
        assert_eq!(c[0].verdict, crate::study::compare::Verdict::Worse);
        // Companion: the same runs with the roles swapped are not worse.
        let swapped: Vec<Row> = (0..3)
            .flat_map(|k| {
                [
                    at(StudyMethod::IcpNormvec, k, 0.9 + 0.01 * k as f64),
                    at(StudyMethod::Srvf, k, 0.5 + 0.01 * k as f64),
                ]
            })
            .collect();
        let c = comparisons(&[("a".into(), swapped)]);
        assert_eq!(c[0].verdict, crate::study::compare::Verdict::NotWorse);
    }

    #[test]
    fn the_table_counts_what_it_says_and_names_the_worst_mesh() {
        let a = vec![
            row(StudyMethod::Srvf, 1, 0.5, 50.4),
            row(StudyMethod::Srvf, 1, 4.0, 50.9),
            row(StudyMethod::Icp, 1, 0.8, 53.5),
        ];
        let mut b = vec![row(StudyMethod::Srvf, 1, 0.7, 57.0)];
        b.push(Row::failed(
            &Task {
                method: StudyMethod::Srvf,
                level: 1,
                run: 1,
                seed: 2,
            },
            "boom",
        ));
        let rows = population_rows(&[("a".into(), a), ("b".into(), b)]);
        let get = |mesh: &str, m| {
            rows.iter()
                .find(|r| r.mesh == mesh && r.method == m)
                .unwrap()
        };
        let sa = get("a", StudyMethod::Srvf);
        assert_eq!(
            (
                sa.runs,
                sa.catastrophic,
                sa.cup_within_1mm,
                sa.cup_exact_size
            ),
            (2, 1, 2, 2)
        );
        assert!((sa.mae_mean - 2.25).abs() < 1e-12);
        let sb = get("b", StudyMethod::Srvf);
        assert_eq!(
            (sb.runs, sb.failed, sb.catastrophic, sb.cup_exact_size),
            (2, 1, 2, 0)
        );
        let all = get("all", StudyMethod::Srvf);
        assert_eq!((all.runs, all.failed, all.catastrophic), (4, 1, 3));
        // 53.5 mm is nearest 54, the truth's 50 is 50: not the exact size.
        assert_eq!(get("a", StudyMethod::Icp).cup_exact_size, 0);
        let worst = worst_meshes(&rows);
        assert_eq!(worst[0], (StudyMethod::Srvf, "a".to_string(), 2.25));
        // Companion: a run within both bounds is not catastrophic.
        assert!(!catastrophic(&row(StudyMethod::Srvf, 1, 2.9, 54.9)));
        assert!(catastrophic(&row(StudyMethod::Srvf, 1, 2.9, 55.1)));
    }

    #[test]
    fn the_table_counts_restarts_and_cups_within_one_size() {
        // Truth 50 mm: cups nearest 52 (one size up), 48 (one down), 54 (two up) and 50.
        let mut rows: Vec<Row> = [51.2, 48.9, 53.1, 50.2]
            .iter()
            .map(|&cup| row(StudyMethod::Srvf, 1, 0.5, cup))
            .collect();
        rows[0].restart = "+u".into();
        rows[2].restart = "limb sphere".into();
        let table = population_rows(&[("a".into(), rows.clone())]);
        let r = &table[0];
        assert_eq!(
            (r.restarted, r.cup_exact_size, r.cup_within_one_size),
            (2, 1, 3)
        );
        // Companion: the cup two sizes up moved to one size up is counted, and a run that did
        // not restart is not.
        rows[2].cup_diameter_mm = 52.9;
        rows[2].restart.clear();
        let r = &population_rows(&[("a".into(), rows)])[0];
        assert_eq!((r.restarted, r.cup_within_one_size), (1, 4));
    }
}
