//! `acetab align`: SRVF elastic alignment of two curves (CSV files of x,y; header optional).

use acetab::contours::read_curve_csv;
use acetab::correspond::srvf::{align, aligned_b, CurveKind, SrvfParams, MAX_SAMPLES, MIN_SAMPLES};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct AlignArgs {
    /// The first curve: a CSV of x,y per line (header optional).
    pub a: PathBuf,
    /// The second curve, aligned to the first.
    pub b: PathBuf,
    /// Both curves closed (default).
    #[arg(long, conflicts_with_all = ["open", "partial"])]
    pub closed: bool,
    /// Both open, ends corresponding.
    #[arg(long, conflicts_with = "partial")]
    pub open: bool,
    /// A is an open arc matched against the best sub-arc of the closed curve B.
    #[arg(long)]
    pub partial: bool,
    /// Arc-length samples per curve.
    #[arg(long, default_value_t = 200)]
    pub samples: usize,
    /// Weight of the position term (0: the elastic shape distance alone). For two curves drawn
    /// in one frame, w > 0 also pairs nearby points (see SrvfParams::anchor; the
    /// reconstruction uses 3).
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub anchor: f64,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

/// A finite weight >= 0.
fn non_negative(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("{s}: must be a finite number >= 0")),
    }
}

pub fn run(args: AlignArgs) -> Result<(), String> {
    let AlignArgs {
        a,
        b,
        closed: _,
        open,
        partial,
        samples,
        anchor,
        json,
    } = args;
    let kind = if open {
        CurveKind::Open
    } else if partial {
        CurveKind::Partial
    } else {
        CurveKind::Closed
    };
    if !(MIN_SAMPLES..=MAX_SAMPLES).contains(&samples) {
        return Err(format!(
            "--samples {samples}: must be {MIN_SAMPLES} to {MAX_SAMPLES}"
        ));
    }
    let ca = read_curve_csv(&a).map_err(|e| e.to_string())?;
    let cb = read_curve_csv(&b).map_err(|e| e.to_string())?;
    let prm = SrvfParams {
        samples,
        anchor,
        ..Default::default()
    };
    let t = std::time::Instant::now();
    let al = align(&ca, &cb, kind, &prm)
        .map_err(|e| format!("{} / {}: {e}", a.display(), b.display()))?;
    let seconds = t.elapsed().as_secs_f64();
    if json {
        let v = serde_json::json!({
            "distance": al.distance,
            "rotation_deg": al.rotation.to_degrees(),
            "seed": al.seed,
            "reversed": al.reversed,
            "samples": samples,
            "gamma": al.gamma,
            "seconds": seconds,
            "aligned": aligned_b(&al).iter().map(|p| [p.x, p.y]).collect::<Vec<_>>(),
        });
        println!("{v}");
    } else {
        println!(
            "distance {:.6}  rotation {:.3} deg  seed {}{}  {:.2} ms",
            al.distance,
            al.rotation.to_degrees(),
            al.seed,
            if al.reversed { "  (A reversed)" } else { "" },
            seconds * 1e3
        );
    }
    Ok(())
}
