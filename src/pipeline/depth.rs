//! The result's depth along the views, and its learned offset. Views turned about one body axis
//! (the paper's antero-posterior view and two obliques at +-20 degrees about the longitudinal
//! axis) all look along nearly one direction: the depth of the acetabulum along it shows only
//! in the obliques' small parallax, and the surface that faces it never forms an outline. There
//! the reconstruction settles where the template's shape, not the X-rays, puts it: on the
//! shared acetabula every method's result sits 0.6-1.1 mm too deep, away from the opening
//! (docs/population.md, "The result's depth along the views"). A calibration learned on
//! acetabula whose surface is known (`CupCalibration::depth_mm`, `CupParams::depth_mm`) moves
//! the result that far back toward the opening; without one nothing moves.

use crate::geom::{opening_axis, Mesh};
use crate::views::Camera;
use nalgebra::{Point3, Vector3};

/// Below this |a . d| (the opening axis a against the views' mean direction d) the depth axis
/// shrinks linearly to zero: an opening turned across the views is too deep along neither side
/// of them.
pub const FACING_RAMP: f64 = 0.1;

/// The depth axis of a result `mesh` whose sphere is centred at `center` (its whole surface's,
/// `CupSpheres::surface`), seen in `cams`: the mean of the unit directions from that centre to
/// the views' sources, pointing to the side the opening faces, its length 1
/// where the opening faces that side clearly (|a . d| >= `FACING_RAMP`) and falling to 0 as the
/// opening turns across the views. None when there are no views or the sources' directions
/// cancel out.
pub fn depth_axis(mesh: &Mesh, center: &Point3<f64>, cams: &[Camera]) -> Option<Vector3<f64>> {
    let d = cams
        .iter()
        .filter_map(|cam| (cam.center() - center).try_normalize(1e-12))
        .sum::<Vector3<f64>>()
        .try_normalize(1e-9)?;
    let a = opening_axis(&mesh.vertices, center);
    let facing = (a.dot(&d) / FACING_RAMP).clamp(-1.0, 1.0);
    facing.is_finite().then(|| d * facing)
}

/// `mesh` moved by `v` (a depth offset: the axis times the offset, toward the opening).
pub fn moved(mesh: &Mesh, v: &Vector3<f64>) -> Mesh {
    mesh.with_vertices(mesh.vertices.iter().map(|p| p + v).collect())
}

/// What takes `rec` back to where the method fitted it: minus the calibration's depth offset
/// (`SolveLog::depth_moved_mm` along `SolveLog::depth_axis`), zero when none moved it.
pub fn back_to_fit(rec: &crate::pipeline::Reconstruction) -> Vector3<f64> {
    match rec.log.depth_axis {
        Some(a) if rec.log.depth_moved_mm != 0.0 => -Vector3::from(a) * rec.log.depth_moved_mm,
        _ => Vector3::zeros(),
    }
}

/// The surface of `rec` as the method fitted it (`back_to_fit`).
pub fn fit_of(rec: &crate::pipeline::Reconstruction) -> Mesh {
    match back_to_fit(rec) {
        v if v == Vector3::zeros() => rec.mesh.clone(),
        v => moved(&rec.mesh, &v),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{simulated_views, XrayGeometry};
    use crate::template::{spherical_cap, Placement};
    use nalgebra::{Point3, Unit};

    fn cap_facing(axis: Vector3<f64>) -> (Mesh, Point3<f64>, Vec<Camera>) {
        let place = Placement {
            center: Point3::new(90.0, 20.0, -560.0),
            radius: 26.0,
            axis: Unit::new_normalize(axis),
        };
        let mesh = place.place(&spherical_cap(1.0, 2000, 80f64.to_radians()));
        let cams = simulated_views(&XrayGeometry::default(), &place.center);
        (mesh, place.center, cams)
    }

    #[test]
    fn the_axis_points_along_the_views_to_the_side_the_opening_faces() {
        // The simulated sources stand on +y (the antero-posterior view's, and the obliques'
        // turned +-20 degrees about z): an opening lateral and a little toward them gives +y, one
        // a little away from them -y, each of full length.
        let (toward, c, cams) = cap_facing(Vector3::new(1.0, 0.4, -0.5));
        let a = depth_axis(&toward, &c, &cams).unwrap();
        assert!((a.norm() - 1.0).abs() < 1e-9 && a.y > 0.99, "{a:?}");
        let (away, c, cams) = cap_facing(Vector3::new(1.0, -0.4, -0.5));
        let b = depth_axis(&away, &c, &cams).unwrap();
        assert!((b.norm() - 1.0).abs() < 1e-9 && b.y < -0.99, "{b:?}");
        // Companion: an opening square across the views gives (almost) no axis.
        let (across, c, cams) = cap_facing(Vector3::new(1.0, 0.0, -0.5));
        let s = depth_axis(&across, &c, &cams).unwrap();
        assert!(s.norm() < 0.2, "{s:?}");
        // No views: no axis.
        assert!(depth_axis(&toward, &c, &[]).is_none());
    }

    #[test]
    fn moved_translates_every_vertex_by_the_offset_along_the_axis() {
        let (mesh, _, _) = cap_facing(Vector3::new(1.0, 0.4, -0.5));
        let axis = Vector3::new(0.0, -1.0, 0.0);
        let m = moved(&mesh, &(axis * 0.8));
        for (p, q) in mesh.vertices.iter().zip(&m.vertices) {
            assert!((q - p - Vector3::new(0.0, -0.8, 0.0)).norm() < 1e-12);
        }
        assert_eq!(m.triangles, mesh.triangles);
        // Companion: no offset, no move.
        assert_eq!(moved(&mesh, &(axis * 0.0)).vertices, mesh.vertices);
    }
}
