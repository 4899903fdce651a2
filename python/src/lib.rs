//! The `acetab._acetab` extension module: the engine's case runner, reconstruction, SRVF
//! alignment and simulation studies for Python. The package's `acetab/__init__.py` wraps these
//! with keyword arguments, numpy conversions and docstrings; options travel as JSON so that an
//! unknown or mistyped option is refused with the engine's own message.

use acetab::case::{run_case_calibrated, solve_case, CalibrationChoice, CaseFile};
use acetab::contours::ContourSource;
use acetab::correspond::srvf::{align as srvf_align, aligned_b, CurveKind, SrvfParams};
use acetab::correspond::srvf::{MAX_SAMPLES, MIN_SAMPLES};
use acetab::correspond::Method;
use acetab::engine::Kernels;
use acetab::pipeline::{CupCalibration, CupEstimator, CupParams, ReconParams, UncertaintyParams};
use acetab::report::{CupCatalogue, Provenance};
use acetab::sim::{load_truth, Protocol, RealisticErrors};
use acetab::solve::PoseParams;
use acetab::study::{run_study, StudyConfig, StudyMethod};
use nalgebra::Point2;
use numpy::{PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde::Deserialize;
use std::path::{Path, PathBuf};

create_exception!(
    _acetab,
    AcetabError,
    PyException,
    "The engine refused the input or could not stand behind a result; the message says why."
);

fn engine_err(e: impl std::fmt::Display) -> PyErr {
    AcetabError::new_err(e.to_string())
}

/// The reconstruction options shared by `reconstruct_case` and `reconstruct` (the command
/// line's flags of `acetab reconstruct`, same defaults).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ReconOptions {
    #[serde(default = "srvf")]
    method: String,
    #[serde(default = "default_catalogue")]
    catalogue: String,
    #[serde(default)]
    refine_poses: bool,
    #[serde(default)]
    pose_prior: Option<[f64; 2]>,
    #[serde(default = "sixteen")]
    uncertainty_samples: u64,
    #[serde(default)]
    calibration: Option<String>,
    #[serde(default = "one")]
    seed: u64,
    #[serde(default = "alpha_shape")]
    contours: String,
    #[serde(default = "none")]
    prior: String,
    #[serde(default = "observed_part")]
    cup_estimator: String,
}

fn observed_part() -> String {
    "observed-part".into()
}

/// A cup estimator argument ("observed-part" or "prior-region"; the latter needs a prior).
fn cup_estimator(name: &str, prior: &str) -> PyResult<CupEstimator> {
    let e = CupEstimator::parse(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "cup_estimator={name:?}: must be \"observed-part\" or \"prior-region\""
        ))
    })?;
    if e == CupEstimator::PriorRegion && prior == "none" {
        return Err(PyValueError::new_err(
            "cup_estimator=\"prior-region\": the region is the prior's; give prior=\"default\" or a file",
        ));
    }
    Ok(e)
}

fn srvf() -> String {
    "srvf".into()
}
fn default_catalogue() -> String {
    "40:70:2".into()
}
fn sixteen() -> u64 {
    16
}
fn one() -> u64 {
    1
}
fn none() -> String {
    "none".into()
}
/// A prior argument: "none", "default" (the shipped one) or a file from `acetab prior build`.
fn shape_prior(arg: &str) -> PyResult<Option<std::sync::Arc<acetab::prior::ShapePrior>>> {
    acetab::prior::choose_prior(arg, None)
        .map(|(p, _)| p.map(std::sync::Arc::new))
        .map_err(|e| engine_err(format!("prior={arg:?}: {e}")))
}
fn alpha_shape() -> String {
    "alpha-shape".into()
}

fn options<T: serde::de::DeserializeOwned>(json: &str) -> PyResult<T> {
    serde_json::from_str(json).map_err(|e| PyTypeError::new_err(format!("options: {e}")))
}

fn method_of(name: &str) -> PyResult<Method> {
    [Method::Srvf, Method::Icp, Method::IcpNormvec]
        .into_iter()
        .find(|m| m.name() == name)
        .ok_or_else(|| {
            PyValueError::new_err(format!(
                "method={name:?}: must be \"srvf\", \"icp\" or \"icp-normvec\""
            ))
        })
}

/// A calibration argument: None for the shipped one, "none", or a file from `acetab calibrate`
/// (learned for the cup estimator `estimator`).
fn calibration(
    arg: &Option<String>,
    shipped: fn() -> CupCalibration,
    estimator: CupEstimator,
) -> PyResult<CupCalibration> {
    CupCalibration::for_estimator(arg.as_deref(), shipped, estimator).map_err(|e| {
        engine_err(format!(
            "calibration={:?}: {e}",
            arg.as_deref().unwrap_or_default()
        ))
    })
}

/// The pose refinement's settings: none without `refine_poses`; its prior SDs (degrees, mm)
/// from `pose_prior`, which needs `refine_poses` (checked as the engine checks them:
/// `PoseParams::invalid`).
fn pose_params(refine: bool, prior: Option<[f64; 2]>) -> PyResult<Option<PoseParams>> {
    if !refine {
        return match prior {
            None => Ok(None),
            Some(_) => Err(PyValueError::new_err(
                "pose_prior: needs refine_poses=True (it is the refinement's prior)",
            )),
        };
    }
    let p = match prior {
        Some([sigma_deg, sigma_mm]) => PoseParams {
            sigma_deg,
            sigma_mm,
            ..Default::default()
        },
        None => PoseParams::default(),
    };
    if let Some((field, v)) = p.invalid() {
        return Err(PyValueError::new_err(format!(
            "pose_prior: {field} = {v}: the SDs (degrees, mm) must be finite and above 0"
        )));
    }
    Ok(Some(p))
}

impl ReconOptions {
    /// The reconstruction's and the uncertainty's parameters, and the cup calibration to give
    /// each case (as `acetab reconstruct` does: by default the shipped one learned on its views).
    fn params(&self) -> PyResult<(ReconParams, UncertaintyParams, CalibrationChoice)> {
        let catalogue = CupCatalogue::parse(&self.catalogue)
            .map_err(|e| PyValueError::new_err(format!("catalogue={:?}: {e}", self.catalogue)))?;
        let contour_source = match self.contours.as_str() {
            "alpha-shape" => ContourSource::AlphaShape,
            "silhouette" => ContourSource::Silhouette,
            other => {
                return Err(PyValueError::new_err(format!(
                    "contours={other:?}: must be \"alpha-shape\" or \"silhouette\""
                )))
            }
        };
        if !(2..=1000).contains(&self.uncertainty_samples) {
            return Err(PyValueError::new_err(format!(
                "uncertainty_samples={}: must be 2 to 1000 (one resample has no spread)",
                self.uncertainty_samples
            )));
        }
        let estimator = cup_estimator(&self.cup_estimator, &self.prior)?;
        let cal = calibration(
            &self.calibration,
            CupCalibration::shipped(true, estimator),
            estimator,
        )?;
        let choice = CalibrationChoice::from_arg(self.calibration.as_deref(), true, estimator, cal);
        let mut prm = ReconParams {
            method: method_of(&self.method)?,
            cup: CupParams {
                catalogue,
                estimator,
                ..Default::default()
            },
            contour_source,
            pose: pose_params(self.refine_poses, self.pose_prior)?,
            ..Default::default()
        };
        prm.deformation.shape_prior = shape_prior(&self.prior)?;
        let up = UncertaintyParams {
            samples: self.uncertainty_samples as usize,
            seed: self.seed,
            ..Default::default()
        };
        Ok((prm, up, choice))
    }
}

/// Run the case file at `path` as `acetab reconstruct` does, writing its files into `out` (a
/// temporary folder, removed, when None); report.json's object as JSON.
#[pyfunction]
#[pyo3(signature = (path, out, force, options_json))]
fn reconstruct_case_json(
    py: Python<'_>,
    path: PathBuf,
    out: Option<PathBuf>,
    force: bool,
    options_json: &str,
) -> PyResult<String> {
    let opts: ReconOptions = options(options_json)?;
    let (prm, up, choice) = opts.params()?;
    if let Some(o) = &out {
        if acetab::io::out_in_use(o) && !force {
            return Err(engine_err(format!(
                "{}: exists and is not empty (force=True writes into it)",
                o.display()
            )));
        }
        if o.exists() && !o.is_dir() {
            return Err(engine_err(format!("{}: is not a folder", o.display())));
        }
    }
    py.detach(move || {
        let scratch;
        let dest = match out {
            Some(o) => o,
            None => {
                scratch = tempfile::tempdir().map_err(|e| format!("temporary folder: {e}"))?;
                scratch.path().join("out")
            }
        };
        let provenance = Provenance::here("cpu", None, 1, up.seed);
        let report =
            run_case_calibrated(&path, &dest, &prm, Kernels::Cpu, &up, provenance, &choice)
                .map_err(|e| e.to_string())?;
        serde_json::to_string(&report).map_err(|e| e.to_string())
    })
    .map_err(engine_err)
}

/// Reconstruct the case given as case-file JSON (numpy arrays already turned into lists);
/// (vertices, faces, report JSON).
#[pyfunction]
#[pyo3(signature = (case_json, options_json))]
#[allow(clippy::type_complexity)]
fn reconstruct_json<'py>(
    py: Python<'py>,
    case_json: &str,
    options_json: &str,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<i64>>, String)> {
    let opts: ReconOptions = options(options_json)?;
    let (prm, up, choice) = opts.params()?;
    let label = Path::new("reconstruct()");
    let file: CaseFile = serde_json::from_str(case_json)
        .map_err(|e| PyValueError::new_err(format!("reconstruct(): {e}")))?;
    let case = file.validate(label).map_err(engine_err)?;
    // The calibration for the case's views, as `acetab reconstruct` gives it.
    let (prm, up, used, view_warning) = choice.apply(&case, &prm, &up);
    let mut warnings = case.warnings.clone();
    warnings.extend(view_warning);
    let (mesh, report) = py
        .detach(|| {
            let (rec, cup) = solve_case(&case, label, &prm, Kernels::Cpu, &up)?;
            let pose_prior = acetab::pipeline::params_used(&rec, &prm)
                .pose
                .map(|p| p.prior_sds());
            let report = serde_json::json!({
                "method": prm.method.name(),
                "pose_prior": pose_prior,
                "cup": cup,
                "sphere": rec.sphere,
                "log": rec.log,
                "views": case.geometry,
                "calibration": used,
                "warnings": warnings,
            });
            Ok::<_, acetab::case::CaseRunError>((rec.mesh, report.to_string()))
        })
        .map_err(engine_err)?;
    let verts: Vec<Vec<f64>> = mesh.vertices.iter().map(|p| vec![p.x, p.y, p.z]).collect();
    let faces: Vec<Vec<i64>> = mesh
        .triangles
        .iter()
        .map(|t| t.iter().map(|&i| i64::from(i)).collect())
        .collect();
    let v = PyArray2::from_vec2(py, &verts).map_err(|e| engine_err(e.to_string()))?;
    let f = PyArray2::from_vec2(py, &faces).map_err(|e| engine_err(e.to_string()))?;
    Ok((v, f, report))
}

fn curve_of(name: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<Point2<f64>>> {
    let a = a.as_array();
    if a.ncols() != 2 {
        return Err(PyValueError::new_err(format!(
            "{name}: shape {:?}; a curve is an (N, 2) array of x, y",
            a.shape()
        )));
    }
    let pts: Vec<Point2<f64>> = a
        .rows()
        .into_iter()
        .map(|r| Point2::new(r[0], r[1]))
        .collect();
    if let Some(i) = pts
        .iter()
        .position(|p| !(p.x.is_finite() && p.y.is_finite()))
    {
        return Err(PyValueError::new_err(format!(
            "{name}[{i}] = {:?}: coordinates must be finite",
            pts[i]
        )));
    }
    Ok(pts)
}

/// SRVF elastic alignment of curve `b` to curve `a`.
#[pyfunction]
#[pyo3(signature = (a, b, mode, samples, anchor))]
fn align<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    b: PyReadonlyArray2<'py, f64>,
    mode: &str,
    samples: usize,
    anchor: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let kind = match mode {
        "closed" => CurveKind::Closed,
        "open" => CurveKind::Open,
        "partial" => CurveKind::Partial,
        other => {
            return Err(PyValueError::new_err(format!(
                "mode={other:?}: must be \"closed\", \"open\" or \"partial\""
            )))
        }
    };
    if !(MIN_SAMPLES..=MAX_SAMPLES).contains(&samples) {
        return Err(PyValueError::new_err(format!(
            "samples={samples}: must be {MIN_SAMPLES} to {MAX_SAMPLES}"
        )));
    }
    if !(anchor.is_finite() && anchor >= 0.0) {
        return Err(PyValueError::new_err(format!(
            "anchor={anchor}: must be a finite number >= 0"
        )));
    }
    let (ca, cb) = (curve_of("a", &a)?, curve_of("b", &b)?);
    let prm = SrvfParams {
        samples,
        anchor,
        ..Default::default()
    };
    let al = py
        .detach(|| srvf_align(&ca, &cb, kind, &prm))
        .map_err(engine_err)?;
    let aligned: Vec<Vec<f64>> = aligned_b(&al).iter().map(|p| vec![p.x, p.y]).collect();
    let a_pts: Vec<Vec<f64>> = al.a_points.iter().map(|p| vec![p.x, p.y]).collect();
    let d = PyDict::new(py);
    d.set_item("distance", al.distance)?;
    d.set_item("rotation_deg", al.rotation.to_degrees())?;
    d.set_item("seed", al.seed)?;
    d.set_item("reversed", al.reversed)?;
    d.set_item("samples", samples)?;
    d.set_item("mode", mode)?;
    d.set_item("gamma", PyArray1::from_vec(py, al.gamma.clone()))?;
    d.set_item(
        "aligned",
        PyArray2::from_vec2(py, &aligned).map_err(|e| engine_err(e.to_string()))?,
    )?;
    d.set_item(
        "a_points",
        PyArray2::from_vec2(py, &a_pts).map_err(|e| engine_err(e.to_string()))?,
    )?;
    d.set_item("b_index", PyArray1::from_vec(py, al.b_index.clone()))?;
    Ok(d)
}

/// A study's settings (the flags of `acetab simulate`, same defaults).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StudyOptions {
    gt: String,
    levels: Vec<u32>,
    runs: usize,
    methods: Vec<String>,
    #[serde(default = "one")]
    seed: u64,
    #[serde(default = "ideal")]
    protocol: String,
    #[serde(default)]
    refine_poses: bool,
    #[serde(default)]
    pose_prior: Option<[f64; 2]>,
    #[serde(default)]
    threads: Option<usize>,
    #[serde(default)]
    uncertainty_samples: u64,
    #[serde(default)]
    calibration: Option<String>,
    #[serde(default = "none")]
    prior: String,
    #[serde(default = "observed_part")]
    cup_estimator: String,
}

fn ideal() -> String {
    "ideal".into()
}

/// A simulation study on a ground truth; its runs (runs.csv's rows) as JSON.
#[pyfunction]
#[pyo3(signature = (options_json))]
fn simulate_json(py: Python<'_>, options_json: &str) -> PyResult<String> {
    let o: StudyOptions = options(options_json)?;
    let methods = o
        .methods
        .iter()
        .map(|m| {
            StudyMethod::from_name(m).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "methods: {m:?} is not one of {}",
                    StudyMethod::ALL.map(|m| m.name()).join(", ")
                ))
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    // A study of no level or no method, or of one listed twice (its runs would come twice,
    // the same seeds, one row each), is refused as the command line refuses it.
    for (name, listed) in [
        (
            "levels",
            o.levels.iter().map(|l| l.to_string()).collect::<Vec<_>>(),
        ),
        (
            "methods",
            methods.iter().map(|m| m.name().to_string()).collect(),
        ),
    ] {
        if listed.is_empty() {
            return Err(PyValueError::new_err(format!(
                "{name}=[]: a study needs at least one"
            )));
        }
        if let Some((k, twice)) = listed
            .iter()
            .enumerate()
            .find(|(k, x)| listed[..*k].contains(x))
        {
            return Err(PyValueError::new_err(format!(
                "{name}[{k}] = {twice}: listed twice"
            )));
        }
    }
    let estimator = cup_estimator(&o.cup_estimator, &o.prior)?;
    let (protocol, shipped): (Protocol, fn() -> CupCalibration) = match o.protocol.as_str() {
        "ideal" => (Protocol::Ideal, CupCalibration::shipped(false, estimator)),
        "realistic" => (
            Protocol::Realistic(RealisticErrors::default()),
            CupCalibration::shipped(true, estimator),
        ),
        other => {
            return Err(PyValueError::new_err(format!(
                "protocol={other:?}: must be \"ideal\" or \"realistic\""
            )))
        }
    };
    if o.uncertainty_samples == 1 || o.uncertainty_samples > 1000 {
        return Err(PyValueError::new_err(format!(
            "uncertainty_samples={}: must be 0 (none) or 2 to 1000",
            o.uncertainty_samples
        )));
    }
    if o.runs == 0 || o.runs > 10_000 {
        return Err(PyValueError::new_err(format!(
            "runs={}: must be 1 to 10000",
            o.runs
        )));
    }
    let threads = match o.threads {
        Some(0) => return Err(PyValueError::new_err("threads=0: must be at least 1")),
        Some(t) => t,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let cal = calibration(&o.calibration, shipped, estimator)?;
    let model_sd_mm = cal.model_sd_mm;
    let cfg = StudyConfig {
        protocol,
        levels: o.levels.clone(),
        runs: o.runs,
        methods,
        seed: o.seed,
        threads,
        params: ReconParams {
            pose: pose_params(o.refine_poses, o.pose_prior)?,
            deformation: acetab::pipeline::DeformationParams {
                shape_prior: shape_prior(&o.prior)?,
                ..Default::default()
            },
            cup: cal.correcting(CupParams {
                estimator,
                ..Default::default()
            }),
            ..Default::default()
        },
        uncertainty: (o.uncertainty_samples > 0).then(|| UncertaintyParams {
            samples: o.uncertainty_samples as usize,
            model_sd_mm,
            ..Default::default()
        }),
        ..Default::default()
    };
    py.detach(move || {
        // Named as this function's arguments are (gt=...), not as the command line's flags.
        let truth = load_truth(&o.gt).map_err(|e| format!("gt={}: {}", e.gt, e.reason))?;
        let (rows, _) = run_study(&truth, &cfg, &|| {}, Kernels::Cpu)
            .map_err(|e| format!("gt={}: {e}", o.gt))?;
        // runs.csv writes its metrics as fixed-precision text; here they are numbers again
        // (None where the run could not give one).
        let mut v = serde_json::to_value(&rows).map_err(|e| e.to_string())?;
        for row in v.as_array_mut().into_iter().flatten() {
            for (key, val) in row.as_object_mut().into_iter().flatten() {
                if key == "error" || key == "fallback" {
                    continue;
                }
                if let Some(x) = val.as_str().and_then(|s| s.parse::<f64>().ok()) {
                    *val =
                        serde_json::Number::from_f64(x).map_or(serde_json::Value::Null, Into::into);
                }
            }
        }
        Ok::<_, String>(v.to_string())
    })
    .map_err(engine_err)
}

/// The engine's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _acetab(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("AcetabError", m.py().get_type::<AcetabError>())?;
    m.add_function(wrap_pyfunction!(reconstruct_case_json, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct_json, m)?)?;
    m.add_function(wrap_pyfunction!(align, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_json, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    Ok(())
}
