//! `acetab reconstruct`: a case file in, the reconstruction, the cup report with its uncertainty
//! and one overlay per view out. Everything is written into a staging folder beside the output
//! and moved into place only when all of it succeeded (`fsutil::fill_dir_atomically`), so a
//! failed run leaves no files.

use crate::case::{CalibrationChoice, CalibrationUsed, Case, CaseError, CaseFile};
use crate::engine::Kernels;
use crate::io::{write_ply, MeshIoError};
use crate::pipeline::{cup_report, CupReport, UncertaintyParams};
use crate::pipeline::{reconstruct, ReconError, ReconParams, Reconstruction};
#[cfg(feature = "plots")]
use crate::report::plots::{overlay, OverlayMarks};
use crate::report::Provenance;
use crate::template::Template;
use std::path::{Path, PathBuf};

/// Why a case could not be run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CaseRunError {
    /// The case file is refused.
    #[error(transparent)]
    Case(#[from] CaseError),
    /// The reconstruction failed.
    #[error("{path}: {source}{}", read_with(warnings))]
    Recon {
        /// The case file.
        path: PathBuf,
        /// Why.
        source: Box<ReconError>,
        /// The case file's own warnings (a closed outline that looks like an open arc, ...),
        /// which may say why.
        warnings: Vec<String>,
    },
    /// The reconstruction could not be written.
    #[error(transparent)]
    Mesh(#[from] MeshIoError),
    /// The cup is outside the catalogue (`CupCatalogue::holds`).
    #[error("{path}: the cup is {diameter_mm:.1} mm across, outside the catalogue's {min_mm}-{max_mm} mm (--catalogue): no size is given")]
    Catalogue {
        /// The case file.
        path: PathBuf,
        /// The cup's diameter.
        diameter_mm: f64,
        /// The catalogue's smallest size.
        min_mm: f64,
        /// Its largest.
        max_mm: f64,
    },
    /// An output file could not be written.
    #[error("{path}: cannot write: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// What `run_case` returns (also written as report.json).
#[derive(Clone, Debug, serde::Serialize)]
pub struct CaseRunReport {
    /// The case file.
    pub case: String,
    /// The correspondence method.
    pub method: String,
    /// Where the kernels ran.
    pub backend: String,
    /// The pose refinement's prior SDs, [degrees, mm], when the views' poses were refined (asked
    /// for, or by the `refine-poses` fallback); None when they were taken as given.
    pub pose_prior: Option<[f64; 2]>,
    /// The cup and its uncertainty.
    pub cup: CupReport,
    /// Version, command line, backend and adapter, threads, seed.
    pub provenance: Provenance,
    /// The cup sphere.
    pub sphere: crate::geom::Sphere,
    /// Per view: its intrinsics, where they came from (case or DICOM tags), the magnification.
    pub views: Vec<crate::case::ViewGeometry>,
    /// What the solver did.
    pub log: crate::pipeline::SolveLog,
    /// Seconds for the reconstruction and the uncertainty.
    pub seconds: f64,
    /// The files written.
    pub files: Vec<String>,
    /// The cup calibration and whether it was learned on the case's views (None when the
    /// caller set the cup's correction itself: `run_case_with`).
    pub calibration: Option<CalibrationUsed>,
    /// What the case's views disagree on, a calibration learned on other views, and pictures
    /// that could not be drawn, and why (the rest is written regardless).
    pub warnings: Vec<String>,
}

#[cfg(feature = "plots")]
fn file_safe(s: &str) -> String {
    s.chars()
        .map(|c| match c {
            '+' => 'p',
            c if c.is_ascii_alphanumeric() || c == '-' => c,
            _ => '_',
        })
        .collect()
}

/// Reconstruct the case at `path` and write reconstruction.ply, cup.json, report.json and
/// `overlay-<view>.png` into `out` (the provenance names no adapter: `run_case_with` does).
pub fn run_case(
    path: &Path,
    out: &Path,
    prm: &ReconParams,
    kernels: Kernels,
    up: &UncertaintyParams,
) -> Result<CaseRunReport, CaseRunError> {
    let provenance = Provenance::here(kernels.name(), None, 1, up.seed);
    run_case_with(path, out, prm, kernels, up, provenance)
}

/// As `run_case`, with the caller's provenance in report.json (its adapter, its threads): the
/// cup corrected as `prm.cup` says, its model SD `up.model_sd_mm`.
pub fn run_case_with(
    path: &Path,
    out: &Path,
    prm: &ReconParams,
    kernels: Kernels,
    up: &UncertaintyParams,
    provenance: Provenance,
) -> Result<CaseRunReport, CaseRunError> {
    let case = CaseFile::load(path)?;
    run_loaded(&case, path, out, prm, kernels, up, provenance, None)
}

/// As `run_case_with`, the cup calibrated as `choice` says for the case's views (its bias,
/// shrink and model SD in place of those in `prm.cup` and `up`); report.json records which
/// calibration, and warns when it was learned on other views.
pub fn run_case_calibrated(
    path: &Path,
    out: &Path,
    prm: &ReconParams,
    kernels: Kernels,
    up: &UncertaintyParams,
    provenance: Provenance,
    choice: &CalibrationChoice,
) -> Result<CaseRunReport, CaseRunError> {
    let mut case = CaseFile::load(path)?;
    let (prm, up, used, warning) = choice.apply(&case, prm, up);
    case.warnings.extend(warning);
    run_loaded(&case, path, out, &prm, kernels, &up, provenance, Some(used))
}

/// Reconstruct a loaded case and write its files (`run_case_with`).
#[allow(clippy::too_many_arguments)]
fn run_loaded(
    case: &Case,
    path: &Path,
    out: &Path,
    prm: &ReconParams,
    kernels: Kernels,
    up: &UncertaintyParams,
    provenance: Provenance,
    calibration: Option<CalibrationUsed>,
) -> Result<CaseRunReport, CaseRunError> {
    let t = std::time::Instant::now();
    let (rec, cup) = solve_case(case, path, prm, kernels, up)?;
    let seconds = t.elapsed().as_secs_f64();

    let write_err = |p: &Path, source| CaseRunError::Write {
        path: p.to_path_buf(),
        source,
    };
    let mut report = None;
    crate::io::fill_dir_atomically(
        out,
        |stage| {
            let mut files = vec!["reconstruction.ply".to_string()];
            #[allow(unused_mut)]
            let mut warnings = case.warnings.clone();
            warnings.extend(rec.log.view_note(&case.names));
            write_ply(&rec.mesh, None, &stage.join("reconstruction.ply"))?;
            #[cfg(feature = "plots")]
            {
                draw_overlays(case, &rec, &cup, stage, &mut files, &mut warnings);
                draw_surface(&rec, kernels, stage, &mut files, &mut warnings);
            }
            #[cfg(not(feature = "plots"))]
            let _ = &case.images; // overlays need the `plots` feature
            files.push("cup.json".into());
            files.push("report.json".into());
            let r = CaseRunReport {
                case: path.display().to_string(),
                method: prm.method.name().into(),
                backend: kernels.name().into(),
                pose_prior: crate::pipeline::params_used(&rec, prm)
                    .pose
                    .map(|p| p.prior_sds()),
                cup: cup.clone(),
                provenance: provenance.clone(),
                sphere: rec.sphere,
                views: case.geometry.clone(),
                log: rec.log.clone(),
                seconds,
                files,
                calibration: calibration.clone(),
                warnings,
            };
            std::fs::write(stage.join("cup.json"), pretty(&cup))
                .map_err(|e| write_err(stage, e))?;
            std::fs::write(stage.join("report.json"), pretty(&r))
                .map_err(|e| write_err(stage, e))?;
            report = Some(r);
            Ok(())
        },
        write_err,
    )?;
    Ok(report.expect("set by the successful fill"))
}

/// Each view's overlay (`overlay-K-NAME.png`: the contours over its X-ray, the catalogue cup,
/// the clicks) written into `stage`; the files drawn added to `files`, a warning for each not.
#[cfg(feature = "plots")]
fn draw_overlays(
    case: &Case,
    rec: &Reconstruction,
    cup: &CupReport,
    stage: &Path,
    files: &mut Vec<String>,
    warnings: &mut Vec<String>,
) {
    for (k, cam) in case.cameras.iter().enumerate() {
        let name = format!("overlay-{k}-{}.png", file_safe(&case.names[k]));
        let marks = OverlayMarks::of_result(
            case.names[k].clone(),
            cam,
            &rec.sphere.center_point(),
            cup.catalogue_mm,
            case.clicks.get(k).map_or(&[], Vec::as_slice),
        );
        match overlay(
            (cam.width, cam.height),
            case.images[k].as_deref(),
            &rec.initial_contours[k].points,
            &rec.final_contours[k].points,
            &case.observed[k],
            &marks,
            &stage.join(&name),
        ) {
            Ok(()) => files.push(name),
            Err(e) => warnings.push(format!("{name} not drawn: {e}")),
        }
    }
}

/// The result from two viewpoints (`reconstruction.png`), coloured by its distance to the cup
/// sphere as fitted (the surface's geometry, before the calibration's size correction),
/// rendered by `kernels`; added to `files`, or a warning when it is not drawn.
#[cfg(feature = "plots")]
fn draw_surface(
    rec: &Reconstruction,
    kernels: Kernels,
    stage: &Path,
    files: &mut Vec<String>,
    warnings: &mut Vec<String>,
) {
    let fitted = &rec.fitted_sphere;
    let c = fitted.center_point();
    let dist: Vec<f64> = rec
        .mesh
        .vertices
        .iter()
        .map(|v| ((v - c).norm() - fitted.radius).abs())
        .collect();
    let axis = crate::report::plots::opening_axis(&rec.mesh, fitted);
    match crate::report::plots::surface_views(
        &rec.mesh,
        &dist,
        &axis,
        3.0,
        "off the cup sphere (mm)",
        &stage.join("reconstruction.png"),
        &|p| kernels.render_surface(p).0,
    ) {
        Ok(()) => files.push("reconstruction.png".into()),
        Err(e) => warnings.push(format!("reconstruction.png not drawn: {e}")),
    }
}

/// Reconstruct a validated case and report its cup (with its uncertainty), writing nothing:
/// refused when the reconstruction fails or the catalogue cannot hold the cup. `path` names the
/// case in the errors.
pub fn solve_case(
    case: &Case,
    path: &Path,
    prm: &ReconParams,
    kernels: Kernels,
    up: &UncertaintyParams,
) -> Result<(Reconstruction, CupReport), CaseRunError> {
    let recon_err = |mut source: ReconError| {
        // A refusal names a view that disagrees by the case's own view names.
        if let ReconError::Guard(refusal) = &mut source {
            refusal.names = case.names.clone();
        }
        CaseRunError::Recon {
            path: path.to_path_buf(),
            source: Box::new(source),
            warnings: case.warnings.clone(),
        }
    };
    let template = Template::standard();
    let rec = reconstruct(&case.input(&template), prm, kernels).map_err(recon_err)?;
    let catalogue = &prm.cup.catalogue;
    if !catalogue.holds(rec.sphere.diameter()) {
        return Err(CaseRunError::Catalogue {
            path: path.to_path_buf(),
            diameter_mm: rec.sphere.diameter(),
            min_mm: catalogue.sizes_mm.first().copied().unwrap_or(f64::NAN),
            max_mm: catalogue.sizes_mm.last().copied().unwrap_or(f64::NAN),
        });
    }
    let cup = cup_report(&rec, &case.observed, prm, kernels, up).map_err(recon_err)?;
    Ok((rec, cup))
}

/// The case file's warnings after a failed reconstruction's reason (none: nothing).
fn read_with(warnings: &[String]) -> String {
    if warnings.is_empty() {
        String::new()
    } else {
        format!(
            " (the case file was read with warnings: {})",
            warnings.join("; ")
        )
    }
}

/// Pretty JSON of a report (the two report types serialise infallibly: plain fields).
fn pretty<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string_pretty(v).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}
