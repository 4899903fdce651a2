//! The simulated X-ray set-up: a point source 900 mm from the object, detector 1100 mm from the
//! source (magnification 1.22), 0.2 mm pixels, 2048 x 2048 images; each view the antero-posterior
//! one turned about body axes (default: about the longitudinal axis z by 0, +20 and -20 degrees)
//! and aimed at the object.

use crate::views::{spread_too_narrow, Camera, Intrinsics, MIN_VIEW_SPREAD_DEG};
pub use crate::views::{BodyAxis, ViewRotation};
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
    /// Each view: the antero-posterior view turned about body axes (see `ViewRotation`).
    pub views: Vec<ViewRotation>,
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
    pub expected: String,
}

impl XrayGeometry {
    /// Distances and pixel size finite and positive, the object between the source and the
    /// detector, a non-empty image, and finite view angles with two sources at least
    /// `MIN_VIEW_SPREAD_DEG` apart (closer ones leave the depth of the cap along them open).
    pub fn validate(&self) -> Result<(), GeometryError> {
        fn bad(field: &'static str, value: String, expected: impl Into<String>) -> GeometryError {
            GeometryError {
                field,
                value: crate::io::shown(&value),
                expected: expected.into(),
            }
        }
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
        if let Some(v) = self
            .views
            .iter()
            .find(|v| v.turns.is_empty() || v.turns.iter().any(|(_, d)| !d.is_finite()))
        {
            return Err(bad("views", v.to_string(), "turns of finite degrees"));
        }
        // Two views are one if their sources stand in (about) the same direction.
        let sources: Vec<Vector3<f64>> = self
            .views
            .iter()
            .map(ViewRotation::source_direction)
            .collect();
        if spread_too_narrow(&sources).is_some() {
            let list: Vec<String> = self.views.iter().map(|v| v.to_string()).collect();
            return Err(bad(
                "views",
                format!("[{}]", list.join(",")),
                format!(
                    "at least two views {MIN_VIEW_SPREAD_DEG} degrees or more apart \
                     (MIN_VIEW_SPREAD_DEG: closer views leave the cap's depth along them open)"
                ),
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
            views: [0.0, 20.0, -20.0]
                .into_iter()
                .map(ViewRotation::about_z)
                .collect(),
        }
    }
}

/// One camera per view: the antero-posterior source (anterior, on +y) turned by the view's
/// rotation, looking at `target`, image rows running along the turned inferior direction.
pub fn simulated_views(g: &XrayGeometry, target: &Point3<f64>) -> Vec<Camera> {
    let f = g.source_to_detector / g.pixel_size;
    let c = g.image_size as f64 / 2.0;
    g.views
        .iter()
        .map(|v| {
            let rot = v.rotation();
            let toward_source = rot * Vector3::y();
            let source = target + toward_source * g.source_to_object;
            let zc = -toward_source;
            let yc = -(rot * Vector3::z());
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
            ("views", about_z(&[0.0, f64::NAN])),
            ("views", about_z(&[20.0])),
            ("views", about_z(&[0.0, 360.0, -360.0])),
            ("views", about_z(&[])),
            (
                "views",
                XrayGeometry {
                    views: vec![ViewRotation::about_z(0.0), ViewRotation { turns: vec![] }],
                    ..Default::default()
                },
            ),
            // Turning about the antero-posterior axis itself moves no source.
            (
                "views",
                XrayGeometry {
                    views: vec![ViewRotation::about_z(0.0), "y:30".parse().unwrap()],
                    ..Default::default()
                },
            ),
        ];
        for (field, g) in cases {
            assert_eq!(g.validate().map_err(|e| e.field), Err(field), "{g:?}");
        }
        // Sources 1 degree apart see the same outline, and 12 degrees leave the depth open:
        // refused.
        for spread in [1.0, 12.0, 14.9] {
            assert_eq!(
                about_z(&[0.0, 360.0 - spread])
                    .validate()
                    .map_err(|e| e.field),
                Err("views")
            );
            assert_eq!(
                about_z(&[-spread / 2.0, spread / 2.0])
                    .validate()
                    .map_err(|e| e.field),
                Err("views")
            );
        }
        // Companion: two views 15 degrees apart are enough, about any axis.
        assert_eq!(about_z(&[0.0, 345.0]).validate(), Ok(()));
        assert_eq!(about_z(&[-7.5, 7.5]).validate(), Ok(()));
        let inlet = XrayGeometry {
            views: vec![ViewRotation::about_z(0.0), "x:25".parse().unwrap()],
            ..Default::default()
        };
        assert_eq!(inlet.validate(), Ok(()));
    }

    fn about_z(deg: &[f64]) -> XrayGeometry {
        XrayGeometry {
            views: deg.iter().map(|d| ViewRotation::about_z(*d)).collect(),
            ..Default::default()
        }
    }

    #[test]
    fn views_read_and_write_as_text_and_turn_the_source_about_their_axes() {
        let v: ViewRotation = "z:20+x:-15".parse().unwrap();
        assert_eq!(v.turns, vec![(BodyAxis::Z, 20.0), (BodyAxis::X, -15.0)]);
        assert_eq!(v.to_string(), "z:20+x:-15");
        let signed: ViewRotation = "z:+20+x:+5".parse().unwrap();
        // Companion of the refused angles below: the ends of the range are read.
        assert!("z:180+x:-180".parse::<ViewRotation>().is_ok());
        assert_eq!(signed.turns, vec![(BodyAxis::Z, 20.0), (BodyAxis::X, 5.0)]);
        for bad in ["20", "w:10", "z:ten", "z:inf", "z:20+", "z:400", "x:-180.5"] {
            assert!(bad.parse::<ViewRotation>().is_err(), "{bad}");
        }
        // z:90 puts the source on the left-right axis; x:90 above the object (inlet at 90).
        let src = |s: &str| s.parse::<ViewRotation>().unwrap().rotation() * Vector3::y();
        assert!((src("z:90") - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-12);
        assert!((src("x:90") - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
        // An inlet view still looks at the target, superior up along its own turned axis.
        let target = Point3::new(1.0, 2.0, 3.0);
        let g = XrayGeometry {
            views: vec![ViewRotation::about_z(0.0), "x:30".parse().unwrap()],
            ..Default::default()
        };
        let cams = simulated_views(&g, &target);
        let px = cams[1].project(&target).unwrap();
        assert!((px.x - 1024.0).abs() < 1e-9 && (px.y - 1024.0).abs() < 1e-9);
        assert!(((cams[1].center() - target).norm() - 900.0).abs() < 1e-9);
        // Companion: the tilted view is not the antero-posterior one.
        assert!((cams[1].center() - cams[0].center()).norm() > 100.0);
    }
}
