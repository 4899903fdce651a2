//! The simulated X-ray set-up: a point source 900 mm from the object, detector 1100 mm from the
//! source (magnification 1.22), 0.2 mm pixels, 2048 x 2048 images; views rotated about the body's
//! longitudinal axis (z) and aimed at the object.

use crate::views::{Camera, Intrinsics};
use nalgebra::{Matrix3, Point3, Rotation3, Vector3};

/// X-ray geometry in mm and pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct XrayGeometry {
    /// Source to detector, mm.
    pub source_to_detector: f64,
    /// Source to the object's centre, mm.
    pub source_to_object: f64,
    /// Detector pixel size, mm.
    pub pixel_size: f64,
    /// Image width and height, pixels.
    pub image_size: u32,
    /// Rotation of each view about the world z axis, degrees (0 = antero-posterior).
    pub angles_deg: Vec<f64>,
}

/// A geometry no X-ray set-up has (see `XrayGeometry::validate`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("X-ray geometry: {field} = {value}: must be {expected}")]
pub struct GeometryError {
    /// The setting.
    pub field: &'static str,
    /// Its value.
    pub value: String,
    /// What it must be.
    pub expected: &'static str,
}

impl XrayGeometry {
    /// Distances and pixel size finite and positive, the object between the source and the
    /// detector, a non-empty image, and at least two distinct finite view angles (one view
    /// cannot place anything in depth).
    pub fn validate(&self) -> Result<(), GeometryError> {
        let bad = |field, value: String, expected| GeometryError {
            field,
            value,
            expected,
        };
        for (field, v) in [
            ("source_to_object", self.source_to_object),
            ("pixel_size", self.pixel_size),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(field, v.to_string(), "finite and > 0"));
            }
        }
        let sdd = self.source_to_detector;
        if !(sdd.is_finite() && sdd > self.source_to_object) {
            return Err(bad(
                "source_to_detector",
                sdd.to_string(),
                "finite and beyond the object (> source_to_object)",
            ));
        }
        if self.image_size == 0 {
            return Err(bad("image_size", "0".into(), "at least 1 pixel"));
        }
        if let Some(a) = self.angles_deg.iter().find(|a| !a.is_finite()) {
            return Err(bad("angles_deg", a.to_string(), "finite degrees"));
        }
        let distinct =
            |a: f64, b: f64| ((a - b).rem_euclid(360.0)).min((b - a).rem_euclid(360.0)) > 1e-9;
        let first = self.angles_deg.first().copied();
        if !first.is_some_and(|f| self.angles_deg.iter().any(|&a| distinct(a, f))) {
            return Err(bad(
                "angles_deg",
                format!("{:?}", self.angles_deg),
                "at least two distinct angles",
            ));
        }
        Ok(())
    }
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

    #[test]
    fn a_geometry_no_xray_has_is_refused_with_its_field() {
        assert_eq!(XrayGeometry::default().validate(), Ok(()));
        let cases: Vec<(&str, XrayGeometry)> = vec![
            (
                "pixel_size",
                XrayGeometry {
                    pixel_size: 0.0,
                    ..Default::default()
                },
            ),
            (
                "pixel_size",
                XrayGeometry {
                    pixel_size: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "source_to_object",
                XrayGeometry {
                    source_to_object: -1.0,
                    ..Default::default()
                },
            ),
            (
                "source_to_detector",
                XrayGeometry {
                    source_to_detector: 800.0,
                    ..Default::default()
                },
            ),
            (
                "image_size",
                XrayGeometry {
                    image_size: 0,
                    ..Default::default()
                },
            ),
            (
                "angles_deg",
                XrayGeometry {
                    angles_deg: vec![0.0, f64::NAN],
                    ..Default::default()
                },
            ),
            (
                "angles_deg",
                XrayGeometry {
                    angles_deg: vec![20.0],
                    ..Default::default()
                },
            ),
            (
                "angles_deg",
                XrayGeometry {
                    angles_deg: vec![0.0, 360.0, -360.0],
                    ..Default::default()
                },
            ),
            (
                "angles_deg",
                XrayGeometry {
                    angles_deg: vec![],
                    ..Default::default()
                },
            ),
        ];
        for (field, g) in cases {
            assert_eq!(g.validate().map_err(|e| e.field), Err(field), "{g:?}");
        }
        // Companion: two distinct views are enough.
        let two = XrayGeometry {
            angles_deg: vec![0.0, 359.0],
            ..Default::default()
        };
        assert_eq!(two.validate(), Ok(()));
    }
}
