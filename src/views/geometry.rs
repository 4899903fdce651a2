//! The simulated X-ray set-up: a point source 900 mm from the object, detector 1100 mm from the
//! source (magnification 1.22), 0.2 mm pixels, 2048 x 2048 images; views rotated about the body's
//! longitudinal axis (z) and aimed at the object.

use super::camera::{Camera, Intrinsics};
use nalgebra::{Matrix3, Point3, Rotation3, Vector3};

/// X-ray geometry in mm and pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct XrayGeometry {
    pub source_to_detector: f64,
    pub source_to_object: f64,
    pub pixel_size: f64,
    pub image_size: u32,
    /// Rotation of each view about the world z axis, degrees (0 = antero-posterior).
    pub angles_deg: Vec<f64>,
}

impl Default for XrayGeometry {
    fn default() -> Self {
        XrayGeometry {
            source_to_detector: 1100.0,
            source_to_object: 900.0,
            pixel_size: 0.2,
            image_size: 2048,
            angles_deg: vec![0.0, 20.0, -20.0],
        }
    }
}

/// One camera per angle, the source placed anteriorly (rotated about z), looking at `target`,
/// image rows running inferiorly.
pub fn simulated_views(g: &XrayGeometry, target: &Point3<f64>) -> Vec<Camera> {
    let f = g.source_to_detector / g.pixel_size;
    let c = g.image_size as f64 / 2.0;
    g.angles_deg
        .iter()
        .map(|deg| {
            let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), deg.to_radians());
            let toward_source = rz * Vector3::y();
            let source = target + toward_source * g.source_to_object;
            let zc = -toward_source;
            let yc = -Vector3::z();
            let xc = yc.cross(&zc);
            let r = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
                xc.transpose(),
                yc.transpose(),
                zc.transpose(),
            ]));
            let t = -(r * source.coords);
            Camera {
                k: Intrinsics {
                    fx: f,
                    fy: f,
                    cx: c,
                    cy: c,
                },
                r,
                t,
                width: g.image_size,
                height: g.image_size,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_are_aimed_at_the_target_at_the_right_distance() {
        let target = Point3::new(5.0, 6.0, 7.0);
        let g = XrayGeometry::default();
        for cam in simulated_views(&g, &target) {
            let px = cam.project(&target).unwrap();
            assert!((px.x - 1024.0).abs() < 1e-9 && (px.y - 1024.0).abs() < 1e-9);
            assert!(((cam.center() - target).norm() - 900.0).abs() < 1e-9);
            assert!((cam.r.matrix().determinant() - 1.0).abs() < 1e-12);
            // Magnification at the object: 1100/900 over 0.2 mm pixels.
            assert!((cam.pixels_per_mm_at(&target) - 1100.0 / 900.0 / 0.2).abs() < 1e-9);
            // Superior is up in the image.
            let up = cam.project(&(target + Vector3::z())).unwrap();
            assert!(up.y < 1024.0);
        }
    }
}
