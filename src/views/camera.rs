//! Pinhole camera: intrinsics K (fx, fy, cx, cy) and pose [R | t] taking world mm to camera mm.

use nalgebra::{Matrix2x3, Point2, Point3, Rotation3, Vector3};

/// Pixel intrinsics: focal lengths and principal point in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length in x, pixels.
    pub fx: f64,
    /// Focal length in y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

/// One view: intrinsics, pose (world -> camera) and image size in pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Intrinsics K.
    pub k: Intrinsics,
    /// Rotation R from the world (patient) frame to the camera frame.
    pub r: Rotation3<f64>,
    /// Translation t, mm: p ~ K (R P + t).
    pub t: Vector3<f64>,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

/// A point could not be projected.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ProjectionError {
    /// The point is not in front of the source.
    #[error("point is behind or on the camera plane (depth {depth} mm)")]
    BehindCamera {
        /// Its depth along the view axis, mm.
        depth: f64,
    },
}

/// Smallest depth (mm) accepted in front of the source.
pub const MIN_DEPTH: f64 = 1e-3;

impl Camera {
    /// World point in camera coordinates.
    pub fn to_camera(&self, p: &Point3<f64>) -> Vector3<f64> {
        self.r * p.coords + self.t
    }

    /// Project a world point to pixels, with the depth check.
    pub fn project(&self, p: &Point3<f64>) -> Result<Point2<f64>, ProjectionError> {
        let c = self.to_camera(p);
        if !(c.z > MIN_DEPTH) {
            return Err(ProjectionError::BehindCamera { depth: c.z });
        }
        Ok(Point2::new(
            self.k.fx * c.x / c.z + self.k.cx,
            self.k.fy * c.y / c.z + self.k.cy,
        ))
    }

    /// Project and return d(pixel)/d(world point) as well.
    pub fn project_with_jacobian(
        &self,
        p: &Point3<f64>,
    ) -> Result<(Point2<f64>, Matrix2x3<f64>), ProjectionError> {
        let c = self.to_camera(p);
        if !(c.z > MIN_DEPTH) {
            return Err(ProjectionError::BehindCamera { depth: c.z });
        }
        let iz = 1.0 / c.z;
        let px = Point2::new(
            self.k.fx * c.x * iz + self.k.cx,
            self.k.fy * c.y * iz + self.k.cy,
        );
        let dcam = Matrix2x3::new(
            self.k.fx * iz,
            0.0,
            -self.k.fx * c.x * iz * iz,
            0.0,
            self.k.fy * iz,
            -self.k.fy * c.y * iz * iz,
        );
        Ok((px, dcam * self.r.matrix()))
    }

    /// Position of the X-ray source (camera centre) in the world.
    pub fn center(&self) -> Point3<f64> {
        Point3::from(-(self.r.inverse() * self.t))
    }

    /// The direction the view looks along in the world (its optical axis).
    pub fn view_direction(&self) -> Vector3<f64> {
        self.r.inverse() * Vector3::z()
    }

    /// The outline of a sphere (centre, radius, mm) in this view, `n` points around it: the
    /// projection of the circle where the rays from the source graze the sphere. Empty when the
    /// source is inside the sphere or a point cannot be projected.
    pub fn sphere_outline(&self, center: &Point3<f64>, radius: f64, n: usize) -> Vec<Point2<f64>> {
        let o = self.center();
        let to_c = center - o;
        let d = to_c.norm();
        if !(radius > 0.0 && d > radius) {
            return Vec::new();
        }
        let w = to_c / d;
        // The grazing circle: radius r sqrt(1 - r^2/d^2), centred r^2/d from the centre toward
        // the source.
        let rc = radius * (1.0 - (radius / d).powi(2)).sqrt();
        let c = center - w * (radius * radius / d);
        let a = if w.x.abs() < 0.9 {
            nalgebra::Vector3::x()
        } else {
            nalgebra::Vector3::y()
        };
        let u = w.cross(&a).normalize();
        let v = w.cross(&u);
        (0..n)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                self.project(&(c + (u * t.cos() + v * t.sin()) * rc))
            })
            .collect::<Result<Vec<_>, _>>()
            .unwrap_or_default()
    }

    /// Pixels per millimetre at the depth of world point `p` (mean of fx and fy over depth).
    pub fn pixels_per_mm_at(&self, p: &Point3<f64>) -> f64 {
        let z = self.to_camera(p).z.max(MIN_DEPTH);
        0.5 * (self.k.fx + self.k.fy) / z
    }

    /// Unit ray direction (world) through pixel `px`.
    pub fn ray(&self, px: &Point2<f64>) -> Vector3<f64> {
        let d = Vector3::new(
            (px.x - self.k.cx) / self.k.fx,
            (px.y - self.k.cy) / self.k.fy,
            1.0,
        );
        (self.r.inverse() * d).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{simulated_views, XrayGeometry};

    #[test]
    fn jacobian_matches_finite_differences() {
        let cams = simulated_views(&XrayGeometry::default(), &Point3::new(3.0, -2.0, 5.0));
        let p = Point3::new(10.0, 4.0, -7.0);
        for cam in &cams {
            let (px, j) = cam.project_with_jacobian(&p).unwrap();
            for k in 0..3 {
                let mut q = p;
                q[k] += 1e-5;
                let d = (cam.project(&q).unwrap() - px) / 1e-5;
                assert!(
                    (d - j.column(k)).norm() < 1e-4,
                    "column {k}: {d} vs {}",
                    j.column(k)
                );
            }
        }
    }

    #[test]
    fn a_spheres_outline_grazes_it() {
        let c = Point3::new(5.0, -3.0, 2.0);
        let cams = simulated_views(&XrayGeometry::default(), &c);
        for cam in &cams {
            let outline = cam.sphere_outline(&c, 26.0, 90);
            assert_eq!(outline.len(), 90);
            // Every outline point's ray passes the centre at the radius, and no point of the
            // sphere projects outside the outline's span.
            let o = cam.center();
            for p in &outline {
                let d = cam.ray(p).normalize();
                let dist = (c - o).cross(&d).norm();
                assert!((dist - 26.0).abs() < 1e-6, "{dist}");
            }
            // Companion: a smaller sphere's outline does not graze the larger one.
            let small = cam.sphere_outline(&c, 20.0, 8);
            let d = cam.ray(&small[0]).normalize();
            assert!(((c - o).cross(&d).norm() - 26.0).abs() > 5.0);
        }
        assert!(cams[0].sphere_outline(&cams[0].center(), 5.0, 8).is_empty());
    }

    #[test]
    fn points_behind_the_source_are_refused() {
        let cams = simulated_views(&XrayGeometry::default(), &Point3::origin());
        let behind = cams[0].center() + (cams[0].center() - Point3::origin());
        assert!(matches!(
            cams[0].project(&behind),
            Err(ProjectionError::BehindCamera { .. })
        ));
    }
}
