//! Writing a study's folder: runs.csv, summary.json (with srvf's paired comparison against its
//! better baseline), errors.png, and one example run per method (the reconstruction coloured by
//! error and one overlay per view).

use super::compare::{compare, TOLERANCE};
use super::population::mesh_name;
use super::runner::ExampleRun;
use super::{summarize, write_csv, Row, StudyError};
use crate::geom::Mesh;
use crate::io::write_atomic;
#[cfg(feature = "plots")]
use crate::report::plots::{box_plots, overlay, OverlayMarks};
use crate::report::{vertex_errors, write_errors_ply};
use std::path::Path;

/// Everything but the examples: the tables, then the box plots. A picture that cannot be drawn
/// does not lose the study: the tables are written first, and the picture's failure comes back
/// as a warning (the returned list), not an error.
pub fn write_tables(
    rows: &[Row],
    dir: &Path,
    meta: &serde_json::Value,
) -> Result<Vec<String>, StudyError> {
    let werr = |p: &Path, e: String| StudyError::Write {
        path: p.to_path_buf(),
        source: std::io::Error::other(e),
    };
    write_csv(rows, &dir.join("runs.csv"))?;
    let summary = summarize(rows);
    // The study's mesh as a sweep names it.
    let mesh = meta["gt"]
        .as_str()
        .map(|g| mesh_name(Path::new(g)))
        .unwrap_or_default();
    let json = serde_json::json!({
        "study": meta, "summary": summary,
        "comparison_tolerance": TOLERANCE, "comparisons": compare(&mesh, rows),
    });
    let p = dir.join("summary.json");
    let text = serde_json::to_string_pretty(&json).map_err(|e| werr(&p, e.to_string()))?;
    write_atomic(&p, text.as_bytes()).map_err(|source| StudyError::Write {
        path: p.clone(),
        source,
    })?;
    #[allow(unused_mut)]
    let mut warnings = Vec::new();
    // A study in which every run failed (a sweep keeps one) has nothing to draw.
    #[cfg(feature = "plots")]
    if !rows.iter().any(|r| r.error.is_empty()) {
        warnings.push("errors.png not drawn: no run has a result".to_string());
    } else if let Err(e) = write_box_plots(rows, dir) {
        warnings.push(format!("errors.png not drawn: {e}"));
    }
    Ok(warnings)
}

/// errors.png: MAE and cup error per level, a box per method.
#[cfg(feature = "plots")]
fn write_box_plots(rows: &[Row], dir: &Path) -> Result<(), StudyError> {
    use super::method::StudyMethod;
    let werr = |p: &Path, e: String| StudyError::Write {
        path: p.to_path_buf(),
        source: std::io::Error::other(e),
    };
    let mut levels: Vec<u32> = rows.iter().map(|r| r.level).collect();
    levels.sort();
    levels.dedup();
    let mut methods: Vec<StudyMethod> = rows.iter().map(|r| r.method).collect();
    methods.sort();
    methods.dedup();
    let series = |f: &dyn Fn(&Row) -> f64| -> Vec<Vec<Vec<f64>>> {
        methods
            .iter()
            .map(|m| {
                levels
                    .iter()
                    .map(|l| {
                        rows.iter()
                            .filter(|r| r.method == *m && r.level == *l)
                            .map(f)
                            .collect()
                    })
                    .collect()
            })
            .collect()
    };
    let names: Vec<&str> = methods.iter().map(|m| m.name()).collect();
    let p = dir.join("errors.png");
    box_plots(
        &[
            ("MAE truth -> reconstruction (mm)", series(&|r| r.mae_mm)),
            ("cup diameter error (mm)", series(&|r| r.cup_error_mm())),
        ],
        &levels,
        &names,
        &p,
    )
    .map_err(|e| werr(&p, e.to_string()))
}

/// The example runs: `example-<method>/reconstruction.ply` and `view<k>.png`; an overlay that
/// cannot be drawn is a warning (the returned list), as in `write_tables`.
pub fn write_examples(
    examples: &[ExampleRun],
    truth: &Mesh,
    dir: &Path,
) -> Result<Vec<String>, StudyError> {
    #[allow(unused_mut)]
    let mut warnings = Vec::new();
    for ex in examples {
        let d = dir.join(format!("example-{}", ex.task.method.name()));
        std::fs::create_dir_all(&d).map_err(|source| StudyError::Write {
            path: d.clone(),
            source,
        })?;
        let p = d.join("reconstruction.ply");
        let err = vertex_errors(&ex.recon.mesh, truth);
        write_errors_ply(&ex.recon.mesh, &err, &p).map_err(|e| StudyError::Write {
            path: p.clone(),
            source: std::io::Error::other(e.to_string()),
        })?;
        #[cfg(feature = "plots")]
        {
            let axis = crate::report::plots::opening_axis(&ex.recon.mesh, &ex.recon.sphere);
            let p = d.join("reconstruction.png");
            if let Err(e) = crate::report::plots::surface_views(
                &ex.recon.mesh,
                &err,
                &axis,
                3.0,
                "error (mm)",
                &p,
                &|p| crate::engine::Kernels::Cpu.render_surface(p).0,
            ) {
                let shown = p.strip_prefix(dir).unwrap_or(&p);
                warnings.push(format!("{} not drawn: {e}", shown.display()));
            }
        }
        #[cfg(feature = "plots")]
        for (k, cam) in ex.sim.cameras.iter().enumerate() {
            let p = d.join(format!("view{k}.png"));
            let marks = OverlayMarks::of_result(
                format!("view {k}"),
                cam,
                &ex.recon.sphere.center_point(),
                ex.recon.cup.catalogue_mm,
                ex.sim.clicks.get(k).map_or(&[], Vec::as_slice),
            );
            if let Err(e) = overlay(
                (cam.width, cam.height),
                None,
                &ex.recon.initial_contours[k].points,
                &ex.recon.final_contours[k].points,
                &ex.sim.observed[k],
                &marks,
                &p,
            ) {
                let shown = p.strip_prefix(dir).unwrap_or(&p);
                warnings.push(format!("{} not drawn: {e}", shown.display()));
            }
        }
    }
    Ok(warnings)
}
