//! `acetab calibrate`: learn the cup uncertainty's model-error SD from studies whose truths are
//! known (see `acetab::pipeline::CupCalibration`).

use acetab::io::write_atomic;
use acetab::pipeline::CupCalibration;
use acetab::study::{read_csv, StudyMethod};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct CalibrateArgs {
    /// Study folders (with runs.csv, as `acetab simulate` writes them) or population folders
    /// (one study per subfolder).
    #[arg(long, num_args = 1.., required = true)]
    pub study: Vec<PathBuf>,
    /// Leave out the studies of these subjects (a study's subject is its folder name up to the
    /// first '_': both hips of a subject leave together), for leave-one-subject-out checks.
    #[arg(long)]
    pub leave_out: Vec<String>,
    /// The method whose runs are learned from.
    #[arg(long, default_value = "srvf", value_parser = crate::common::method)]
    pub method: StudyMethod,
    /// A note on what the studies were (protocol, data, commit), kept in the file's
    /// `learned_from`.
    #[arg(long)]
    pub note: Option<String>,
    /// Where the calibration is written (JSON; `--calibration` on simulate and reconstruct).
    #[arg(long)]
    pub out: PathBuf,
}

/// The subject of a study folder or mesh file: its name (a file's without the extension) up to
/// the first '_'.
pub fn subject_of(path: &Path) -> String {
    let name = if path.is_dir() {
        path.file_name()
    } else {
        path.file_stem()
    };
    let name = name
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    name.split('_').next().unwrap_or_default().to_string()
}

/// The study folders under `dirs`: each one with runs.csv, or its subfolders that have one.
fn study_dirs(dirs: &[PathBuf]) -> Result<Vec<PathBuf>, String> {
    let mut out = Vec::new();
    for d in dirs {
        if d.join("runs.csv").is_file() {
            out.push(d.clone());
            continue;
        }
        let entries = std::fs::read_dir(d).map_err(|e| format!("--study {}: {e}", d.display()))?;
        let mut subs: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.join("runs.csv").is_file())
            .collect();
        if subs.is_empty() {
            return Err(format!(
                "--study {}: no runs.csv in it or in its subfolders",
                d.display()
            ));
        }
        subs.sort();
        out.extend(subs);
    }
    Ok(out)
}

/// The model-error SD a study's cup SDs already hold (summary.json's study.cup_model_sd_mm; 0
/// when absent: a study made before calibrations, or run without one).
fn model_sd_of(dir: &Path) -> Result<f64, String> {
    let p = dir.join("summary.json");
    let Ok(text) = std::fs::read_to_string(&p) else {
        return Ok(0.0);
    };
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", p.display()))?;
    match v.pointer("/study/cup_model_sd_mm") {
        None | Some(serde_json::Value::Null) => Ok(0.0),
        Some(x) => x
            .as_f64()
            .filter(|s| s.is_finite() && *s >= 0.0)
            .ok_or_else(|| {
                format!(
                    "{}: study.cup_model_sd_mm = {x}: must be a finite SD >= 0",
                    p.display()
                )
            }),
    }
}

/// Learn a calibration from the `method` runs of the studies under `study`, leaving out the
/// subjects `leave_out`; `note` is appended to `learned_from`.
pub fn learn(
    study: &[PathBuf],
    leave_out: &[String],
    method: StudyMethod,
    note: Option<&str>,
) -> Result<CupCalibration, String> {
    let dirs = study_dirs(study)?;
    let mut pairs = Vec::new();
    let mut used = 0;
    for d in &dirs {
        if leave_out.contains(&subject_of(d)) {
            continue;
        }
        used += 1;
        let model = model_sd_of(d)?;
        let rows = read_csv(&d.join("runs.csv")).map_err(|e| e.to_string())?;
        for r in rows
            .iter()
            .filter(|r| r.method == method && r.error.is_empty())
        {
            // The resampled SD alone: the study's SD without the model error it already held.
            let resample = (r.cup_sd_mm * r.cup_sd_mm - model * model).max(0.0).sqrt();
            pairs.push((r.cup_error_mm(), resample));
        }
    }
    let mut from = format!("{} {} runs in {used} studies", pairs.len(), method.name());
    if !leave_out.is_empty() {
        from += &format!(" (left out: {})", leave_out.join(", "));
    }
    if let Some(n) = note {
        from += &format!(": {n}");
    }
    CupCalibration::learn(&pairs, from).map_err(|e| e.to_string())
}

pub fn run(args: CalibrateArgs) -> Result<(), String> {
    let cal = learn(
        &args.study,
        &args.leave_out,
        args.method,
        args.note.as_deref(),
    )?;
    write_atomic(&args.out, cal.to_json().as_bytes())
        .map_err(|e| format!("--out {}: {e}", args.out.display()))?;
    println!(
        "model-error SD {:.3} mm from {} runs (training coverage {:.1} %); written to {}",
        cal.model_sd_mm,
        cal.runs,
        100.0 * cal.training_coverage,
        args.out.display()
    );
    Ok(())
}
