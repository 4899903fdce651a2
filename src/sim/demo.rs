//! The built-in demonstration and the evaluation shared by the CLI: simulate the phantom, run the
//! reconstruction, measure it against the truth, write the outputs.

use crate::engine::Kernels;
use crate::geom::Mesh;
use crate::io::MeshIoError;
use crate::pipeline::{reconstruct, ReconError, ReconParams, Reconstruction};
use crate::report::accuracy;
use crate::sim::XrayGeometry;
use crate::sim::{phantom, PhantomParams};
use crate::sim::{simulate_case, NoiseLevel, SimError};
use crate::template::Template;
use serde::Serialize;

/// What `acetab demo` reports.
#[derive(Clone, Debug, Serialize)]
pub struct DemoReport {
    pub seed: u64,
    pub level: u32,
    pub method: String,
    pub contour_noise_px: f64,
    pub mae_mm: f64,
    pub sd_mm: f64,
    pub p95_mm: f64,
    pub cup_diameter_mm: f64,
    pub cup_catalogue_mm: f64,
    pub gt_cup_diameter_mm: f64,
    pub cup_error_mm: f64,
    pub initial_mae_mm: f64,
    pub seconds: f64,
    /// Where the kernels ran: "cpu" or "gpu".
    pub backend: String,
    pub log: crate::pipeline::SolveLog,
}

#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    #[error("noise level {0} is not one of 0..5")]
    Level(u32),
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Recon(#[from] ReconError),
    #[error(transparent)]
    Io(#[from] MeshIoError),
    #[error("{path}: cannot write: {source}")]
    Write {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
}

/// Simulate the default phantom at `level`, reconstruct from the standard template with the
/// kernels on `kernels`, and measure.
pub fn run_demo(
    seed: u64,
    level: u32,
    prm: &ReconParams,
    kernels: Kernels,
) -> Result<(DemoReport, Mesh, Reconstruction), DemoError> {
    let noise = NoiseLevel::level(level).ok_or(DemoError::Level(level))?;
    let truth = phantom(&PhantomParams::default()).mesh;
    let sim = simulate_case(&truth, &XrayGeometry::default(), 2.0, &noise, seed)?;
    let start = std::time::Instant::now();
    let template = Template::standard();
    let rec = reconstruct(&sim.input(&template), prm, kernels)?;
    let seconds = start.elapsed().as_secs_f64();
    let acc = accuracy(&truth, &rec.mesh);
    let init_acc = accuracy(&truth, &rec.initial);
    let report = DemoReport {
        seed,
        level,
        method: prm.method.name().to_string(),
        contour_noise_px: 2.0,
        mae_mm: acc.mae_mm,
        sd_mm: acc.sd_mm,
        p95_mm: acc.p95_mm,
        cup_diameter_mm: rec.sphere.diameter(),
        cup_catalogue_mm: rec.cup.catalogue_mm,
        gt_cup_diameter_mm: sim.truth_sphere.diameter(),
        cup_error_mm: rec.sphere.diameter() - sim.truth_sphere.diameter(),
        initial_mae_mm: init_acc.mae_mm,
        seconds,
        backend: kernels.name().to_string(),
        log: rec.log.clone(),
    };
    Ok((report, truth, rec))
}
