//! `acetab pose-study`: pose refinement in simulation. Cases whose oblique views' poses are off
//! by --deg and --mm, reconstructed with and without the per-view pose refinement.

use crate::common::{count_in, load_truth, threads_or_all, MAX_RUNS, MAX_THREADS};

#[derive(clap::Args)]
pub struct PoseStudyArgs {
    /// Ground truth mesh or "phantom".
    #[arg(long, default_value = "phantom")]
    pub gt: String,
    /// Runs, each with its own pose errors and start.
    #[arg(long, default_value_t = 10, value_parser = count_in(1, MAX_RUNS))]
    pub runs: usize,
    /// Rotation error of views 1 and 2, degrees (0 to 180), about a random axis through the
    /// object.
    #[arg(long, default_value_t = 2.0)]
    pub deg: f64,
    /// Translation error of views 1 and 2, mm, in a random direction.
    #[arg(long, default_value_t = 5.0)]
    pub mm: f64,
    /// Initialisation noise level 1..5.
    #[arg(long, visible_alias = "levels", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=5))]
    pub level: u32,
    /// Study seed; each run's seed is derived from it.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long, value_parser = count_in(1, MAX_THREADS))]
    pub threads: Option<usize>,
    /// Print the rows as one JSON array instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Also write the study here: summary.json (settings, means, every row, provenance).
    #[arg(long)]
    pub out: Option<std::path::PathBuf>,
    /// Write into an --out that is not empty (same-named files are replaced, others stay).
    #[arg(long)]
    pub force: bool,
}

pub fn run(args: PoseStudyArgs) -> Result<(), String> {
    let PoseStudyArgs {
        gt,
        runs,
        deg,
        mm,
        level,
        seed,
        threads,
        json,
        out,
        force,
    } = args;
    if let Some(o) = &out {
        crate::common::check_out(o, force)?;
    }
    check_offsets(deg, mm)?;
    let truth = load_truth(&gt)?;
    let cfg = acetab::study::pose::PoseStudy {
        runs,
        seed,
        level,
        deg,
        mm,
        threads: threads_or_all(threads),
        ..Default::default()
    };
    let t = std::time::Instant::now();
    let rows =
        acetab::study::pose::run_pose_study(&truth, &cfg).map_err(|e| format!("--gt {gt}: {e}"))?;
    let ok: Vec<_> = rows.iter().filter(|r| r.error.is_empty()).collect();
    if ok.is_empty() {
        return Err(format!(
            "pose-study: all {} runs failed (run 0: {})",
            rows.len(),
            rows.first().map_or("", |r| r.error.as_str())
        ));
    }
    let mean = |f: &dyn Fn(&acetab::study::pose::PoseRow) -> f64| {
        ok.iter().map(|r| f(r)).sum::<f64>() / ok.len() as f64
    };
    let (without, with) = (mean(&|r| r.mae_without_mm), mean(&|r| r.mae_with_mm));
    let summary = serde_json::json!({
        "gt": gt, "runs": runs, "deg": deg, "mm": mm, "level": level, "seed": seed,
        "reference_view": cfg.pose.reference_view,
        "mae_without_mm": without, "mae_with_mm": with,
        "reduction": 1.0 - with / without,
        "cup_abs_error_without_mm": mean(&|r| r.cup_error_without_mm.abs()),
        "cup_abs_error_with_mm": mean(&|r| r.cup_error_with_mm.abs()),
        "failed": rows.len() - ok.len(),
        "seconds": t.elapsed().as_secs_f64(),
        "provenance": acetab::report::Provenance::here("cpu", None, cfg.threads, seed),
        "rows": rows,
    });
    if let Some(o) = &out {
        write_summary(o, &summary)?;
    }
    if json {
        println!(
            "{}",
            serde_json::to_string(&summary).map_err(|e| e.to_string())?
        );
    } else {
        print_rows(&rows);
        println!(
            "mean MAE {without:.3} mm without, {with:.3} mm with pose refinement ({:.0} % lower); poses off by {deg} deg and {mm} mm (all views but view {}), seed {seed}",
            100.0 * (1.0 - with / without),
            cfg.pose.reference_view
        );
    }
    Ok(())
}

/// The poses' offsets: finite, non-negative, the turn at most 180 degrees.
fn check_offsets(deg: f64, mm: f64) -> Result<(), String> {
    if !(deg.is_finite() && mm.is_finite() && deg >= 0.0 && mm >= 0.0) {
        return Err(format!(
            "--deg {deg} / --mm {mm}: must be finite and non-negative"
        ));
    }
    if deg > 180.0 {
        return Err(format!(
            "--deg {deg}: must be at most 180 (a turn beyond it is a smaller turn the other way, \
             so the study would report an error it did not make)"
        ));
    }
    Ok(())
}

/// summary.json written into `out`, all or nothing.
fn write_summary(out: &std::path::Path, summary: &serde_json::Value) -> Result<(), String> {
    let text = serde_json::to_string_pretty(summary).map_err(|e| e.to_string())?;
    acetab::io::fill_dir_atomically(
        out,
        |d| {
            std::fs::write(d.join("summary.json"), text.as_bytes())
                .map_err(|e| crate::common::io_msg(&d.join("summary.json"), e))
        },
        crate::common::io_msg,
    )
    .map_err(|e| crate::common::unstage(&e, out))
}

/// The runs' table on the terminal.
fn print_rows(rows: &[acetab::study::pose::PoseRow]) {
    println!("run  seed                  MAE without  MAE with  cup err without  cup err with");
    for r in rows {
        println!(
            "{:>3}  {:<20}  {:>11.3}  {:>8.3}  {:>15.2}  {:>12.2}  {}",
            r.run,
            r.seed,
            r.mae_without_mm,
            r.mae_with_mm,
            r.cup_error_without_mm,
            r.cup_error_with_mm,
            r.error
        );
    }
}
