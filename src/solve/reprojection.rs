//! The one data term every solve shares (similarity, pose, deformation): an observation's
//! reprojection residual in its contour's frame (across the outline, with `tangential` weight
//! along it; see `Observation::residual_frame`), scaled by the caller's weight (to mm at the
//! object), and its Jacobian with respect to the world point.

use super::normal::Linearization;
use crate::correspond::Observation;
use crate::views::Camera;
use nalgebra::{Matrix2x3, Point3, Vector2};

/// One observation's residual and, when asked for, d(residual)/d(world point).
pub struct Reprojection {
    /// `scale * F (project(v) - target)`, F the contour frame.
    pub residual: Vector2<f64>,
    /// `scale * F dproject/dv`, when asked for.
    pub jacobian: Option<Matrix2x3<f64>>,
}

/// The data term of `o` at world point `v` seen by `cam`. `with_jacobian` projects with the
/// Jacobian (`Camera::project_with_jacobian`), otherwise plainly (`Camera::project`); the two
/// round differently, and each solve keeps the projection it was written with. None when `v`
/// lies behind the source: the caller pushes `behind` instead, an infinite cost that refuses
/// the step that led there.
pub fn reprojection(
    cam: &Camera,
    v: &Point3<f64>,
    o: &Observation,
    tangential: f64,
    scale: f64,
    with_jacobian: bool,
) -> Option<Reprojection> {
    let (px, jp) = if with_jacobian {
        let (px, jp) = cam.project_with_jacobian(v).ok()?;
        (px, Some(jp))
    } else {
        (cam.project(v).ok()?, None)
    };
    let frame = o.residual_frame(tangential);
    Some(Reprojection {
        residual: frame * (px - o.target) * scale,
        jacobian: jp.map(|j| frame * j * scale),
    })
}

/// The two residuals of an observation behind the source: infinite.
pub fn behind(l: &mut Linearization) {
    l.push_residual(f64::INFINITY);
    l.push_residual(f64::INFINITY);
}
