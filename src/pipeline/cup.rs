//! The cup sphere: fitted to the part of the result the X-rays observe.

use crate::mesh::Mesh;
use crate::report::{fit_sphere_robust, Sphere};
use crate::solve::Observation;
use nalgebra::Point3;

/// Fewest distinct observed vertices the cup sphere is fitted to.
const MIN_SPHERE_VERTICES: usize = 30;

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
