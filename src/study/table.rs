//! The study's tables: one row per run (runs.csv), the per-method-and-level summary
//! (summary.json), and merging shards.

use super::method::StudyMethod;
use super::task::Task;
use crate::io::write_atomic;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One run's result, one line of runs.csv (csv + serde; numbers at fixed precision, 6 decimals
/// and 4 for seconds). Metrics are NaN for a run that failed (`error` says why).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct Row {
    /// The method.
    pub method: StudyMethod,
    /// The start's noise level.
    pub level: u32,
    /// The run.
    pub run: usize,
    /// Its seed.
    pub seed: u64,
    /// Mean truth -> result distance, mm.
    #[serde(serialize_with = "six")]
    pub mae_mm: f64,
    /// Its SD, mm.
    #[serde(serialize_with = "six")]
    pub sd_mm: f64,
    /// Its 95th percentile, mm.
    #[serde(serialize_with = "six")]
    pub p95_mm: f64,
    /// Mean result -> truth distance over the truth's interior, mm.
    #[serde(serialize_with = "six")]
    pub recon_mae_mm: f64,
    /// The cup sphere's diameter, mm.
    #[serde(serialize_with = "six")]
    pub cup_diameter_mm: f64,
    /// The truth's sphere diameter, mm.
    #[serde(serialize_with = "six")]
    pub gt_cup_diameter_mm: f64,
    /// The sphere fitted to the whole reconstructed surface (the cup uses its observed part).
    #[serde(serialize_with = "six")]
    pub surface_fit_diameter_mm: f64,
    /// The sphere fitted to the outlines' limbs before any deformation (NaN when not used).
    #[serde(serialize_with = "six")]
    pub limb_diameter_mm: f64,
    /// The last solve converged.
    pub converged: bool,
    /// LM iterations.
    pub iterations: usize,
    /// Stage B correspondence rounds.
    pub correspondence_updates: usize,
    /// Seconds for the reconstruction.
    #[serde(serialize_with = "four")]
    pub seconds: f64,
    /// Why the run failed (empty when it did not).
    pub error: String,
    /// The fallback that gave the result when the method's own failed a guard ("srvf-shape",
    /// "icp-normvec", "rigid", "refine-poses"), or empty.
    #[serde(default)]
    pub fallback: String,
    /// SD of the cup diameter over the run's resamples (`cup_report`, the same resampling as
    /// `acetab reconstruct`), mm; NaN when the study resamples nothing or the run failed.
    #[serde(serialize_with = "six")]
    pub cup_sd_mm: f64,
    /// The resamples' probability of the catalogue size the cup was given; NaN as above.
    #[serde(serialize_with = "six")]
    pub size_probability: f64,
    /// Brier score of the resamples' size probabilities against the truth's catalogue size:
    /// the sum over sizes of (p - [size is the truth's])^2, 0 (certain and right) to 2 (certain
    /// and wrong); NaN as above.
    #[serde(serialize_with = "six")]
    pub brier: f64,
    /// The cup's radiographic inclination from the rim (`solve::rim_orientation`), degrees; NaN
    /// when the run failed or the outlines trace no rim.
    #[serde(serialize_with = "six", default = "nan")]
    pub inclination_deg: f64,
    /// Its radiographic anteversion, degrees; NaN as above.
    #[serde(serialize_with = "six", default = "nan")]
    pub anteversion_deg: f64,
    /// Inclination minus the truth's own (the same fit on the truth's noise-free outlines and
    /// sphere), degrees; NaN as above.
    #[serde(serialize_with = "six", default = "nan")]
    pub inclination_err_deg: f64,
    /// Anteversion minus the truth's own, degrees; NaN as above.
    #[serde(serialize_with = "six", default = "nan")]
    pub anteversion_err_deg: f64,
    /// Where a restarted run's result started (`pipeline::PlacementParams::restart_above_px`):
    /// "given" when the given start's result stayed the best, else the tilt ("+u", "-u", "+v",
    /// "-v"); empty when the run did not restart.
    #[serde(default)]
    pub restart: String,
    /// How far the result's outlines lie from the annotations (`SolveLog::outline_px`, the RMS
    /// over all views, pixels); NaN when the run failed. Annotation noise alone leaves 1-3 px.
    #[serde(serialize_with = "six", default = "nan")]
    pub outline_px: f64,
    /// The largest turn the pose refinement gave a view (`SolveLog::pose_corrections`), degrees;
    /// NaN when the run refined no poses or failed.
    #[serde(serialize_with = "six", default = "nan")]
    pub pose_turn_deg: f64,
    /// The largest shift it gave a view, mm; NaN as above.
    #[serde(serialize_with = "six", default = "nan")]
    pub pose_shift_mm: f64,
    /// How far the result lies displaced as a whole: the length of the translation that brings
    /// it nearest the truth (`report::shifted_accuracy`), mm; NaN when the run failed.
    #[serde(serialize_with = "six", default = "nan")]
    pub frame_shift_mm: f64,
    /// `mae_mm` after that translation: the shape's error without the displacement, mm; NaN as
    /// above.
    #[serde(serialize_with = "six", default = "nan")]
    pub shifted_mae_mm: f64,
    /// Why the run tried the tilted starts (`pipeline::RestartCause::name`): "outlines" (the
    /// given start's result left them farther than the trigger), "folded" (folded over at its
    /// rim) or "guard-" and the guard that refused it ("guard-cup", ...); empty when it did not
    /// try them.
    #[serde(default)]
    pub restart_cause: String,
    /// The guard the method's own result failed when a fallback gave the result
    /// (`pipeline::GuardFailure::name`: "cup", "folded", "rough", "limb-sphere",
    /// "non-finite-vertex", "non-finite-pose", "reprojection", "outlines"); empty when no
    /// fallback was taken.
    #[serde(default)]
    pub fallback_guard: String,
    /// The translation whose length is `frame_shift_mm`, along x (body axes: left-right), mm:
    /// it moves the result towards the truth, so it is minus where the result lies off; NaN
    /// when the run failed or in a runs.csv written without it.
    #[serde(serialize_with = "six", default = "nan")]
    pub frame_shift_x_mm: f64,
    /// The same along y (antero-posterior), mm.
    #[serde(serialize_with = "six", default = "nan")]
    pub frame_shift_y_mm: f64,
    /// The same along z (longitudinal), mm.
    #[serde(serialize_with = "six", default = "nan")]
    pub frame_shift_z_mm: f64,
    /// The result's translation to the truth along its depth axis (`pipeline::depth_axis`),
    /// before any depth offset the run was given (`CupParams::depth_mm`), mm: positive where
    /// the result sat too deep, away from the opening. What `acetab calibrate` learns the
    /// offset from. NaN when the run failed, the result had no depth axis, or in a runs.csv
    /// written without it.
    #[serde(serialize_with = "six", default = "nan")]
    pub depth_offset_mm: f64,
}

/// The columns runs.csv gained with the cup's orientation: a file without them still reads (NaN).
const ORIENTATION_COLUMNS: usize = 4;
/// The column runs.csv gained with the restarts (`restart`): a file without it still reads.
const RESTART_COLUMNS: usize = 1;
/// The column runs.csv gained after the restarts (`outline_px`): a file without it reads (NaN).
const OUTLINE_COLUMNS: usize = 1;
/// The columns runs.csv gained after the outline distance (`pose_turn_deg`, `pose_shift_mm`): a file
/// without them reads (NaN).
const POSE_COLUMNS: usize = 2;
/// The columns runs.csv gained after the pose corrections (`frame_shift_mm`,
/// `shifted_mae_mm`): a file without them reads (NaN).
const SHIFT_COLUMNS: usize = 2;
/// The columns runs.csv gained after the shifts (`restart_cause`, `fallback_guard`): a file
/// without them reads (empty).
const CAUSE_COLUMNS: usize = 2;
/// The columns runs.csv gained after the causes (`frame_shift_x_mm`, `_y_mm`, `_z_mm`): a file
/// without them reads (NaN).
const SHIFT_AXES_COLUMNS: usize = 3;
/// The column runs.csv gained after the shift's axes (`depth_offset_mm`): a file without it
/// reads (NaN).
const DEPTH_COLUMNS: usize = 1;

fn nan() -> f64 {
    f64::NAN
}

/// The methods that ran on any of `meshes` (name, runs), in order.
pub(super) fn methods_in(meshes: &[(String, Vec<Row>)]) -> Vec<StudyMethod> {
    let mut methods: Vec<StudyMethod> = meshes
        .iter()
        .flat_map(|(_, rows)| rows.iter().map(|r| r.method))
        .collect();
    methods.sort();
    methods.dedup();
    methods
}

/// Per mesh of `meshes`, what `value` reads from each run of `method` with a result (None:
/// the run is left out); meshes with nothing left are dropped.
pub(super) fn per_mesh<T>(
    meshes: &[(String, Vec<Row>)],
    method: StudyMethod,
    value: impl Fn(&Row) -> Option<T>,
) -> Vec<Vec<T>> {
    meshes
        .iter()
        .map(|(_, rows)| {
            rows.iter()
                .filter(|r| r.method == method && r.error.is_empty())
                .filter_map(&value)
                .collect::<Vec<T>>()
        })
        .filter(|v| !v.is_empty())
        .collect()
}

impl Row {
    /// A failed run of `t` with the reason.
    pub fn failed(t: &Task, error: &str) -> Row {
        Row {
            method: t.method,
            level: t.level,
            run: t.run,
            seed: t.seed,
            mae_mm: f64::NAN,
            sd_mm: f64::NAN,
            p95_mm: f64::NAN,
            recon_mae_mm: f64::NAN,
            cup_diameter_mm: f64::NAN,
            gt_cup_diameter_mm: f64::NAN,
            surface_fit_diameter_mm: f64::NAN,
            limb_diameter_mm: f64::NAN,
            converged: false,
            iterations: 0,
            correspondence_updates: 0,
            seconds: 0.0,
            error: error.to_string(),
            fallback: String::new(),
            cup_sd_mm: f64::NAN,
            size_probability: f64::NAN,
            brier: f64::NAN,
            inclination_deg: f64::NAN,
            anteversion_deg: f64::NAN,
            inclination_err_deg: f64::NAN,
            anteversion_err_deg: f64::NAN,
            restart: String::new(),
            outline_px: f64::NAN,
            pose_turn_deg: f64::NAN,
            pose_shift_mm: f64::NAN,
            frame_shift_mm: f64::NAN,
            shifted_mae_mm: f64::NAN,
            restart_cause: String::new(),
            fallback_guard: String::new(),
            frame_shift_x_mm: f64::NAN,
            frame_shift_y_mm: f64::NAN,
            frame_shift_z_mm: f64::NAN,
            depth_offset_mm: f64::NAN,
        }
    }

    /// The first value no run of the program can have, as runs.csv's column, the value and what
    /// it must be (NaN is "not recorded" and passes everywhere): a level outside 0-5, an
    /// infinite number, a negative distance, SD, diameter or time, a probability outside [0, 1]
    /// or a Brier score outside [0, 2]. A hand-edited or damaged file is refused with it
    /// rather than learned or summarised from.
    pub fn implausible(&self) -> Option<String> {
        // The library's noise levels (`NoiseLevel::level`): 0, no start noise, runs from the
        // library and Python; the command line's studies take 1-5.
        if crate::sim::NoiseLevel::level(self.level).is_none() {
            return Some(format!(
                "column \"level\": {} is not a noise level 0 to 5",
                self.level
            ));
        }
        let at_least_0 = [
            ("mae_mm", self.mae_mm),
            ("sd_mm", self.sd_mm),
            ("p95_mm", self.p95_mm),
            ("recon_mae_mm", self.recon_mae_mm),
            ("seconds", self.seconds),
            ("cup_sd_mm", self.cup_sd_mm),
            ("outline_px", self.outline_px),
            ("pose_turn_deg", self.pose_turn_deg),
            ("pose_shift_mm", self.pose_shift_mm),
            ("frame_shift_mm", self.frame_shift_mm),
            ("shifted_mae_mm", self.shifted_mae_mm),
        ];
        let above_0 = [
            ("cup_diameter_mm", self.cup_diameter_mm),
            ("gt_cup_diameter_mm", self.gt_cup_diameter_mm),
            ("surface_fit_diameter_mm", self.surface_fit_diameter_mm),
            ("limb_diameter_mm", self.limb_diameter_mm),
        ];
        let unit = [("size_probability", self.size_probability)];
        // A Brier score over the catalogue's sizes: 0 (certain and right) to 2 (certain, wrong).
        let brier = [("brier", self.brier)];
        let signed = [
            ("inclination_deg", self.inclination_deg),
            ("anteversion_deg", self.anteversion_deg),
            ("inclination_err_deg", self.inclination_err_deg),
            ("anteversion_err_deg", self.anteversion_err_deg),
            ("frame_shift_x_mm", self.frame_shift_x_mm),
            ("frame_shift_y_mm", self.frame_shift_y_mm),
            ("frame_shift_z_mm", self.frame_shift_z_mm),
            ("depth_offset_mm", self.depth_offset_mm),
        ];
        let bad = |column: &str, v: f64, expected: &str| {
            Some(format!(
                "column {column:?}: {} is not {expected} (or NaN: not recorded)",
                crate::io::shown(&v.to_string())
            ))
        };
        let groups: [(&[(&str, f64)], fn(f64) -> bool, &str); 5] = [
            (
                &at_least_0,
                |v| v.is_finite() && v >= 0.0,
                "a finite number >= 0",
            ),
            (
                &above_0,
                |v| v.is_finite() && v > 0.0,
                "a finite number > 0",
            ),
            (
                &unit,
                |v| (0.0..=1.0).contains(&v),
                "a probability in [0, 1]",
            ),
            (
                &brier,
                |v| (0.0..=2.0).contains(&v),
                "a Brier score in [0, 2]",
            ),
            (&signed, f64::is_finite, "a finite number"),
        ];
        for (columns, ok, expected) in groups {
            for &(column, v) in columns {
                if !v.is_nan() && !ok(v) {
                    return bad(column, v, expected);
                }
            }
        }
        None
    }

    /// Cup minus truth, mm.
    pub fn cup_error_mm(&self) -> f64 {
        self.cup_diameter_mm - self.gt_cup_diameter_mm
    }

    /// Canonical order: method, level, run.
    pub fn key(&self) -> (StudyMethod, u32, usize) {
        (self.method, self.level, self.run)
    }
}

/// Problems with study files.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StudyError {
    /// A study file cannot be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A study file cannot be written.
    #[error("{path}: cannot write: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A runs.csv line that is not a run.
    #[error("{path}: line {line}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The line (1 is the header).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// Two shards of different studies.
    #[error("{path}: study field {field:?} is {value}, but {first} has {expected}: not shards of one study")]
    Mismatch {
        /// The shard.
        path: PathBuf,
        /// The study setting that differs.
        field: String,
        /// Its value there.
        value: String,
        /// The first shard.
        first: PathBuf,
        /// Its value in the first shard.
        expected: String,
    },
    /// The same run in two shards.
    #[error("run {method} level {level} run {run} appears in more than one shard ({path})")]
    Duplicate {
        /// The run's method.
        method: String,
        /// Its level.
        level: u32,
        /// Its number.
        run: usize,
        /// The second shard.
        path: PathBuf,
    },
    /// The shards given are not the whole set their summary.json files name.
    #[error("shards {missing} of {count} are missing (the folders given hold {present}); merge every shard of the study")]
    ShardGap {
        /// The missing shard indices, as "I/N" joined by commas.
        missing: String,
        /// The shard count N.
        count: usize,
        /// The shards present.
        present: String,
    },
    /// The shards hold fewer runs than their study's settings make (a shard whose runs were
    /// lost or cut short).
    #[error("the shards hold {held} of the study's {expected} runs (levels x runs x methods in summary.json); missing: {first}; run the shards again")]
    Incomplete {
        /// Runs the shards hold.
        held: usize,
        /// Runs the study makes.
        expected: usize,
        /// The first missing runs, named.
        first: String,
    },
}

/// Every run the study of merged settings `meta` (summary.json's `study`, as `merge_meta` gives
/// it) makes, levels x runs x methods, must be among `rows`; a study whose settings do not say
/// (an older summary.json) is not checked.
pub fn check_complete(rows: &[Row], meta: &serde_json::Value) -> Result<(), StudyError> {
    let (Some(levels), Some(runs), Some(methods)) = (
        meta.get("levels").and_then(|v| v.as_array()),
        meta.get("runs").and_then(|v| v.as_u64()),
        meta.get("methods").and_then(|v| v.as_array()),
    ) else {
        return Ok(());
    };
    let held: std::collections::BTreeSet<(StudyMethod, u32, usize)> =
        rows.iter().map(|r| r.key()).collect();
    let mut missing = Vec::new();
    let mut expected = 0;
    for m in methods
        .iter()
        .filter_map(|m| m.as_str().and_then(StudyMethod::from_name))
    {
        for l in levels.iter().filter_map(|l| l.as_u64()) {
            for r in 0..runs as usize {
                expected += 1;
                if !held.contains(&(m, l as u32, r)) {
                    missing.push(format!("{} level {l} run {r}", m.name()));
                }
            }
        }
    }
    if missing.is_empty() {
        return Ok(());
    }
    let more = missing.len().saturating_sub(3);
    let mut first = missing[..missing.len().min(3)].join(", ");
    if more > 0 {
        first += &format!(" and {more} more");
    }
    Err(StudyError::Incomplete {
        held: expected - missing.len(),
        expected,
        first,
    })
}

fn six<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(&format_args!("{v:.6}"))
}

fn four<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(&format_args!("{v:.4}"))
}

/// The header line of runs.csv: `Row`'s field names in order, as the csv writer writes them.
fn header() -> csv::StringRecord {
    let t = Task {
        method: StudyMethod::Srvf,
        level: 0,
        run: 0,
        seed: 0,
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    let bytes = w
        .serialize(Row::failed(&t, ""))
        .ok()
        .and_then(|_| w.into_inner().ok())
        .unwrap_or_default();
    let mut r = csv::Reader::from_reader(&bytes[..]);
    r.headers().cloned().unwrap_or_default()
}

/// Write rows as CSV (an error message with commas or line breaks is quoted).
pub fn write_csv(rows: &[Row], path: &Path) -> Result<(), StudyError> {
    let werr = |e: std::io::Error| StudyError::Write {
        path: path.to_path_buf(),
        source: e,
    };
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in rows {
        w.serialize(r).map_err(|e| werr(std::io::Error::other(e)))?;
    }
    if rows.is_empty() {
        w.write_record(&header())
            .map_err(|e| werr(std::io::Error::other(e)))?;
    }
    let bytes = w.into_inner().map_err(|e| werr(e.into_error()))?;
    write_atomic(path, &bytes).map_err(werr)
}

/// Read a runs.csv written by `write_csv`.
pub fn read_csv(path: &Path) -> Result<Vec<Row>, StudyError> {
    let perr = |line: usize, reason: String| StudyError::Parse {
        path: path.to_path_buf(),
        line,
        reason,
    };
    let mut rd = csv::Reader::from_path(path).map_err(|e| match e.into_kind() {
        csv::ErrorKind::Io(source) => StudyError::Read {
            path: path.to_path_buf(),
            source,
        },
        other => perr(1, format!("{other:?}")),
    })?;
    let full = header();
    // Files written before the depth offset, before the shift's axes too, before the cause
    // columns too, before the shift
    // columns, before the pose columns, before the outline column as well, before the restart
    // column, or before the orientation columns, have the header without them.
    let prefix = |n: usize| -> csv::StringRecord { full.iter().take(n).collect() };
    let older: Vec<usize> = [
        DEPTH_COLUMNS,
        SHIFT_AXES_COLUMNS,
        CAUSE_COLUMNS,
        SHIFT_COLUMNS,
        POSE_COLUMNS,
        OUTLINE_COLUMNS,
        RESTART_COLUMNS,
        ORIENTATION_COLUMNS,
    ]
    .iter()
    .scan(full.len(), |n, k| {
        *n -= k;
        Some(*n)
    })
    .collect();
    let want = match rd.headers() {
        Ok(h) if *h == full => full.clone(),
        Ok(h) if older.iter().any(|&n| *h == prefix(n)) => h.clone(),
        _ => {
            let want = full;
            let names: Vec<&str> = want.iter().collect();
            return Err(perr(
                1,
                format!("expected the header {:?}", names.join(",")),
            ));
        }
    };
    let mut rows = Vec::new();
    // Each run's line, for naming the first of two lines of one run.
    let mut lines: BTreeMap<(StudyMethod, u32, usize), usize> = BTreeMap::new();
    for rec in rd.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line() as usize);
            match e.kind() {
                csv::ErrorKind::UnequalLengths { len, .. } => {
                    perr(line, format!("{len} fields, expected {}", want.len()))
                }
                other => perr(line, format!("{other:?}")),
            }
        })?;
        let line = rec.position().map_or(0, |p| p.line() as usize);
        let row: Row = rec.deserialize(Some(&want)).map_err(|e| {
            let reason = match e.kind() {
                csv::ErrorKind::Deserialize { err, .. } => match err.field() {
                    Some(k) => {
                        let column = want.get(k as usize).unwrap_or("?");
                        let expected = match column {
                            "converged" => "true or false",
                            "method" => "a method (srvf, icp, icp-normvec, or one of them -paper)",
                            "level" | "run" | "seed" | "iterations" | "correspondence_updates" => {
                                "a whole number"
                            }
                            _ => "a number",
                        };
                        let value = rec.get(k as usize).unwrap_or("");
                        format!("column {column:?}: {value:?} is not {expected}")
                    }
                    None => err.kind().to_string(),
                },
                other => format!("{other:?}"),
            };
            perr(line, reason)
        })?;
        if let Some(reason) = row.implausible() {
            return Err(perr(line, reason));
        }
        if let Some(first) = lines.insert(row.key(), line) {
            return Err(perr(
                line,
                format!(
                    "{} level {} run {} is already on line {} (a run is one line; two studies' files joined?)",
                    row.method.name(),
                    row.level,
                    row.run,
                    first
                ),
            ));
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Per method and level.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    /// The method.
    pub method: StudyMethod,
    /// The start's noise level.
    pub level: u32,
    /// Runs.
    pub runs: usize,
    /// Runs whose last solve converged.
    pub converged: usize,
    /// Runs that failed.
    pub failed: usize,
    /// Runs whose result came from a fallback.
    pub fallbacks: usize,
    /// Runs that restarted, from tilted starts or the limb sphere (`Row::restart` not empty).
    pub restarted: usize,
    /// Restarted runs whose result came from another start than the given one (a tilted start
    /// or the limb sphere).
    pub restart_tilted: usize,
    /// Restarted runs by why (`Row::restart_cause`: "outlines", "folded", "guard-" and the
    /// guard); runs read from a runs.csv written before the cause was recorded are not counted.
    pub restart_causes: BTreeMap<String, usize>,
    /// Runs that fell back, by the guard the method's own result failed (`Row::fallback_guard`).
    pub fallback_guards: BTreeMap<String, usize>,
    /// Mean MAE, mm.
    pub mae_mean: f64,
    /// SD of the MAE (dividing by n), mm.
    pub mae_sd: f64,
    /// Mean cup error, mm.
    pub cup_error_mean: f64,
    /// SD of the cup error, mm.
    pub cup_error_sd: f64,
    /// Runs with |cup diameter - truth| <= 1 mm.
    pub cup_within_1mm: usize,
    /// The same for the whole-surface sphere fit and for the limb sphere (None, null in JSON,
    /// when no run had a limb sphere: the paper's protocol and pose refinement skip stage 0).
    pub surface_fit_within_1mm: usize,
    /// See `surface_fit_within_1mm`.
    pub limb_within_1mm: Option<usize>,
    /// Runs with a cup SD (`Row::cup_sd_mm`), and of those, the share whose cup error is
    /// within it (68 % for a Gaussian that means what it says); None without resamples.
    pub cup_sd_runs: usize,
    /// See `cup_sd_runs`.
    pub cup_sd_coverage: Option<f64>,
    /// Mean Brier score of the size probabilities over those runs; None without resamples.
    pub brier_mean: Option<f64>,
    /// Median seconds per run.
    pub median_seconds: f64,
}

/// Mean and SD of the runs themselves (the SD divides by n).
fn mean_sd(v: &[f64]) -> (f64, f64) {
    crate::geom::mean_sd(v, false)
}

/// Runs whose `diameter` is within 1 mm of the truth's.
fn within(rows: &[&Row], diameter: impl Fn(&Row) -> f64) -> usize {
    rows.iter()
        .filter(|r| (diameter(r) - r.gt_cup_diameter_mm).abs() <= 1.0)
        .count()
}

/// How often each non-empty name occurs.
fn counts<'a>(names: impl Iterator<Item = &'a str>) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    for n in names.filter(|n| !n.is_empty()) {
        *out.entry(n.to_string()).or_insert(0) += 1;
    }
    out
}

/// Summaries in canonical order. Failed runs count in `runs` and `failed`, not in the means.
pub fn summarize(rows: &[Row]) -> Vec<Summary> {
    let mut keys: Vec<(StudyMethod, u32)> = rows.iter().map(|r| (r.method, r.level)).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .map(|(method, level)| {
            let g: Vec<&Row> = rows
                .iter()
                .filter(|r| r.method == method && r.level == level)
                .collect();
            let ok: Vec<&Row> = g
                .iter()
                .copied()
                .filter(|r| r.error.is_empty() && r.mae_mm.is_finite())
                .collect();
            let (mae_mean, mae_sd) = mean_sd(&ok.iter().map(|r| r.mae_mm).collect::<Vec<_>>());
            let ce: Vec<f64> = ok.iter().map(|r| r.cup_error_mm()).collect();
            let (cup_error_mean, cup_error_sd) = mean_sd(&ce);
            let with_sd: Vec<&Row> = ok
                .iter()
                .copied()
                .filter(|r| r.cup_sd_mm.is_finite() && r.brier.is_finite())
                .collect();
            let mut secs: Vec<f64> = g.iter().map(|r| r.seconds).collect();
            secs.sort_by(f64::total_cmp);
            Summary {
                method,
                level,
                runs: g.len(),
                converged: g.iter().filter(|r| r.converged).count(),
                failed: g.len() - ok.len(),
                fallbacks: g.iter().filter(|r| !r.fallback.is_empty()).count(),
                restarted: g.iter().filter(|r| !r.restart.is_empty()).count(),
                restart_tilted: g
                    .iter()
                    .filter(|r| !r.restart.is_empty() && r.restart != "given")
                    .count(),
                restart_causes: counts(g.iter().map(|r| r.restart_cause.as_str())),
                fallback_guards: counts(g.iter().map(|r| r.fallback_guard.as_str())),
                mae_mean,
                mae_sd,
                cup_error_mean,
                cup_error_sd,
                cup_within_1mm: ce.iter().filter(|e| e.abs() <= 1.0).count(),
                surface_fit_within_1mm: within(&ok, |r| r.surface_fit_diameter_mm),
                limb_within_1mm: ok
                    .iter()
                    .any(|r| r.limb_diameter_mm.is_finite())
                    .then(|| within(&ok, |r| r.limb_diameter_mm)),
                median_seconds: secs.get(secs.len() / 2).copied().unwrap_or(f64::NAN),
                cup_sd_runs: with_sd.len(),
                cup_sd_coverage: (!with_sd.is_empty()).then(|| {
                    with_sd
                        .iter()
                        .filter(|r| r.cup_error_mm().abs() <= r.cup_sd_mm)
                        .count() as f64
                        / with_sd.len() as f64
                }),
                brier_mean: (!with_sd.is_empty())
                    .then(|| with_sd.iter().map(|r| r.brier).sum::<f64>() / with_sd.len() as f64),
            }
        })
        .collect()
}

/// The study settings shards share, from their summary.json files (folders without one are
/// skipped): every field but `shard`, `seconds` and `merged` must agree, or the shards are not of
/// one study (so merged folders can be merged again). The result lists the folders under
/// `merged`.
pub fn merge_meta(dirs: &[PathBuf]) -> Result<serde_json::Value, StudyError> {
    let mut common: Option<(PathBuf, Settings)> = None;
    let mut shards: Vec<(PathBuf, usize, usize)> = Vec::new();
    let mut all_sharded = true;
    for d in dirs {
        let path = d.join("summary.json");
        let Some((study, shard)) = study_settings(&path)? else {
            continue;
        };
        match shard_of(&path, shard.as_ref())? {
            Some((i, n)) => shards.push((path.clone(), i, n)),
            // A merged folder (or one from before shards were recorded) holds shards of its
            // own: the set cannot be checked.
            None => all_sharded = false,
        }
        let Some((first, c)) = &common else {
            common = Some((path, study));
            continue;
        };
        if let Some((field, expected, value)) = first_difference(c, &study) {
            return Err(StudyError::Mismatch {
                path,
                field,
                value,
                first: first.clone(),
                expected,
            });
        }
    }
    if all_sharded {
        check_shard_set(&shards)?;
    }
    let mut meta = common.map(|(_, c)| c).unwrap_or_default();
    meta.insert("merged".into(), serde_json::json!(dirs));
    Ok(serde_json::Value::Object(meta))
}

/// The shard "I/N" a summary.json's study names (`shard`, its value in the file at `path`), if
/// it names one (a merged folder names none); one that is not "I/N" with 0 <= I < N is an error
/// naming the file and the value.
fn shard_of(
    path: &Path,
    shard: Option<&serde_json::Value>,
) -> Result<Option<(usize, usize)>, StudyError> {
    let Some(shard) = shard else {
        return Ok(None);
    };
    let parsed = shard.as_str().and_then(|s| {
        let (i, n) = s.split_once('/')?;
        let (i, n): (usize, usize) = (i.trim().parse().ok()?, n.trim().parse().ok()?);
        (i < n).then_some((i, n))
    });
    match parsed {
        Some(p) => Ok(Some(p)),
        None => Err(StudyError::Parse {
            path: path.to_path_buf(),
            line: 1,
            reason: format!("study.shard is {shard}: expected \"I/N\" with 0 <= I < N"),
        }),
    }
}

/// Shards named by the summaries (path, I, N) must share N and be the whole set 0..N: shards of
/// different counts, or a merge with a gap, are refused.
fn check_shard_set(shards: &[(PathBuf, usize, usize)]) -> Result<(), StudyError> {
    let Some((first, i0, count)) = shards.first() else {
        return Ok(());
    };
    if let Some((path, i, n)) = shards.iter().find(|s| s.2 != *count) {
        return Err(StudyError::Mismatch {
            path: path.clone(),
            field: "shard".into(),
            value: format!("\"{i}/{n}\""),
            first: first.clone(),
            expected: format!("\"{i0}/{count}\""),
        });
    }
    let mut present: Vec<usize> = shards.iter().map(|s| s.1).collect();
    present.sort_unstable();
    present.dedup();
    let missing: Vec<String> = (0..*count)
        .filter(|i| present.binary_search(i).is_err())
        .map(|i| format!("{i}/{count}"))
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    Err(StudyError::ShardGap {
        missing: missing.join(", "),
        count: *count,
        present: present
            .iter()
            .map(|i| format!("{i}/{count}"))
            .collect::<Vec<_>>()
            .join(", "),
    })
}

/// The settings of one study, as a summary.json's `study` object holds them.
type Settings = serde_json::Map<String, serde_json::Value>;

/// The `study` object of a summary.json without the fields that differ between shards, and its
/// `shard` if it names one; None when the file does not exist.
fn study_settings(
    path: &Path,
) -> Result<Option<(Settings, Option<serde_json::Value>)>, StudyError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => {
            return Err(StudyError::Read {
                path: path.to_path_buf(),
                source,
            })
        }
    };
    let bad = |reason: String| StudyError::Parse {
        path: path.to_path_buf(),
        line: 1,
        reason,
    };
    let v: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
    let Some(serde_json::Value::Object(study)) = v.get("study") else {
        return Err(bad("no \"study\" object".into()));
    };
    let mut study = study.clone();
    let shard = study.remove("shard");
    // What differs between shards of one study: the shard, its time, its command line and
    // engine counts.
    for k in ["seconds", "merged", "provenance", "engine"] {
        study.remove(k);
    }
    Ok(Some((study, shard)))
}

/// The first field (in name order) whose value differs between `a` and `b`, with both values
/// as JSON text ("missing" where absent).
fn first_difference(a: &Settings, b: &Settings) -> Option<(String, String, String)> {
    let show =
        |x: Option<&serde_json::Value>| x.map_or_else(|| "missing".into(), |v| v.to_string());
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    keys.into_iter()
        .find(|k| a.get(*k) != b.get(*k))
        .map(|k| (k.clone(), show(a.get(k)), show(b.get(k))))
}

/// Join the runs.csv of several shard folders, in canonical order; a run present twice is an error.
pub fn merge_dirs(dirs: &[PathBuf]) -> Result<Vec<Row>, StudyError> {
    let mut rows: Vec<(Row, PathBuf)> = Vec::new();
    for d in dirs {
        let p = d.join("runs.csv");
        for r in read_csv(&p)? {
            rows.push((r, p.clone()));
        }
    }
    rows.sort_by_key(|a| a.0.key());
    for w in rows.windows(2) {
        if w[0].0.key() == w[1].0.key() {
            let r = &w[1].0;
            return Err(StudyError::Duplicate {
                method: r.method.name().into(),
                level: r.level,
                run: r.run,
                path: w[1].1.clone(),
            });
        }
    }
    Ok(rows.into_iter().map(|(r, _)| r).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(method: StudyMethod, level: u32, run: usize, mae: f64) -> Row {
        let t = Task {
            method,
            level,
            run,
            seed: 9,
        };
        Row {
            mae_mm: mae,
            cup_diameter_mm: 50.5,
            gt_cup_diameter_mm: 50.0,
            converged: true,
            error: String::new(),
            ..Row::failed(&t, "")
        }
    }

    #[test]
    fn summary_counts_restarts_by_cause_and_fallbacks_by_guard() {
        let mut rows: Vec<Row> = (0..4).map(|k| row(StudyMethod::Srvf, 1, k, 0.8)).collect();
        for (r, cause) in rows.iter_mut().zip(["folded", "guard-rough", "folded"]) {
            r.restart = "+u".into();
            r.restart_cause = cause.into();
        }
        rows[3].fallback = "icp-normvec".into();
        rows[3].fallback_guard = "rough".into();
        let s = &summarize(&rows)[0];
        let map = |v: &[(&str, usize)]| -> BTreeMap<String, usize> {
            v.iter().map(|&(k, n)| (k.to_string(), n)).collect()
        };
        assert_eq!(s.restart_causes, map(&[("folded", 2), ("guard-rough", 1)]));
        assert_eq!(s.fallback_guards, map(&[("rough", 1)]));
        // Companion: a run with another cause is counted under it, not under the first's.
        rows[2].restart_cause = "outlines".into();
        let s = &summarize(&rows)[0];
        assert_ne!(s.restart_causes, map(&[("folded", 2), ("guard-rough", 1)]));
        assert_eq!(s.restart_causes["outlines"], 1);
    }

    #[test]
    fn summary_counts_the_runs_within_their_cup_sd_and_averages_brier() {
        // Cup errors +0.5 mm each (`row`); SDs 0.6, 0.4, 1.0 and one run without resamples.
        let mut rows: Vec<Row> = (0..4).map(|k| row(StudyMethod::Srvf, 1, k, 0.8)).collect();
        for (r, (sd, b)) in rows.iter_mut().zip([(0.6, 0.2), (0.4, 1.0), (1.0, 0.3)]) {
            r.cup_sd_mm = sd;
            r.brier = b;
        }
        let s = &summarize(&rows)[0];
        assert_eq!(s.cup_sd_runs, 3);
        assert!((s.cup_sd_coverage.unwrap() - 2.0 / 3.0).abs() < 1e-12);
        assert!((s.brier_mean.unwrap() - 0.5).abs() < 1e-12);
        // Companion: the same runs with every SD halved are counted as the misses they are.
        for r in rows.iter_mut().take(3) {
            r.cup_sd_mm *= 0.5;
        }
        let s = &summarize(&rows)[0];
        assert!((s.cup_sd_coverage.unwrap() - 1.0 / 3.0).abs() < 1e-12);
        // Without resamples there is nothing to cover.
        let plain = vec![row(StudyMethod::Srvf, 1, 0, 0.8)];
        let s = &summarize(&plain)[0];
        assert_eq!(
            (s.cup_sd_runs, s.cup_sd_coverage, s.brier_mean),
            (0, None, None)
        );
    }

    #[test]
    fn merge_meta_keeps_the_shared_settings_and_rejects_another_study() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let write = |name: &str, seed: u64, shard: &str| {
            let d = dir.join(name);
            std::fs::create_dir_all(&d).unwrap();
            let v = serde_json::json!({"study": {"gt": "phantom", "seed": seed, "shard": shard,
                "seconds": 1.5, "w_reg": 10.0}, "summary": []});
            std::fs::write(d.join("summary.json"), v.to_string()).unwrap();
            d
        };
        let (a, b, c) = (
            write("a", 1, "0/2"),
            write("b", 1, "1/2"),
            write("c", 2, "1/2"),
        );
        let plain = dir.join("plain");
        std::fs::create_dir_all(&plain).unwrap();
        let m = merge_meta(&[a.clone(), b.clone(), plain.clone()]).unwrap();
        assert_eq!(m["seed"], 1);
        assert_eq!(m["w_reg"], 10.0);
        assert!(m.get("shard").is_none() && m.get("seconds").is_none());
        assert_eq!(m["merged"].as_array().unwrap().len(), 3);
        // A merged folder (its own `merged` list, no `shard`) merges with a shard of its study.
        let joined = dir.join("joined");
        std::fs::create_dir_all(&joined).unwrap();
        let v = serde_json::json!({"study": m.clone(), "summary": []});
        std::fs::write(joined.join("summary.json"), v.to_string()).unwrap();
        assert_eq!(merge_meta(&[joined, a.clone()]).unwrap()["seed"], 1);
        // A shard set with a gap is refused, naming what is missing; one shard of a study made
        // in one shard is whole.
        let e = merge_meta(std::slice::from_ref(&b))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("shards 0/2 of 2 are missing") && e.contains("hold 1/2"),
            "{e}"
        );
        let whole = write("whole", 1, "0/1");
        assert!(merge_meta(&[whole]).is_ok());
        // The companion: a shard of another study (seed 2) is refused, naming the field.
        let e = merge_meta(&[a, c]).unwrap_err().to_string();
        assert!(e.contains("\"seed\" is 2") && e.contains("has 1"), "{e}");
        // A shard that is not "I/N" with I < N is refused, naming the file and the value, not
        // taken for a merged folder (which would skip the set's check).
        for (name, shard) in [("odd1", "2/2"), ("odd2", "half"), ("odd3", "1/0")] {
            let d = write(name, 1, shard);
            let e = merge_meta(&[d.clone()]).unwrap_err().to_string();
            assert!(
                e.contains(&format!("study.shard is \"{shard}\""))
                    && e.contains(&d.join("summary.json").display().to_string()),
                "{e}"
            );
        }
        std::fs::write(plain.join("summary.json"), "{").unwrap();
        assert!(merge_meta(&[plain])
            .unwrap_err()
            .to_string()
            .contains("not JSON"));
    }

    #[test]
    fn csv_round_trips_and_merge_rejects_duplicates() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let (a, b) = (dir.join("a"), dir.join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        let mut r1 = vec![
            row(StudyMethod::Srvf, 1, 0, 0.5),
            row(StudyMethod::Icp, 1, 0, 2.0),
        ];
        (r1[0].outline_px, r1[0].pose_turn_deg, r1[0].pose_shift_mm) = (1.25, 0.8, 3.5);
        (r1[0].frame_shift_mm, r1[0].shifted_mae_mm) = (2.5, 0.375);
        (r1[0].restart_cause, r1[0].fallback_guard) = ("guard-folded".into(), "outlines".into());
        (
            r1[0].frame_shift_x_mm,
            r1[0].frame_shift_y_mm,
            r1[0].frame_shift_z_mm,
        ) = (0.5, -2.25, 1.0);
        r1[0].depth_offset_mm = 0.75;
        r1[1].error = "solver: boom, twice".into();
        r1[1].mae_mm = f64::NAN;
        write_csv(&r1, &a.join("runs.csv")).unwrap();
        write_csv(&[row(StudyMethod::Srvf, 1, 1, 0.7)], &b.join("runs.csv")).unwrap();
        let back = read_csv(&a.join("runs.csv")).unwrap();
        assert_eq!(format!("{:?}", back[0]), format!("{:?}", r1[0]));
        assert!(back[1].mae_mm.is_nan() && back[1].error == "solver: boom, twice");
        let merged = merge_dirs(&[b.clone(), a.clone()]).unwrap();
        assert_eq!(
            merged.iter().map(|r| r.key()).collect::<Vec<_>>(),
            vec![
                (StudyMethod::Srvf, 1, 0),
                (StudyMethod::Srvf, 1, 1),
                (StudyMethod::Icp, 1, 0)
            ]
        );
        assert!(matches!(
            merge_dirs(&[a.clone(), a.clone()]),
            Err(StudyError::Duplicate { .. })
        ));
        let good = std::fs::read_to_string(a.join("runs.csv")).unwrap();
        for (from, to, column) in [
            ("\nsrvf,", "\nsfrv,", "method"),
            (",true,", ",yes,", "converged"),
            (",0.500000,", ",half,", "mae_mm"),
        ] {
            std::fs::write(b.join("runs.csv"), good.replacen(from, to, 1)).unwrap();
            let e = read_csv(&b.join("runs.csv")).unwrap_err().to_string();
            assert!(
                e.contains(&format!("column {column:?}")) && e.contains("line 2"),
                "{e}"
            );
        }
        // Companion: the file as written reads back.
        std::fs::write(b.join("runs.csv"), &good).unwrap();
        assert_eq!(read_csv(&b.join("runs.csv")).unwrap().len(), 2);
        std::fs::write(b.join("runs.csv"), "nonsense\n").unwrap();
        assert!(matches!(
            merge_dirs(std::slice::from_ref(&b)),
            Err(StudyError::Parse { line: 1, .. })
        ));
        let drop_last = |text: &str, k: usize| -> String {
            text.lines()
                .map(|l| {
                    let f: Vec<&str> = l.split(',').collect();
                    f[..f.len() - k].join(",") + "\n"
                })
                .collect()
        };
        // A file from before the depth offset reads, its offset NaN and the rest as written.
        std::fs::write(b.join("runs.csv"), drop_last(&good, DEPTH_COLUMNS)).unwrap();
        let back = read_csv(&b.join("runs.csv")).unwrap();
        assert!(back[0].depth_offset_mm.is_nan() && back[0].frame_shift_y_mm == -2.25);
        // Companion: written with it, it reads as written.
        assert_eq!(
            read_csv(&a.join("runs.csv")).unwrap()[0].depth_offset_mm,
            0.75
        );
        // A file from before the shift's axes too reads, its axes NaN and the rest as written.
        let good = drop_last(&good, DEPTH_COLUMNS);
        std::fs::write(b.join("runs.csv"), drop_last(&good, SHIFT_AXES_COLUMNS)).unwrap();
        let back = read_csv(&b.join("runs.csv")).unwrap();
        assert!(
            back[0].frame_shift_x_mm.is_nan()
                && back[0].frame_shift_z_mm.is_nan()
                && back[0].fallback_guard == "outlines"
                && back[0].frame_shift_mm == 2.5
        );
        // A file from before the cause columns too reads, its causes empty.
        let good = drop_last(&good, SHIFT_AXES_COLUMNS);
        std::fs::write(b.join("runs.csv"), drop_last(&good, CAUSE_COLUMNS)).unwrap();
        let back = read_csv(&b.join("runs.csv")).unwrap();
        assert!(
            back[0].restart_cause.is_empty()
                && back[0].fallback_guard.is_empty()
                && back[0].shifted_mae_mm == 0.375
        );
        // One from before the shift columns too, its shifts NaN.
        let good = drop_last(&good, CAUSE_COLUMNS);
        std::fs::write(b.join("runs.csv"), drop_last(&good, SHIFT_COLUMNS)).unwrap();
        let back = read_csv(&b.join("runs.csv")).unwrap();
        assert!(
            back[0].frame_shift_mm.is_nan()
                && back[0].shifted_mae_mm.is_nan()
                && back[0].pose_shift_mm == 3.5
        );
        // One from before the pose columns too, its pose corrections NaN.
        let no_pose = drop_last(&good, SHIFT_COLUMNS + POSE_COLUMNS);
        std::fs::write(b.join("runs.csv"), no_pose).unwrap();
        let back = read_csv(&b.join("runs.csv")).unwrap();
        assert!(
            back[0].pose_shift_mm.is_nan()
                && back[0].pose_turn_deg.is_nan()
                && back[0].outline_px == 1.25
        );
        // One from before the outline column as well, its outline distances NaN.
        let no_outline = drop_last(&good, SHIFT_COLUMNS + POSE_COLUMNS + OUTLINE_COLUMNS);
        std::fs::write(b.join("runs.csv"), no_outline).unwrap();
        let back = read_csv(&b.join("runs.csv")).unwrap();
        assert!(back[0].outline_px.is_nan() && back[0].mae_mm == 0.5);
        // One from before the restart column as well, its restarts empty.
        let no_restart = drop_last(
            &good,
            SHIFT_COLUMNS + POSE_COLUMNS + OUTLINE_COLUMNS + RESTART_COLUMNS,
        );
        std::fs::write(b.join("runs.csv"), &no_restart).unwrap();
        let back = read_csv(&b.join("runs.csv")).unwrap();
        assert!(back[0].restart.is_empty() && back[0].mae_mm == 0.5);
        // A file from before the orientation columns reads, its angles NaN; one column short
        // of that is still refused.
        let old = drop_last(
            &good,
            SHIFT_COLUMNS + POSE_COLUMNS + OUTLINE_COLUMNS + RESTART_COLUMNS + ORIENTATION_COLUMNS,
        );
        std::fs::write(b.join("runs.csv"), &old).unwrap();
        let back = read_csv(&b.join("runs.csv")).unwrap();
        assert_eq!(back[0].mae_mm, 0.5);
        assert!(back[0].inclination_deg.is_nan() && back[0].anteversion_err_deg.is_nan());
        let short: String = old
            .lines()
            .map(|l| l.rsplit_once(',').unwrap().0.to_string() + "\n")
            .collect();
        std::fs::write(b.join("runs.csv"), short).unwrap();
        assert!(read_csv(&b.join("runs.csv")).is_err());
    }

    /// A runs.csv holding a value no run can have (a negative SD or diameter, an infinite
    /// offset, a probability above 1, a level 6) is refused naming its line, column and value,
    /// as is a run on two lines (files joined); the file as written, NaN where a run records
    /// nothing, and the same run number at another level or method read (the companions).
    #[test]
    fn a_runs_csv_with_an_impossible_value_or_a_run_twice_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("runs.csv");
        let mut rows = vec![
            row(StudyMethod::Srvf, 1, 0, 0.5),
            row(StudyMethod::Srvf, 3, 0, 0.625),
            row(StudyMethod::Icp, 1, 0, 0.75),
        ];
        (rows[0].cup_sd_mm, rows[0].size_probability, rows[0].brier) = (0.75, 0.5, 1.5);
        (rows[0].depth_offset_mm, rows[0].limb_diameter_mm) = (-0.25, 49.5);
        write_csv(&rows, &path).unwrap();
        let good = std::fs::read_to_string(&path).unwrap();
        // (Debug: NaN, a value not recorded, is not equal to itself.)
        assert_eq!(
            format!("{:?}", read_csv(&path).unwrap()),
            format!("{rows:?}")
        );
        let header: Vec<&str> = good.lines().next().unwrap().split(',').collect();
        // `good` with `column` of line 2 (the first run) set to `value`.
        let with = |column: &str, value: &str| -> String {
            let k = header.iter().position(|h| *h == column).unwrap();
            let mut lines: Vec<String> = good.lines().map(str::to_string).collect();
            let mut f: Vec<&str> = lines[1].split(',').collect();
            f[k] = value;
            lines[1] = f.join(",");
            lines.join("\n") + "\n"
        };
        for (column, value) in [
            ("cup_sd_mm", "-0.5"),
            ("cup_diameter_mm", "-1"),
            ("gt_cup_diameter_mm", "0"),
            ("limb_diameter_mm", "inf"),
            ("mae_mm", "-0.1"),
            ("seconds", "-1"),
            ("depth_offset_mm", "-inf"),
            ("size_probability", "1.5"),
            ("brier", "2.5"),
            ("level", "6"),
        ] {
            std::fs::write(&path, with(column, value)).unwrap();
            let e = read_csv(&path).unwrap_err().to_string();
            assert!(
                e.contains("line 2") && e.contains(&format!("column {column:?}: {value}")),
                "{column} = {value}: {e}"
            );
        }
        // Companions: NaN (not recorded) and the range's ends read.
        for (column, value) in [
            ("cup_sd_mm", "NaN"),
            ("cup_sd_mm", "0"),
            ("size_probability", "1"),
            ("brier", "2"),
            ("depth_offset_mm", "NaN"),
            ("level", "5"),
            ("level", "0"),
        ] {
            std::fs::write(&path, with(column, value)).unwrap();
            assert!(read_csv(&path).is_ok(), "{column} = {value}");
        }
        // A run on two lines.
        std::fs::write(&path, good.clone() + good.lines().nth(2).unwrap() + "\n").unwrap();
        let e = read_csv(&path).unwrap_err().to_string();
        assert!(
            e.contains("line 5") && e.contains("srvf level 3 run 0 is already on line 3"),
            "{e}"
        );
        rows.push(row(StudyMethod::Icp, 3, 0, 0.75));
        write_csv(&rows, &path).unwrap();
        assert_eq!(read_csv(&path).unwrap().len(), 4);
    }

    /// A merge whose shards hold every run of their study passes; one that lacks runs (a shard
    /// cut short: its runs.csv only a header) is refused, naming the first missing ones; an
    /// older summary.json without the settings is not checked.
    #[test]
    fn a_merge_missing_runs_of_its_study_is_refused() {
        let meta = serde_json::json!({"levels": [1, 3], "runs": 2, "methods": ["srvf", "icp"]});
        let all: Vec<Row> = [StudyMethod::Srvf, StudyMethod::Icp]
            .into_iter()
            .flat_map(|m| {
                [1, 3]
                    .into_iter()
                    .flat_map(move |l| (0..2).map(move |r| row(m, l, r, 0.5)))
            })
            .collect();
        assert_eq!(all.len(), 8);
        assert!(check_complete(&all, &meta).is_ok());
        let cut: Vec<Row> = all.iter().filter(|r| r.run == 0).cloned().collect();
        let e = check_complete(&cut, &meta).unwrap_err().to_string();
        assert!(
            e.contains("4 of the study's 8 runs")
                && e.contains("srvf level 1 run 1")
                && e.contains("1 more"),
            "{e}"
        );
        assert!(check_complete(&cut, &serde_json::json!({"seed": 3})).is_ok());
    }

    #[test]
    fn summary_counts_and_means() {
        let mut rows = vec![
            row(StudyMethod::Srvf, 2, 0, 0.4),
            row(StudyMethod::Srvf, 2, 1, 0.6),
            row(StudyMethod::Srvf, 2, 2, 9.0),
        ];
        rows[2].error = "failed".into();
        rows[2].converged = false;
        rows[1].cup_diameter_mm = 52.0;
        rows[0].limb_diameter_mm = 50.9;
        rows[1].limb_diameter_mm = 51.1;
        let s = summarize(&rows);
        assert_eq!(s.len(), 1);
        assert_eq!((s[0].runs, s[0].converged, s[0].failed), (3, 2, 1));
        assert!((s[0].mae_mean - 0.5).abs() < 1e-12 && (s[0].mae_sd - 0.1).abs() < 1e-12);
        assert_eq!(s[0].cup_within_1mm, 1);
        assert_eq!(
            (s[0].limb_within_1mm, s[0].surface_fit_within_1mm),
            (Some(1), 0)
        );
        rows[0].limb_diameter_mm = f64::NAN;
        rows[1].limb_diameter_mm = f64::NAN;
        assert_eq!(summarize(&rows)[0].limb_within_1mm, None);
    }
}
