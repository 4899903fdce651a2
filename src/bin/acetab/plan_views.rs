//! `acetab plan-views`: which set of X-ray views sizes the cup best. Reads population sweeps of
//! the same acetabula made with different `--views` (one `acetab simulate --gt ... --views SET`
//! sweep per set) and writes the view-planning table (`acetab::study::view_plan`): per set and
//! source of truths, the surface's MAE, the fitted cup's error, and the cup corrected by what
//! the set's other subjects' runs teach (leave-one-subject-out).

use crate::calibrate::{
    applied_in, hold_estimator, hold_protocol, resampled_cups, resampled_sd, source_index, Applied,
};
use crate::calibrate::{study_dirs, subject_of};
use crate::common::{check_out, io_msg};
use acetab::io::fill_dir_atomically;
use acetab::pipeline::{CupEstimator, Learn};
use acetab::study::view_plan::{plan_rows, PlanRun, ViewSetRow};
use acetab::study::{read_csv, StudyMethod};
use std::path::{Path, PathBuf};

/// `--correction`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum CorrectionArg {
    /// The fitted cup as it is.
    None,
    /// Less a bias learned leave-one-subject-out (as `acetab calibrate` learns it).
    Bias,
    /// Less a bias and a shrink learned leave-one-subject-out (`acetab calibrate --shrink`).
    Shrink,
}

#[derive(clap::Args)]
pub struct PlanViewsArgs {
    /// Population sweeps (folders with one study per acetabulum, as `acetab simulate --gt
    /// DIR... --out SWEEP` writes them), one per view set, of the same acetabula.
    #[arg(long, num_args = 1.., required = true)]
    pub sweep: Vec<PathBuf>,
    /// The cup each set is judged by: as fitted, or corrected by a bias (or a bias and a
    /// shrink) learned from the set's own runs, leaving each subject out of its own correction.
    #[arg(long, value_enum, default_value_t = CorrectionArg::Bias)]
    pub correction: CorrectionArg,
    /// The method whose runs are compared.
    #[arg(long, default_value = "srvf", value_parser = crate::common::method)]
    pub method: StudyMethod,
    /// Where views.csv and views.json are written (a new folder, or --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Write into an --out that is not empty.
    #[arg(long)]
    pub force: bool,
}

/// One sweep read: its views, protocol, cup estimator, meshes and runs.
struct Sweep {
    views: String,
    /// The protocol its studies say ("ideal", "realistic"), if they say.
    protocol: Option<&'static str>,
    estimator: CupEstimator,
    meshes: Vec<String>,
    runs: Vec<PlanRun>,
}

/// Read one sweep; its runs' sources index `sources`, the sources of every sweep read so far
/// (a new one is added).
fn read_sweep(
    sweep: &Path,
    method: StudyMethod,
    sources: &mut Vec<PathBuf>,
) -> Result<Sweep, String> {
    let dirs = study_dirs(std::slice::from_ref(&sweep.to_path_buf()))
        .map_err(|e| e.replacen("--study", "--sweep", 1))?;
    let mut views: Option<(Vec<String>, PathBuf)> = None;
    let mut estimator: Option<(CupEstimator, PathBuf)> = None;
    let mut protocol: Option<(&'static str, PathBuf)> = None;
    let mut meshes = Vec::new();
    let mut runs = Vec::new();
    for d in &dirs {
        let applied = applied_in(d)?;
        hold_views(&mut views, &mut estimator, &applied, d)?;
        hold_protocol(&mut protocol, &applied, d, "a sweep is one protocol")?;
        let source = source_index(sources, &applied.source);
        meshes.push(
            d.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
        );
        runs.extend(study_runs(d, method, &applied, source)?);
    }
    let (Some((views, _)), Some((estimator, _))) = (views, estimator) else {
        return Err(format!("--sweep {}: no study in it", sweep.display()));
    };
    if runs.is_empty() {
        return Err(format!(
            "--sweep {}: no {} runs in its studies",
            sweep.display(),
            method.name()
        ));
    }
    meshes.sort();
    Ok(Sweep {
        views: views.join(","),
        protocol: protocol.map(|(k, _)| k),
        estimator,
        meshes,
        runs,
    })
}

/// The study in `d` (`applied`) made with the views and the cup estimator of the sweep's first
/// study (`views` and `estimator`, which the first study read sets): a sweep is one view set.
fn hold_views(
    views: &mut Option<(Vec<String>, PathBuf)>,
    estimator: &mut Option<(CupEstimator, PathBuf)>,
    applied: &Applied,
    d: &Path,
) -> Result<(), String> {
    let Some(these) = applied.views.clone() else {
        return Err(format!(
            "{}: study.views missing: the sweep's views are not known (a study made before they were recorded)",
            d.join("summary.json").display()
        ));
    };
    match views {
        None => *views = Some((these, d.to_path_buf())),
        Some((v, at)) if *v != these => {
            return Err(format!(
                "{}: views {} differ from {}'s {}: a sweep is one view set",
                d.display(),
                these.join(","),
                at.display(),
                v.join(",")
            ))
        }
        Some(_) => {}
    }
    hold_estimator(estimator, applied, d, "")
}

/// The `method`'s runs of the study in `d` (`applied`), its truths from `source`: each run's
/// cup as the estimator fitted it and its resampled SD, without the correction the study made.
fn study_runs(
    d: &Path,
    method: StudyMethod,
    applied: &Applied,
    source: usize,
) -> Result<Vec<PlanRun>, String> {
    let subject = subject_of(d);
    let rows = read_csv(&d.join("runs.csv")).map_err(|e| e.to_string())?;
    let resampled = resampled_cups(&rows, method);
    let mut runs = Vec::new();
    for r in rows.iter().filter(|r| r.method == method) {
        if !(r.gt_cup_diameter_mm.is_finite() && r.gt_cup_diameter_mm > 0.0) {
            return Err(format!(
                "{}: {} level {} run {}: gt_cup_diameter_mm = {}: must be a positive diameter (the truth's cup)",
                d.join("runs.csv").display(),
                r.method.name(),
                r.level,
                r.run,
                r.gt_cup_diameter_mm
            ));
        }
        let ok = r.error.is_empty() && r.cup_diameter_mm.is_finite();
        // The resampled SD alone (`resampled_sd`), and the estimator's own diameter,
        // without the correction the study made.
        let resample = resampled_sd(r.cup_sd_mm, applied.model_sd, resampled);
        let (fitted, resample_sd_mm) = applied.undo(r.cup_diameter_mm, resample);
        runs.push(PlanRun {
            source,
            subject: subject.clone(),
            fitted_mm: ok.then_some(fitted),
            truth_mm: r.gt_cup_diameter_mm,
            resample_sd_mm,
            mae_mm: r.mae_mm,
        });
    }
    Ok(runs)
}

/// Short names for the sources: each folder's own name, or its last two components where two
/// share a name.
fn source_names(paths: &[PathBuf]) -> Vec<String> {
    let last = |p: &Path, n: usize| {
        let parts: Vec<String> = p
            .components()
            .map(|c| c.as_os_str().to_string_lossy().into_owned())
            .collect();
        parts[parts.len().saturating_sub(n)..].join("/")
    };
    let short: Vec<String> = paths.iter().map(|p| last(p, 1)).collect();
    let mut sorted = short.clone();
    sorted.sort();
    sorted.dedup();
    if sorted.len() == short.len() {
        short
    } else {
        paths.iter().map(|p| last(p, 2)).collect()
    }
}

pub fn run(args: PlanViewsArgs) -> Result<(), String> {
    check_out(&args.out, args.force)?;
    let what = match args.correction {
        CorrectionArg::None => Learn::SdOnly,
        CorrectionArg::Bias => Learn::Bias,
        CorrectionArg::Shrink => Learn::BiasAndShrink,
    };
    // Every set's sources, in order of first appearance, named once for the whole table.
    let mut all_sources: Vec<PathBuf> = Vec::new();
    let sweeps: Vec<Sweep> = args
        .sweep
        .iter()
        .map(|s| read_sweep(s, args.method, &mut all_sources))
        .collect::<Result<_, _>>()?;
    let names = source_names(&all_sources);
    one_protocol(&sweeps, &args.sweep)?;
    warn_other_acetabula(&sweeps, &args.sweep);
    let mut rows: Vec<ViewSetRow> = Vec::new();
    for s in &sweeps {
        rows.extend(
            plan_rows(&s.views, &names, &s.runs, s.estimator, what).map_err(|e| e.to_string())?,
        );
    }
    let meta = serde_json::json!({
        "method": args.method.name(),
        "correction": match args.correction {
            CorrectionArg::None => "none: the fitted cup",
            CorrectionArg::Bias => "a bias learned leave-one-subject-out from the set's own runs",
            CorrectionArg::Shrink => "a bias and a shrink learned leave-one-subject-out from the set's own runs",
        },
        "sweeps": args.sweep.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "sources": all_sources.iter().zip(&names).map(|(p, n)| serde_json::json!({"name": n, "path": p.display().to_string()})).collect::<Vec<_>>(),
    });
    write_plan(&args.out, &rows, &meta)?;
    print_plan(&rows);
    eprintln!("view-planning table in {}", args.out.display());
    Ok(())
}

/// View sets are compared under one protocol (a sweep that does not say is not held to one):
/// an error naming two `sweeps` (read from `paths`) made under different ones.
fn one_protocol(sweeps: &[Sweep], paths: &[PathBuf]) -> Result<(), String> {
    let said = || {
        sweeps
            .iter()
            .zip(paths)
            .filter_map(|(s, p)| Some((s.protocol?, p)))
    };
    if let Some(((k0, p0), (k, p))) = said().next().and_then(|first| {
        said()
            .find(|(k, _)| *k != first.0)
            .map(|other| (first, other))
    }) {
        return Err(format!(
            "--sweep {}: made under the {k} protocol, --sweep {} under the {k0}: view sets are compared under one protocol",
            p.display(),
            p0.display()
        ));
    }
    Ok(())
}

/// A warning for each sweep (read from `paths`) whose acetabula are not the first one's.
fn warn_other_acetabula(sweeps: &[Sweep], paths: &[PathBuf]) {
    let missing = |a: &Sweep, b: &Sweep| -> String {
        let names: Vec<&str> = b
            .meshes
            .iter()
            .filter(|m| !a.meshes.contains(m))
            .map(String::as_str)
            .collect();
        match names.len() {
            0 => "none".into(),
            n if n <= 5 => names.join(", "),
            n => format!("{} and {} more", names[..5].join(", "), n - 5),
        }
    };
    for (s, path) in sweeps.iter().zip(paths).skip(1) {
        if s.meshes != sweeps[0].meshes {
            eprintln!(
                "acetab: warning: --sweep {} holds {} acetabula, {} holds {}: the sets are not compared on the same acetabula (not in {}: {}; not in {}: {})",
                path.display(),
                s.meshes.len(),
                paths[0].display(),
                sweeps[0].meshes.len(),
                path.display(),
                missing(s, &sweeps[0]),
                paths[0].display(),
                missing(&sweeps[0], s),
            );
        }
    }
}

/// views.csv and views.json (the rows with `meta`) written into `out`, all or nothing.
fn write_plan(out: &Path, rows: &[ViewSetRow], meta: &serde_json::Value) -> Result<(), String> {
    fill_dir_atomically(
        out,
        |d| {
            let p = d.join("views.csv");
            let mut w = csv::Writer::from_path(&p).map_err(|e| format!("{}: {e}", p.display()))?;
            for r in rows {
                w.serialize(r)
                    .map_err(|e| format!("{}: {e}", p.display()))?;
            }
            w.flush().map_err(|e| io_msg(&p, e))?;
            let p = d.join("views.json");
            let text =
                serde_json::to_string_pretty(&serde_json::json!({"plan": meta, "rows": rows}))
                    .map_err(|e| e.to_string())?;
            std::fs::write(&p, text).map_err(|e| io_msg(&p, e))
        },
        io_msg,
    )
    .map_err(|e| crate::common::unstage(&e, out))
}

/// The table on the terminal, then the set with most cups within 1 mm over all sources.
fn print_plan(rows: &[ViewSetRow]) {
    println!(
        "{:<28} {:<22} {:>5} {:>6} {:>7} {:>9} {:>8} {:>7} {:>8} {:>9} {:>9}",
        "views",
        "source",
        "runs",
        "failed",
        "MAE",
        "fit bias",
        "cup RMS",
        "exact",
        "<=1 mm",
        "one size",
        "<=cup SD"
    );
    for r in rows {
        println!(
            "{:<28} {:<22} {:>5} {:>6} {:>7.3} {:>+9.2} {:>8.2} {:>6.0}% {:>7.0}% {:>8.0}% {:>9}",
            r.views,
            r.source,
            r.runs,
            r.failed,
            r.mae_mm,
            r.fitted_bias_mm,
            r.rms_mm,
            100.0 * r.exact_size,
            100.0 * r.within_1mm,
            100.0 * r.within_one_size,
            r.sd_coverage
                .map_or("-".to_string(), |c| format!("{:.0}%", 100.0 * c))
        );
    }
    if let Some(best) = rows
        .iter()
        .filter(|r| r.source == "all")
        .max_by(|a, b| a.within_1mm.total_cmp(&b.within_1mm))
    {
        println!(
            "most cups within 1 mm over all sources: {} ({:.0} %, exact size {:.0} %)",
            best.views,
            100.0 * best.within_1mm,
            100.0 * best.exact_size
        );
    }
}
