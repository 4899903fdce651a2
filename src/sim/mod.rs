//! Simulated truths and X-rays: the built-in phantom, the simulated view geometry, synthetic
//! cases from a ground-truth surface (noise levels, perturbed starts), and the demonstration.

mod demo;
mod geometry;
mod phantom;
mod realistic;
mod simulate;
mod truth;

pub use demo::{phantom_case, run_demo, DemoError, DemoReport, DEMO_NOISE_PX};
pub use geometry::{simulated_views, BodyAxis, GeometryError, ViewRotation, XrayGeometry};
pub use phantom::{phantom, radiographic_axis, try_phantom, Phantom, PhantomError, PhantomParams};
pub use realistic::{Protocol, RealisticErrors};
pub use simulate::{
    fit_placement, ground_truth_surface, observed_alpha, perturb, perturb_poses, simulate_case,
    NoiseLevel, SimCase, SimError, SimSetup, OBSERVED_ALPHA_FRACTION,
};
pub use truth::{load_truth, TruthError, PLAUSIBLE_RADIUS_MM};
