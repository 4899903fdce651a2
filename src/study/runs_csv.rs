//! One row per run: runs.csv, written and read (files from before the later columns read too,
//! a value no run can have is refused).

use super::error::StudyError;
use super::method::StudyMethod;
use super::task::Task;
use crate::io::write_atomic;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

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
    /// "non-finite-vertex", "non-finite-pose", "reprojection", "outlines", "open-rims"); empty
    /// when no fallback was taken.
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
        // (the columns, what each value must pass, what the message says it must be)
        type Group<'a> = (&'a [(&'a str, f64)], fn(f64) -> bool, &'a str);
        let groups: [Group; 5] = [
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
    let want = accepted_header(rd.headers().ok()).map_err(|reason| perr(1, reason))?;
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
        let row: Row = rec
            .deserialize(Some(&want))
            .map_err(|e| perr(line, field_reason(&rec, &want, &e)))?;
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

/// The header a runs.csv may have (`h`, none where it could not be read): the whole one, or the
/// whole one's prefix that files written before later columns were added have.
fn accepted_header(h: Option<&csv::StringRecord>) -> Result<csv::StringRecord, String> {
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
    match h {
        Some(h) if *h == full => Ok(full.clone()),
        Some(h) if older.iter().any(|&n| *h == prefix(n)) => Ok(h.clone()),
        _ => {
            let names: Vec<&str> = full.iter().collect();
            Err(format!("expected the header {:?}", names.join(",")))
        }
    }
}

/// Why the record `rec` (under the header `want`) is not a row (`e`): the column, its value and
/// what it must be.
fn field_reason(rec: &csv::StringRecord, want: &csv::StringRecord, e: &csv::Error) -> String {
    match e.kind() {
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
    }
}

/// A converged run of `method` at `level`, number `run`, with MAE `mae` and a cup 0.5 mm over
/// its truth's: the tests' row.
#[cfg(test)]
pub(super) fn test_row(method: StudyMethod, level: u32, run: usize, mae: f64) -> Row {
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

#[cfg(test)]
mod tests {
    use super::*;
    use test_row as row;

    #[test]
    fn csv_round_trips_and_older_files_read() {
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
            read_csv(&b.join("runs.csv")),
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
}
