//! `acetab calibrate`: learn the cup estimator's bias (and, asked, its shrink) and the cup
//! uncertainty's model-error SD from studies whose truths are known (see
//! `acetab::pipeline::CupCalibration`).

use acetab::pipeline::{CupCalibration, CupEstimator, CupParams, Learn, TrainingRun};
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
    /// Learn no bias (bias_mm 0): only the model-error SD, as calibrations made before the
    /// bias were.
    #[arg(long, conflicts_with = "shrink")]
    pub no_bias: bool,
    /// Learn a shrink too: the cup pulled toward the training runs' mean by one minus the
    /// slope of the least-squares line from fitted diameter to truth (each source of truths, the
    /// folder its mesh came from, weighing the same). It pays where the cup's error is large
    /// against the spread of acetabula (the realistic protocol), not on ideal X-rays.
    #[arg(long)]
    pub shrink: bool,
    /// Learn no depth offset (depth_mm 0): the result stays where the method puts it along the
    /// views. For training studies whose sources of truths want offsets so far apart that the
    /// one learned with each weighing the same moves one population's results farther off
    /// (docs/population.md, "The realistic Judet and prior-region calibrations with a depth
    /// offset").
    #[arg(long)]
    pub no_depth: bool,
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
pub(crate) fn study_dirs(dirs: &[PathBuf]) -> Result<Vec<PathBuf>, String> {
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

/// What a study's cups already hold: the model-error SD in its cup SDs
/// (summary.json's study.cup_model_sd_mm), the correction its cups were given
/// (study.cup_bias_mm, cup_shrink, cup_shrink_to_mm) and its cup estimator
/// (study.cup_estimator); none and the observed part when absent (a study made before
/// calibrations, the bias or the shrink, or run without them); and the folder its truth came
/// from (study.gt's; the study's own parent folder when absent).
pub(crate) struct Applied {
    pub(crate) model_sd: f64,
    pub(crate) cup: CupParams,
    pub(crate) estimator: CupEstimator,
    pub(crate) source: PathBuf,
    /// study.views (None when absent).
    pub(crate) views: Option<Vec<String>>,
    /// The kind of study.protocol, "ideal" or "realistic" (None when absent).
    pub(crate) protocol: Option<&'static str>,
}

impl Applied {
    /// The estimator's own diameter and resampled SD behind a study's corrected cup and its
    /// resampled SD: the correction undone (`CupParams::corrected` is linear, with slope one
    /// less the shrink).
    pub(crate) fn undo(&self, cup_mm: f64, resample_sd_mm: f64) -> (f64, f64) {
        (
            self.cup.uncorrected(cup_mm),
            resample_sd_mm / (1.0 - self.cup.shrink),
        )
    }
}

/// A run's resampled SD alone: its study's SD (`cup_sd_mm`) without the model error the study
/// already held in it. NaN in a study that resampled none gives 0 (the model SD learned then
/// holds the whole spread); NaN in one that did (`resampled`: the run's resampling failed, its
/// result kept) stays NaN, a run with no SD. What `calibrate` and `plan-views` read alike.
pub(crate) fn resampled_sd(cup_sd_mm: f64, model_sd_mm: f64, resampled: bool) -> f64 {
    if resampled && cup_sd_mm.is_nan() {
        return f64::NAN;
    }
    (cup_sd_mm * cup_sd_mm - model_sd_mm * model_sd_mm)
        .max(0.0)
        .sqrt()
}

/// Whether a study resampled its `method` runs' cups: some run with a result has a finite SD.
pub(crate) fn resampled_cups(rows: &[acetab::study::Row], method: StudyMethod) -> bool {
    rows.iter()
        .any(|r| r.method == method && r.error.is_empty() && r.cup_sd_mm.is_finite())
}

pub(crate) fn applied_in(dir: &Path) -> Result<Applied, String> {
    let mut a = Applied {
        model_sd: 0.0,
        cup: CupParams::default(),
        estimator: CupEstimator::ObservedPart,
        source: dir.parent().map(Path::to_path_buf).unwrap_or_default(),
        views: None,
        protocol: None,
    };
    let p = dir.join("summary.json");
    let Ok(text) = std::fs::read_to_string(&p) else {
        return Ok(a);
    };
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", p.display()))?;
    let number = |field: &str, ok: fn(f64) -> bool, expected: &str| match v
        .pointer(&format!("/study/{field}"))
    {
        None | Some(serde_json::Value::Null) => Ok(0.0),
        Some(x) => x
            .as_f64()
            .filter(|s| ok(*s))
            .ok_or_else(|| format!("{}: study.{field} = {x}: must be {expected}", p.display())),
    };
    a.model_sd = number(
        "cup_model_sd_mm",
        |s| s.is_finite() && s >= 0.0,
        "a finite SD >= 0",
    )?;
    // The correction's fields as numbers, then judged together (`CupParams::invalid_correction`).
    a.cup.bias_mm = number("cup_bias_mm", |_| true, "a number")?;
    a.cup.shrink = number("cup_shrink", |_| true, "a number")?;
    a.cup.shrink_to_mm = number("cup_shrink_to_mm", |_| true, "a number")?;
    a.cup.depth_mm = number("cup_depth_mm", |_| true, "a number")?;
    if let Some((field, value, expected)) = a.cup.invalid_correction() {
        return Err(format!(
            "{}: study.cup_{field} = {value}: must be {expected}",
            p.display()
        ));
    }
    if let Some(gt) = v.pointer("/study/gt").and_then(|g| g.as_str()) {
        if let Some(parent) = Path::new(gt).parent() {
            a.source = parent.to_path_buf();
        }
    }
    if let Some(x) = v.pointer("/study/views") {
        let views: Option<Vec<String>> = x
            .as_array()
            .and_then(|a| a.iter().map(|v| v.as_str().map(String::from)).collect());
        let readable = views.as_ref().is_some_and(|v| {
            !v.is_empty()
                && v.iter()
                    .all(|v| v.parse::<acetab::views::ViewRotation>().is_ok())
        });
        if !readable {
            return Err(format!(
                "{}: study.views = {x}: must be a list of views as --views writes them (\"z:20\")",
                p.display()
            ));
        }
        a.views = views;
    }
    if let Some(x) = v.pointer("/study/protocol") {
        // As summary.json writes a `Protocol`: "Ideal", or {"Realistic": its errors}.
        a.protocol = Some(match x {
            serde_json::Value::String(k) if k == "Ideal" => "ideal",
            serde_json::Value::Object(m) if m.len() == 1 && m.contains_key("Realistic") => {
                "realistic"
            }
            _ => {
                return Err(format!(
                    "{}: study.protocol = {x}: must be \"Ideal\" or {{\"Realistic\": ...}}",
                    p.display()
                ))
            }
        });
    }
    if let Some(x) = v.pointer("/study/cup_estimator") {
        a.estimator = x.as_str().and_then(CupEstimator::parse).ok_or_else(|| {
            format!(
                "{}: study.cup_estimator = {x}: must be observed-part or prior-region",
                p.display()
            )
        })?;
    }
    Ok(a)
}

/// Hold the study `d` (its `applied` settings) to the protocol of the first study in `seen`
/// that said one (`seen` is set by the first that does; a study that says none is not held):
/// a different one is an error naming both, `why` saying why they must agree.
pub(crate) fn hold_protocol(
    seen: &mut Option<(&'static str, PathBuf)>,
    applied: &Applied,
    d: &Path,
    why: &str,
) -> Result<(), String> {
    match (applied.protocol, &*seen) {
        (Some(k), None) => *seen = Some((k, d.to_path_buf())),
        (Some(k), Some((first_kind, first))) if k != *first_kind => {
            return Err(format!(
                "{}: protocol {k} differs from {}'s {first_kind}: {why}",
                d.display(),
                first.display(),
            ))
        }
        _ => {}
    }
    Ok(())
}

/// Study `d`'s cup estimator (`applied`) held to the first study's (`seen`, set by the first):
/// a different one is an error naming both, ending in `why`.
pub(crate) fn hold_estimator(
    seen: &mut Option<(CupEstimator, PathBuf)>,
    applied: &Applied,
    d: &Path,
    why: &str,
) -> Result<(), String> {
    match &*seen {
        None => *seen = Some((applied.estimator, d.to_path_buf())),
        Some((e, first)) if *e != applied.estimator => {
            return Err(format!(
                "{}: cup_estimator {} differs from {}'s {}{why}",
                d.display(),
                applied.estimator.name(),
                first.display(),
                e.name()
            ))
        }
        Some(_) => {}
    }
    Ok(())
}

/// Where `source` is in `sources` (added at the end where it is new): the index a run's source
/// of truths is known by.
pub(crate) fn source_index(sources: &mut Vec<PathBuf>, source: &Path) -> usize {
    match sources.iter().position(|s| s == source) {
        Some(k) => k,
        None => {
            sources.push(source.to_path_buf());
            sources.len() - 1
        }
    }
}

/// The protocol kinds ("ideal", "realistic") the studies under `dirs` say they were made under,
/// with the first study saying each.
pub(crate) fn protocols_in(dirs: &[PathBuf]) -> Result<Vec<(&'static str, PathBuf)>, String> {
    let mut out: Vec<(&'static str, PathBuf)> = Vec::new();
    for d in study_dirs(dirs)? {
        if let Some(k) = applied_in(&d)?.protocol {
            if !out.iter().any(|(o, _)| *o == k) {
                out.push((k, d));
            }
        }
    }
    Ok(out)
}

/// What the flags ask to learn.
pub fn what(no_bias: bool, shrink: bool) -> Learn {
    match (no_bias, shrink) {
        (_, true) => Learn::BiasAndShrink,
        (true, false) => Learn::SdOnly,
        (false, false) => Learn::Bias,
    }
}

/// Learn a calibration from the `method` runs of the studies under `study`, leaving out the
/// subjects `leave_out` (learning `what`); `note` is appended to `learned_from`. The studies
/// must share one cup estimator, which the calibration is for.
pub fn learn(
    study: &[PathBuf],
    leave_out: &[String],
    method: StudyMethod,
    what: Learn,
    note: Option<&str>,
) -> Result<CupCalibration, String> {
    let dirs = study_dirs(study)?;
    let mut runs = Vec::new();
    let mut sources: Vec<PathBuf> = Vec::new();
    let mut used = 0;
    let mut shared = SharedSettings::default();
    for d in &dirs {
        if leave_out.contains(&subject_of(d)) {
            continue;
        }
        used += 1;
        let applied = applied_in(d)?;
        shared.hold(d, &applied)?;
        let source = source_index(&mut sources, &applied.source);
        runs.extend(training_runs(d, &applied, method, source)?);
    }
    let estimator = shared
        .estimator
        .map_or(CupEstimator::ObservedPart, |(e, _)| e);
    let mut from = format!(
        "{} {} runs in {used} studies from {} sources of truths",
        runs.len(),
        method.name(),
        sources.len()
    );
    if !leave_out.is_empty() {
        from += &format!(" (left out: {})", leave_out.join(", "));
    }
    if let Some(n) = note {
        from += &format!(": {n}");
    }
    let mut cal = CupCalibration::learn(&runs, estimator, what, from).map_err(|e| e.to_string())?;
    cal.views = shared.said.filter(|_| !shared.unsaid).map(|(v, _)| v);
    Ok(cal)
}

/// What the training studies of one calibration share, as they are read: one cup estimator,
/// one protocol where they say, one set of views (each with the first study that gave it).
#[derive(Default)]
struct SharedSettings<'a> {
    estimator: Option<(CupEstimator, PathBuf)>,
    /// The views the studies say they were made with.
    said: Option<(Vec<String>, &'a Path)>,
    /// A study did not say (then the calibration does not either).
    unsaid: bool,
    protocol: Option<(&'static str, PathBuf)>,
}

impl<'a> SharedSettings<'a> {
    /// Study `d`'s settings (`applied`) held to those before it: an error naming both when they
    /// differ.
    fn hold(&mut self, d: &'a Path, applied: &Applied) -> Result<(), String> {
        hold_estimator(
            &mut self.estimator,
            applied,
            d,
            ": a calibration is learned for one estimator",
        )?;
        hold_protocol(
            &mut self.protocol,
            applied,
            d,
            "a calibration is learned under one protocol (its bias and SD are that protocol's errors)",
        )?;
        match (&applied.views, &self.said) {
            (None, _) => self.unsaid = true,
            (Some(v), None) => self.said = Some((v.clone(), d)),
            (Some(v), Some((first_views, first))) if v != first_views => {
                return Err(format!(
                    "{}: views {} differ from {}'s {}: a calibration is learned on one set of views (its bias and SD are theirs)",
                    d.display(),
                    v.join(","),
                    first.display(),
                    first_views.join(",")
                ))
            }
            _ => {}
        }
        Ok(())
    }
}

/// The `method` runs of study `d` (made with `applied`) that a calibration learns from, their
/// truths from source `source`: each run's own diameter and resampled SD, without the
/// correction the study made.
fn training_runs(
    d: &Path,
    applied: &Applied,
    method: StudyMethod,
    source: usize,
) -> Result<Vec<TrainingRun>, String> {
    let rows = read_csv(&d.join("runs.csv")).map_err(|e| e.to_string())?;
    // In a study that resampled its cups, a run whose resampling failed (its SD NaN, its
    // result kept) says nothing of the cup's spread and is skipped.
    let resampled = resampled_cups(&rows, method);
    Ok(rows
        .iter()
        .filter(|r| r.method == method && r.error.is_empty())
        .filter(|r| !(resampled && r.cup_sd_mm.is_nan()))
        .map(|r| {
            // The resampled SD alone (`resampled_sd`), and the estimator's own diameter,
            // without the correction the study made.
            let resample = resampled_sd(r.cup_sd_mm, applied.model_sd, resampled);
            let (fitted_mm, resample_sd_mm) = applied.undo(r.cup_diameter_mm, resample);
            TrainingRun {
                fitted_mm,
                truth_mm: r.gt_cup_diameter_mm,
                resample_sd_mm,
                depth_offset_mm: r.depth_offset_mm,
                source,
            }
        })
        .collect())
}

pub fn run(args: CalibrateArgs) -> Result<(), String> {
    crate::common::check_out_file(&args.out)?;
    let mut cal = learn(
        &args.study,
        &args.leave_out,
        args.method,
        what(args.no_bias, args.shrink),
        args.note.as_deref(),
    )?;
    if args.no_depth {
        cal.depth_mm = 0.0;
    }
    crate::common::write_out_file(&args.out, cal.to_json().as_bytes())?;
    let shrink = if cal.shrink > 0.0 {
        format!(
            ", shrink {:.3} toward {:.2} mm",
            cal.shrink, cal.shrink_to_mm
        )
    } else {
        String::new()
    };
    println!(
        "{} cup: bias {:+.3} mm{shrink}, model-error SD {:.3} mm from {} runs (training coverage {:.1} %); result's depth offset {:+.3} mm; written to {}",
        cal.estimator,
        cal.bias_mm,
        cal.model_sd_mm,
        cal.runs,
        100.0 * cal.training_coverage,
        cal.depth_mm,
        args.out.display()
    );
    Ok(())
}
