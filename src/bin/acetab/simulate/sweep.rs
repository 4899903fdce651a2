//! `acetab simulate` over many meshes: each mesh's study in a folder of its own (resumed where
//! it is there already, made with the same settings), then the population table.

use super::study::Study;
use crate::common::{io_msg, mesh_files};
use acetab::study::compare::{Comparison, Verdict, TOLERANCE};
use acetab::study::cup_spread::cup_spread;
use acetab::study::frame_shift::frame_shifts;
use acetab::study::population::{
    comparisons, mesh_name, worst_meshes, write_population, PopulationRow,
};
use acetab::study::{read_csv, Row};
use std::path::{Path, PathBuf};

/// The meshes of a population sweep (name, path), or none for a single study (one --gt that
/// is a file or "phantom"). A folder gives its .stl, .ply and .obj files, sorted.
pub(super) fn population_meshes(gt: &[String]) -> Result<Vec<(String, PathBuf)>, String> {
    let single = gt.len() == 1 && (gt[0] == "phantom" || !Path::new(&gt[0]).is_dir());
    if single {
        return Ok(Vec::new());
    }
    let mut out: Vec<(String, PathBuf)> = Vec::new();
    for f in mesh_files(gt, "--gt ")? {
        let name = mesh_name(&f);
        if out.iter().any(|(n, _)| *n == name) {
            return Err(format!(
                "--gt: two meshes are named {name:?} ({})",
                f.display()
            ));
        }
        out.push((name, f));
    }
    Ok(out)
}

/// A mesh study a sweep resumes must have been made with the sweep's settings (`Study::settings`):
/// otherwise the population table would mix studies of different settings under this sweep's
/// name. Settings its summary.json does not record (an older version's) are not compared.
fn same_settings(study: &Study, dir: &Path) -> Result<(), String> {
    let path = dir.join("summary.json");
    let text = std::fs::read_to_string(&path).map_err(|e| {
        format!(
            "{}: cannot resume this mesh's study: {e} (its runs.csv is there; remove the folder \
             to run it again)",
            path.display()
        )
    })?;
    let saved: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        format!(
            "{}: cannot resume this mesh's study: not JSON: {e}",
            path.display()
        )
    })?;
    for (key, want) in study.settings() {
        if let Some(had) = saved.pointer(&format!("/study/{key}")) {
            if *had != want {
                return Err(format!(
                    "{}: study.{key} is {had}, this sweep's is {want}: a sweep resumes only with \
                     the settings it was started with (use another --out, or remove {})",
                    path.display(),
                    dir.display()
                ));
            }
        }
    }
    Ok(())
}

/// The sweep: each mesh's study in --out/<name> unless its runs.csv is there already (made with
/// the same settings), then the population table over all of them.
pub(super) fn sweep(
    study: &Study,
    meshes: &[(String, PathBuf)],
    out: &Path,
    json: bool,
) -> Result<(), String> {
    let start = std::time::Instant::now();
    // Every study done before is checked first, so a refused resume runs nothing.
    for (name, _) in meshes {
        let dir = out.join(name);
        if dir.join("runs.csv").is_file() {
            same_settings(study, &dir)?;
        }
    }
    std::fs::create_dir_all(out).map_err(|e| io_msg(out, e))?;
    let mut failed = Vec::new();
    for (k, (name, path)) in meshes.iter().enumerate() {
        let dir = out.join(name);
        if dir.join("runs.csv").is_file() {
            eprintln!("[{}/{}] {name}: done before, skipped", k + 1, meshes.len());
            continue;
        }
        eprintln!("[{}/{}] {name}", k + 1, meshes.len());
        if let Err(e) = study.run(&path.to_string_lossy(), &dir, true) {
            eprintln!("acetab: error: {name}: {e}");
            failed.push(name.clone());
        }
    }
    let mut tables = Vec::new();
    for (name, _) in meshes {
        let p = out.join(name).join("runs.csv");
        if p.is_file() {
            let rows = read_csv(&p).map_err(|e| e.to_string())?;
            // A mesh whose every run failed (now or in the sweep this one resumes) is in the
            // table, its runs counted as failed, and the sweep says so.
            if !rows.is_empty() && rows.iter().all(|r| !r.error.is_empty()) {
                eprintln!(
                    "acetab: error: {name}: all {} runs failed (the first: {}); {} says why",
                    rows.len(),
                    rows[0].error,
                    p.display()
                );
                if !failed.contains(name) {
                    failed.push(name.clone());
                }
            }
            tables.push((name.clone(), rows));
        }
    }
    let meta = serde_json::json!({
        "gt": meshes.iter().map(|(_, p)| p.display().to_string()).collect::<Vec<_>>(),
        "levels": study.cfg.levels, "runs": study.runs, "methods": study.cfg.methods,
        "views": study.cfg.geometry.views.iter().map(|v| v.to_string()).collect::<Vec<_>>(),
        "seed": study.seed, "protocol": study.cfg.protocol, "sweep_seconds": start.elapsed().as_secs_f64(),
        "prior": if study.prior.leave_out { format!("{} without each mesh's subject", study.prior.arg) } else { study.prior.from.clone() },
    });
    let (rows, warning) = write_population(out, &tables, &meta).map_err(|e| e.to_string())?;
    if let Some(w) = warning {
        eprintln!("acetab: warning: {w}");
    }
    if json {
        println!(
            "{}",
            serde_json::to_string(&rows).map_err(|e| e.to_string())?
        );
    } else {
        print_population(&rows, &tables);
    }
    eprintln!(
        "{} meshes in {:.1} s; population table in {}",
        tables.len(),
        start.elapsed().as_secs_f64(),
        out.display()
    );
    if failed.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "the study failed on {} mesh(es): {}",
            failed.len(),
            failed.join(", ")
        ))
    }
}

/// The population table as text: per method and level over all meshes, the worst mesh per
/// method, the paired comparisons, the cup's spread and the results' translation to the truth.
fn print_population(rows: &[PopulationRow], tables: &[(String, Vec<Row>)]) {
    println!(
        "{:<17} {:>5} {:>6} {:>6} {:>9} {:>9} {:>12} {:>11} {:>10} {:>9}",
        "method",
        "level",
        "runs",
        "failed",
        "fallbacks",
        "restarts",
        "catastrophic",
        "cup<=1mm",
        "exact size",
        "+-1 size"
    );
    for r in rows.iter().filter(|r| r.mesh == "all") {
        println!(
            "{:<17} {:>5} {:>6} {:>6} {:>9} {:>9} {:>12} {:>11} {:>10} {:>9}   MAE {:.3} mm",
            r.method.name(),
            r.level,
            r.runs,
            r.failed,
            r.fallbacks,
            r.restarted,
            r.catastrophic,
            r.cup_within_1mm,
            r.cup_exact_size,
            r.cup_within_one_size,
            r.mae_mean
        );
    }
    for (m, mesh, mae) in worst_meshes(rows) {
        println!("worst mesh for {}: {mesh} (mean MAE {mae:.3} mm)", m.name());
    }
    print_comparisons(&comparisons(tables));
    // An SD that too few runs or meshes leave undefined is "n/a", not NaN.
    let mm = |v: f64| {
        if v.is_finite() {
            format!("{v:.2}")
        } else {
            "n/a".to_string()
        }
    };
    for c in cup_spread(tables).iter().filter(|c| c.runs > 0) {
        println!(
            "{} cup error over {} runs on {} meshes: bias {:+.2} mm, SD {} (per acetabulum {}, run to run {}), RMS {:.2}",
            c.method.name(),
            c.runs,
            c.meshes,
            c.bias_mm,
            mm(c.sd_mm),
            mm(c.per_acetabulum_sd_mm),
            mm(c.run_to_run_sd_mm),
            c.rms_mm
        );
    }
    for f in frame_shifts(tables).iter().filter(|f| f.runs > 0) {
        let [x, y, z] = f.mean_mm;
        let [rx, ry, rz] = f.rms_mm;
        println!(
            "{} results' translation to the truth over {} runs on {} meshes (x, y, z): mean {x:+.2}, {y:+.2}, {z:+.2} mm, RMS {rx:.2}, {ry:.2}, {rz:.2}",
            f.method.name(),
            f.runs,
            f.meshes,
        );
        if f.depth_runs > 0 {
            println!(
                "{} results' translation to the truth along their depth axis, before any depth offset, over {} runs: mean {:+.2} mm",
                f.method.name(),
                f.depth_runs,
                f.depth_mean_mm
            );
        }
    }
}

/// Per method and level, how many meshes the paired comparison with the better baseline finds
/// worse than the tolerance beyond the runs' spread (named), within it, and undecided.
fn print_comparisons(all: &[Comparison]) {
    let mut keys: Vec<_> = all.iter().map(|c| (c.method, c.level)).collect();
    keys.sort();
    keys.dedup();
    for (method, level) in keys {
        let here: Vec<&Comparison> = all
            .iter()
            .filter(|c| c.method == method && c.level == level)
            .collect();
        let count = |v| here.iter().filter(|c| c.verdict == v).count();
        let worse: Vec<String> = here
            .iter()
            .filter(|c| c.verdict == Verdict::Worse)
            .map(|c| format!("{} {:.2}x", c.mesh, c.ratio))
            .collect();
        println!(
            "{} against the better baseline, level {level} (paired runs, {TOLERANCE}x): worse {}{}, not worse {}, undecided {}",
            method.name(),
            worse.len(),
            if worse.is_empty() { String::new() } else { format!(" ({})", worse.join(", ")) },
            count(Verdict::NotWorse),
            count(Verdict::Undecided),
        );
    }
}
