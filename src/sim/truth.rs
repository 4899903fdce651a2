//! A study's ground truth from its name: `phantom` (the built-in one) or a mesh file, checked to
//! be an acetabulum in millimetres before any run.

use crate::geom::{fit_sphere, Mesh};
use crate::io::read_mesh;
use crate::sim::{ground_truth_surface, phantom, PhantomParams};
use std::path::Path;

/// Sphere radii (mm) an acetabulum can have; a truth outside them is refused (in metres or
/// centimetres it would run, but the solver's tolerances and the guards are in millimetres).
pub const PLAUSIBLE_RADIUS_MM: (f64, f64) = (15.0, 60.0);

/// The truth cannot be used; the message names it (as `--gt NAME`) and says why.
#[derive(Debug, thiserror::Error)]
#[error("--gt {gt}: {reason}")]
pub struct TruthError {
    /// The truth as given.
    pub gt: String,
    /// Why it is refused.
    pub reason: String,
}

/// The truth `gt` (a mesh file or `phantom`). A surface no sphere fits, one whose sphere's
/// radius is outside `PLAUSIBLE_RADIUS_MM`, or one the simulated views cannot see is refused.
pub fn load_truth(gt: &str) -> Result<Mesh, TruthError> {
    let err = |reason: String| TruthError {
        gt: gt.to_string(),
        reason,
    };
    let truth = if gt == "phantom" {
        phantom(&PhantomParams::default()).mesh
    } else {
        let mesh = read_mesh(Path::new(gt)).map_err(|e| err(e.to_string()))?;
        ground_truth_surface(&mesh).map_err(|e| err(e.to_string()))?
    };
    let r = fit_sphere(&truth.vertices)
        .map_err(|e| err(format!("ground truth sphere fit: {e}")))?
        .radius;
    let (lo, hi) = PLAUSIBLE_RADIUS_MM;
    if !(lo..=hi).contains(&r) {
        return Err(err(format!(
            "the fitted sphere's radius is {r:.3} mm, outside the {lo}-{hi} mm of an \
             acetabulum: is the mesh in millimetres?"
        )));
    }
    Ok(truth)
}
