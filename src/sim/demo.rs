//! The built-in demonstration and the evaluation shared by the CLI: simulate the phantom, run the
//! reconstruction, measure it against the truth, write the outputs.

use crate::engine::Kernels;
use crate::geom::Mesh;
use crate::io::MeshIoError;
use crate::pipeline::{reconstruct, ReconError, ReconParams, Reconstruction};
use crate::report::accuracy;
use crate::sim::XrayGeometry;
use crate::sim::{phantom, PhantomParams};
use crate::sim::{simulate_case, NoiseLevel, SimCase, SimError};
use crate::template::Template;
use serde::Serialize;

/// What `acetab demo` reports.
#[derive(Clone, Debug, Serialize)]
pub struct DemoReport {
    /// The seed of every draw.
    pub seed: u64,
    /// The start's noise level (0-5).
    pub level: u32,
    /// The correspondence method.
    pub method: String,
    /// Contour noise SD, pixels.
    pub contour_noise_px: f64,
    /// Mean truth -> result distance, mm.
    pub mae_mm: f64,
    /// Its SD, mm.
    pub sd_mm: f64,
    /// Its 95th percentile, mm.
    pub p95_mm: f64,
    /// The cup sphere's diameter, mm.
    pub cup_diameter_mm: f64,
    /// Its nearest catalogue size, mm.
    pub cup_catalogue_mm: f64,
    /// The truth's sphere diameter, mm.
    pub gt_cup_diameter_mm: f64,
    /// Cup minus truth, mm.
    pub cup_error_mm: f64,
    /// Mean distance of the start, mm.
    pub initial_mae_mm: f64,
    /// Seconds for the reconstruction.
    pub seconds: f64,
    /// Where the kernels ran: "cpu" or "gpu".
    pub backend: String,
    /// What the solver did.
    pub log: crate::pipeline::SolveLog,
}

/// Why the demo failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DemoError {
    /// A noise level outside 0..=5.
    #[error("noise level {0} is not one of 0..5")]
    Level(u32),
    /// The phantom could not be simulated.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The reconstruction failed.
    #[error(transparent)]
    Recon(#[from] ReconError),
    /// An output mesh could not be written.
    #[error(transparent)]
    Io(#[from] MeshIoError),
    /// An output file could not be written.
    #[error("{path}: cannot write: {source}")]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Contour noise of the demonstration's simulated X-rays, pixels.
pub const DEMO_NOISE_PX: f64 = 2.0;

/// The demonstration's case, the one fixture the demo, the tests, the benches and the examples
/// share: the default phantom in the default views with `DEMO_NOISE_PX` contour noise and a
/// start perturbed at noise level `level` (0-5), drawn with `seed`. Returns the truth and the
/// case.
pub fn phantom_case(level: u32, seed: u64) -> Result<(Mesh, SimCase), DemoError> {
    let noise = NoiseLevel::level(level).ok_or(DemoError::Level(level))?;
    let truth = phantom(&PhantomParams::default()).mesh;
    let sim = simulate_case(
        &truth,
        &XrayGeometry::default(),
        DEMO_NOISE_PX,
        &noise,
        seed,
    )?;
    Ok((truth, sim))
}

/// Simulate the default phantom at `level`, reconstruct from the standard template with the
/// kernels on `kernels`, and measure.
pub fn run_demo(
    seed: u64,
    level: u32,
    prm: &ReconParams,
    kernels: Kernels,
) -> Result<(DemoReport, Mesh, Reconstruction), DemoError> {
    let (truth, sim) = phantom_case(level, seed)?;
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
        contour_noise_px: DEMO_NOISE_PX,
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
