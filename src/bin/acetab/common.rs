//! What the subcommands share: the GPU device, output-folder errors, the ground truth, and the
//! checks of numeric flags.

use acetab::engine::gpu::GpuDevice;
use acetab::engine::BackendChoice;
use acetab::pipeline::{MAX_RESAMPLES, MIN_RESAMPLES};
use acetab::study::summarize;
use std::path::Path;

/// The device for `--backend`: none for cpu; for auto, none (with one line saying so) when no
/// adapter can be had.
pub fn open_device(choice: BackendChoice) -> Result<Option<GpuDevice>, String> {
    match choice {
        BackendChoice::Cpu => Ok(None),
        BackendChoice::Gpu => GpuDevice::from_env()
            .map(Some)
            .map_err(|e| format!("--backend gpu: {e}")),
        BackendChoice::Auto => match GpuDevice::from_env() {
            Ok(d) => Ok(Some(d)),
            Err(e) => {
                eprintln!("--backend auto: {e}; running on the CPU");
                Ok(None)
            }
        },
    }
}

/// `--out` must be writable (checked before the work) and new or empty: a reused folder would
/// mix an earlier result's files with this one's. `force` lets it be reused (same-named files
/// are replaced, others stay).
pub fn check_out(out: &Path, force: bool) -> Result<(), String> {
    check_writable_out(out, out)?;
    if force {
        return Ok(());
    }
    if acetab::io::out_in_use(out) {
        return Err(format!(
            "--out {}: exists and is not empty (an earlier result's files would mix with this \
             one's); choose a new folder, or pass --force to write into it",
            out.display()
        ));
    }
    Ok(())
}

/// A one-file `--out` (a prior, a calibration): the folder it goes in must be one this process
/// can make (checked before the work, so that a long build does not end in "cannot write").
pub fn check_out_file(out: &Path) -> Result<(), String> {
    let folder = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    check_writable_out(out, folder)
}

/// `acetab::io::check_writable(folder)` for the `--out` given as `out`, as a message naming it.
pub fn check_writable_out(out: &Path, folder: &Path) -> Result<(), String> {
    acetab::io::check_writable(folder)
        .map_err(|e| format!("--out {}: cannot be written: {e}", out.display()))
}

/// Write a one-file `--out` atomically, making the folders above it that are missing.
pub fn write_out_file(out: &Path, bytes: &[u8]) -> Result<(), String> {
    if let Some(folder) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(folder).map_err(|e| io_msg(folder, e))?;
    }
    acetab::io::write_atomic(out, bytes).map_err(|e| io_msg(out, e))
}

/// `msg` with the hidden staging folder of `out` (`fill_dir_atomically`'s `.NAME.partial-XXXX`
/// beside it) replaced by `out` itself: errors name the user's folder, not ours.
pub fn unstage(msg: &str, out: &Path) -> String {
    let Some(name) = out.file_name() else {
        return msg.to_string();
    };
    let marker = format!(".{}.partial-", name.to_string_lossy());
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut rest = msg;
    let mut done = String::new();
    while let Some(k) = rest.find(&marker) {
        let after = &rest[k + marker.len()..];
        let end = after.find(['/', ':', ' ']).unwrap_or(after.len());
        // Drop the parent folder written before the marker, then put `out` in its place.
        let head = &rest[..k];
        let prefix = format!("{}/", parent.display());
        done.push_str(head.strip_suffix(prefix.as_str()).unwrap_or(head));
        done.push_str(&out.display().to_string());
        rest = &after[end..];
    }
    done.push_str(rest);
    done
}

/// An I/O error on an output path, for `fill_dir_atomically`.
pub fn io_msg(p: &Path, e: std::io::Error) -> String {
    format!("{}: cannot write: {e}", p.display())
}

/// The study's ground truth from `--gt` (`acetab::sim::load_truth`).
pub fn load_truth(gt: &str) -> Result<acetab::geom::Mesh, String> {
    acetab::sim::load_truth(gt).map_err(|e| e.to_string())
}

/// The engine on the device, if any (its pipelines compile here).
pub fn engine_on(dev: &Option<GpuDevice>) -> Result<Option<acetab::engine::gpu::Gpu<'_>>, String> {
    dev.as_ref()
        .map(|d| d.engine())
        .transpose()
        .map_err(|e| e.to_string())
}

/// The mesh files (.stl, .ply, .obj, any case) in folder `dir`, sorted; an empty list when it
/// has none.
pub fn mesh_files_in(dir: &Path) -> Result<Vec<std::path::PathBuf>, String> {
    let mut v: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| io_msg(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|f| {
            f.extension()
                .and_then(|x| x.to_str())
                .is_some_and(|x| ["stl", "ply", "obj"].contains(&x.to_ascii_lowercase().as_str()))
        })
        .collect();
    v.sort();
    Ok(v)
}

/// The mesh files of `paths`: a folder gives its mesh files (`mesh_files_in`; one without any is
/// an error, `label` before its name), a file itself.
pub fn mesh_files<P: AsRef<Path>>(
    paths: &[P],
    label: &str,
) -> Result<Vec<std::path::PathBuf>, String> {
    let mut out = Vec::new();
    for p in paths {
        let p = p.as_ref();
        if p.is_dir() {
            let v = mesh_files_in(p)?;
            if v.is_empty() {
                return Err(format!(
                    "{label}{}: no .stl, .ply or .obj file in the folder",
                    p.display()
                ));
            }
            out.extend(v);
        } else {
            out.push(p.to_path_buf());
        }
    }
    Ok(out)
}

/// `--threads` if given (clap checks 1 to `MAX_THREADS`), or every core.
pub fn threads_or_all(threads: Option<usize>) -> usize {
    threads.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    })
}

/// Most worker threads a study takes.
pub const MAX_THREADS: usize = 1024;
/// Most runs per level a study takes (a study's tasks are listed up front).
pub const MAX_RUNS: usize = 100_000;

/// A clap value parser for a count in `lo..=hi` (clap's error names the flag, the value and the
/// range).
pub fn count_in(lo: usize, hi: usize) -> clap::builder::RangedU64ValueParser<usize> {
    clap::builder::RangedU64ValueParser::new().range(lo as u64..=hi as u64)
}

/// A comma-separated list without repeats; `allowed` (what the flag takes) goes into the error
/// naming an entry that cannot be read.
fn parse_list<T: PartialEq>(
    s: &str,
    allowed: &str,
    f: impl Fn(&str) -> Option<T>,
) -> Result<Vec<T>, String> {
    parse_list_why(s, |x| {
        f(x).ok_or_else(|| format!("cannot read {x:?} (expected {allowed})"))
    })
}

/// `parse_list` whose entries say themselves why they cannot be read.
fn parse_list_why<T: PartialEq>(
    s: &str,
    f: impl Fn(&str) -> Result<T, String>,
) -> Result<Vec<T>, String> {
    let mut list: Vec<T> = Vec::new();
    for x in s.split(',').map(str::trim) {
        let v = f(x)?;
        if list.contains(&v) {
            return Err(format!("{x:?} is listed twice"));
        }
        list.push(v);
    }
    Ok(list)
}

/// A list of sizes (bench problem counts, mesh vertices), each 1 to `MAX_BENCH_SIZE`.
#[derive(Clone, Debug)]
pub struct Sizes(pub Vec<usize>);

/// The largest size `acetab bench` takes in a list.
pub const MAX_BENCH_SIZE: usize = 1_000_000;

/// Parse a list of sizes (clap value parser).
pub fn sizes(s: &str) -> Result<Sizes, String> {
    let allowed = format!("sizes 1 to {MAX_BENCH_SIZE}");
    parse_list(s, &allowed, |x| {
        x.parse::<usize>()
            .ok()
            .filter(|n| (1..=MAX_BENCH_SIZE).contains(n))
    })
    .map(Sizes)
}

/// `--levels`: noise levels, a list of 1 to 5 (clap value parser).
#[derive(Clone, Debug)]
pub struct Levels(pub Vec<u32>);

/// Parse `--levels`.
pub fn levels(s: &str) -> Result<Levels, String> {
    parse_list(s, "levels 1 to 5", |x| {
        x.parse::<u32>().ok().filter(|l| (1..=5).contains(l))
    })
    .map(Levels)
}

/// `--views`: the X-ray views, each the antero-posterior view turned about body axes (clap
/// value parser).
#[derive(Clone, Debug)]
pub struct Views(pub Vec<acetab::sim::ViewRotation>);

/// Parse `--views` ("z:0,z:20,z:-20"; a view may chain turns, "z:20+x:-15").
pub fn views(s: &str) -> Result<Views, String> {
    let list = parse_list_why(s, |x| {
        x.parse::<acetab::sim::ViewRotation>().map_err(|e| {
            format!("cannot read {x:?}: {e} (a view is AXIS:DEGREES, AXIS x, y or z, e.g. z:20)")
        })
    })?;
    let g = acetab::sim::XrayGeometry {
        views: list.clone(),
        ..Default::default()
    };
    g.validate().map_err(|e| e.to_string())?;
    Ok(Views(list))
}

/// `--realistic`: the realistic protocol's error settings, each KEY=VALUE over the defaults
/// (clap value parser).
#[derive(Clone, Debug)]
pub struct Realistic(pub acetab::sim::RealisticErrors);

/// Parse `--realistic` ("left_out=0,pose_deg=2"; keys as `RealisticErrors`' fields).
pub fn realistic(s: &str) -> Result<Box<Realistic>, String> {
    let mut e = acetab::sim::RealisticErrors::default();
    for item in s.split(',').map(str::trim).filter(|x| !x.is_empty()) {
        let (key, value) = item
            .split_once('=')
            .ok_or_else(|| format!("{item:?}: expected KEY=VALUE"))?;
        let v: f64 = value
            .trim()
            .parse()
            .map_err(|_| format!("{item:?}: {value:?} is not a number"))?;
        let field = match key.trim() {
            "pose_deg" => &mut e.pose_deg,
            "pose_mm" => &mut e.pose_mm,
            "magnification" => &mut e.magnification,
            "left_out" => &mut e.left_out,
            "drift_px" => &mut e.drift_px,
            "drift_length_px" => &mut e.drift_length_px,
            "jitter_px" => &mut e.jitter_px,
            "click_px" => &mut e.click_px,
            "raster_px" => &mut e.raster_px,
            other => {
                return Err(format!(
                    "{other:?} is not a setting; expected pose_deg, pose_mm, magnification, \
                     left_out, drift_px, drift_length_px, jitter_px, click_px or raster_px"
                ))
            }
        };
        *field = v;
    }
    e.validate().map_err(|e| e.to_string())?;
    Ok(Box::new(Realistic(e)))
}

/// `--pose-prior DEG,MM`: the pose refinement's prior SDs (clap value parser), each finite and
/// above 0.
pub fn pose_prior(s: &str) -> Result<acetab::solve::PoseParams, String> {
    let (deg, mm) = s
        .split_once(',')
        .ok_or_else(|| format!("{s:?}: expected DEG,MM (e.g. 2,5)"))?;
    let number = |what: &str, v: &str| -> Result<f64, String> {
        v.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite() && *x > 0.0)
            .ok_or_else(|| format!("{what} {v:?} must be a number above 0"))
    };
    Ok(acetab::solve::PoseParams {
        sigma_deg: number("rotation SD (degrees)", deg)?,
        sigma_mm: number("translation SD (mm)", mm)?,
        ..Default::default()
    })
}

/// `--methods`: a list of study methods (clap value parser).
#[derive(Clone, Debug)]
pub struct Methods(pub Vec<acetab::study::StudyMethod>);

/// Parse `--methods` (names in any case).
pub fn methods(s: &str) -> Result<Methods, String> {
    use acetab::study::StudyMethod;
    let names = StudyMethod::ALL.map(StudyMethod::name).join(", ");
    parse_list(s, &names, |x| {
        StudyMethod::from_name(&x.to_ascii_lowercase())
    })
    .map(Methods)
}

/// `--uncertainty-samples` of a study: 0 (off) or 2 to 1000 (one resample has no spread).
pub fn study_samples(s: &str) -> Result<u64, String> {
    match s.trim().parse::<u64>() {
        Ok(n) if n == 0 || (MIN_RESAMPLES as u64..=MAX_RESAMPLES as u64).contains(&n) => Ok(n),
        _ => Err(format!(
            "{s:?}: expected 0 (off) or {MIN_RESAMPLES} to {MAX_RESAMPLES} (one resample has no spread)"
        )),
    }
}

/// Parse one study method (names in any case).
pub fn method(s: &str) -> Result<acetab::study::StudyMethod, String> {
    use acetab::study::StudyMethod;
    StudyMethod::from_name(&s.trim().to_ascii_lowercase()).ok_or_else(|| {
        let names = StudyMethod::ALL.map(StudyMethod::name).join(", ");
        format!("unknown method {s:?}; expected one of {names}")
    })
}

/// `--calibration`: the cup calibration file, "none" (the resamples alone, no bias), or None
/// for the one shipped for the protocol (`realistic` or ideal) and `estimator`; it must have been
/// learned for `estimator`, which needs a prior (`has_prior`) when it is the prior's region.
/// Returns the calibration and where it came from.
pub fn calibration(
    arg: &Option<String>,
    realistic: bool,
    estimator: acetab::pipeline::CupEstimator,
    has_prior: bool,
    views: &[acetab::views::ViewRotation],
) -> Result<(acetab::pipeline::CupCalibration, String), String> {
    use acetab::pipeline::{CupCalibration, CupEstimator};
    if estimator == CupEstimator::PriorRegion && !has_prior {
        return Err(
            "--cup-estimator prior-region: the region is the prior's; give a --prior (default or a file)"
                .into(),
        );
    }
    let directions: Vec<_> = views.iter().map(|v| v.source_direction()).collect();
    let (shipped, shipped_name, _) =
        CupCalibration::shipped_for_views(realistic, estimator, &directions);
    let cal = CupCalibration::for_estimator(arg.as_deref(), || shipped, estimator)
        .map_err(|e| format!("--calibration {e}"))?;
    let source = match arg.as_deref() {
        None => format!("shipped {shipped_name}"),
        Some(choice) => choice.to_string(),
    };
    Ok((cal, source))
}

/// `--cup-estimator` (clap value parser).
pub fn cup_estimator(s: &str) -> Result<acetab::pipeline::CupEstimator, String> {
    acetab::pipeline::CupEstimator::parse(s.trim()).ok_or_else(|| {
        let names = acetab::pipeline::CupEstimator::ALL
            .map(|e| e.name())
            .join(", ");
        format!("unknown cup estimator {s:?}; expected one of {names}")
    })
}

/// `--shard I/N`, 0 <= I < N (clap value parser).
pub fn shard(s: &str) -> Result<(usize, usize), String> {
    let bad = || format!("expected I/N with 0 <= I < N, got {s:?}");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n): (usize, usize) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 || i >= n {
        return Err(bad());
    }
    Ok((i, n))
}

/// The study's summary (summary.json's `summary` array) as one JSON line on stdout, or the table.
pub fn print_summary_as(rows: &[acetab::study::Row], json: bool) -> Result<(), String> {
    if json {
        let v = serde_json::to_string(&summarize(rows)).map_err(|e| e.to_string())?;
        println!("{v}");
    } else {
        print_summary(rows);
    }
    Ok(())
}

/// The study's summary as a table on stdout, then srvf against its better baseline per level.
pub fn print_summary(rows: &[acetab::study::Row]) {
    print_table(rows);
    for c in acetab::study::compare::compare("", rows) {
        let [lo, hi] = c.difference_ci95_mm;
        println!(
            "{} against {}, level {} ({} paired runs): {:.2}x, difference {:+.3} mm (95 %: {:+.3} to {:+.3}): {}",
            c.method.name(),
            c.baseline.name(),
            c.level,
            c.pairs,
            c.ratio,
            c.difference_mm,
            lo,
            hi,
            c.verdict.describe()
        );
    }
}

/// The summary table alone.
fn print_table(rows: &[acetab::study::Row]) {
    println!(
        "{:<17} {:>5} {:>5} {:>6} {:>9} {:>8} {:>9} {:>9} {:>11} {:>9} {:>9} {:>9} {:>9} {:>9} {:>6}",
        "method",
        "level",
        "runs",
        "failed",
        "fallbacks",
        "restarts",
        "MAE mm",
        "SD",
        "cup err mm",
        "|cup|<=1",
        "surface",
        "limb",
        "median s",
        "|err|<=SD",
        "Brier"
    );
    for s in summarize(rows) {
        println!(
            "{:<17} {:>5} {:>5} {:>6} {:>9} {:>8} {:>9.3} {:>9.3} {:>+11.2} {:>6}/{:<2} {:>6}/{:<2} {:>9} {:>9.2} {:>9} {:>6}",
            s.method.name(),
            s.level,
            s.runs,
            s.failed,
            s.fallbacks,
            s.restarted,
            s.mae_mean,
            s.mae_sd,
            s.cup_error_mean,
            s.cup_within_1mm,
            s.runs,
            s.surface_fit_within_1mm,
            s.runs,
            s.limb_within_1mm
                .map_or_else(|| "-".to_string(), |k| format!("{k:>6}/{:<2}", s.runs)),
            s.median_seconds,
            s.cup_sd_coverage
                .map_or_else(|| "-".to_string(), |c| format!("{:.0} %", 100.0 * c)),
            s.brier_mean
                .map_or_else(|| "-".to_string(), |b| format!("{b:.3}"))
        );
    }
}

#[cfg(test)]
mod unstage_tests {
    use super::*;

    #[test]
    fn the_staging_folder_is_named_as_the_users() {
        let out = Path::new("/data/run1");
        let msg = "/data/.run1.partial-Ab12Cd/example-srvf/view0.png: cannot write: disk full";
        assert_eq!(
            unstage(msg, out),
            "/data/run1/example-srvf/view0.png: cannot write: disk full"
        );
        // Companion: a message without the staging folder is left as it is.
        let plain = "/data/other/x.csv: cannot write: disk full";
        assert_eq!(unstage(plain, out), plain);
    }
}
