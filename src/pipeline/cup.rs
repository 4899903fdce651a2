//! The cup sphere, the one estimator of the cup: fitted to the part of the result the X-rays
//! observe. `reconstruct` reports it and the uncertainty's resamples go through it too, so the
//! +- and the size probabilities describe the number they stand beside.

use crate::correspond::Observation;
use crate::geom::Mesh;
use crate::geom::{fit_sphere_robust, Sphere, SphereFitError};
use nalgebra::Point3;

/// Fewest distinct observed vertices the cup sphere is fitted to.
const MIN_SPHERE_VERTICES: usize = 30;

/// The cup sphere of a reconstructed surface and the sphere of its whole surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CupSpheres {
    /// The cup: the observed part's sphere (`observed_part_sphere`), or the whole surface's when
    /// too few vertices are observed.
    pub cup: Sphere,
    /// The sphere fitted (robustly) to every vertex.
    pub surface: Sphere,
}

/// The cup estimator: the observed part's sphere of `mesh` under the correspondences `obs` (with
/// their robust weights), falling back to the whole surface's sphere.
pub fn cup_spheres(mesh: &Mesh, obs: &[Observation]) -> Result<CupSpheres, SphereFitError> {
    let surface = fit_sphere_robust(&mesh.vertices)?;
    let cup = observed_part_sphere(mesh, obs).unwrap_or(surface);
    Ok(CupSpheres { cup, surface })
}

/// Robust sphere fit to the reconstructed vertices that the correspondences hold to the outlines
/// (robust weight above one half). Away from the outlines the surface is the template's
/// interpolation, which the X-rays never see; there the deformation's smoothing, not the patient,
/// decides the shape, and a whole-surface fit follows it. None when too few such vertices.
pub fn observed_part_sphere(mesh: &Mesh, obs: &[Observation]) -> Option<Sphere> {
    let mut ids: Vec<u32> = obs
        .iter()
        .filter(|o| o.weight > 0.5)
        .map(|o| o.vertex)
        .filter(|&v| (v as usize) < mesh.vertex_count())
        .collect();
    ids.sort_unstable();
    ids.dedup();
    if ids.len() < MIN_SPHERE_VERTICES {
        return None;
    }
    let pts: Vec<Point3<f64>> = ids.iter().map(|&v| mesh.vertices[v as usize]).collect();
    fit_sphere_robust(&pts)
        .ok()
        .filter(|s| s.radius.is_finite())
}
