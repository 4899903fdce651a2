//! The built-in acetabulum phantom: a procedural surface that is deliberately not a hemisphere,
//! used as the default ground truth for the demo and the tests.

use crate::geom::Mesh;
use crate::template::{spherical_cap, Placement, MAX_CAP_VERTICES};
use nalgebra::{Matrix3, Point3, Rotation3, Unit, Vector3};

/// Shape and pose of the phantom. Angles in degrees, lengths in mm.
#[derive(Clone, Debug, PartialEq)]
pub struct PhantomParams {
    /// Sphere radius before the ellipticity is applied.
    pub radius: f64,
    /// Semi-axis factors of the rim ellipse (local x and y); 1.0 each is circular.
    pub ellipticity: [f64; 2],
    /// Polar angle of the rim, < 90 makes it shallower than a hemisphere.
    pub depth_deg: f64,
    /// Acetabular notch: azimuthal width (centred on the inferior rim) and the polar angle where
    /// the cut starts. A notch that would remove every triangle is not cut.
    pub notch_width_deg: f64,
    /// Polar angle where the notch starts.
    pub notch_start_deg: f64,
    /// Fossa: a depression of this depth (mm, away from the centre) with this angular radius,
    /// centred this far from the pole towards the notch.
    pub fossa_depth: f64,
    /// Fossa's angular radius.
    pub fossa_radius_deg: f64,
    /// Fossa's distance from the pole towards the notch.
    pub fossa_offset_deg: f64,
    /// Radiographic anteversion and inclination of the opening axis (Murray's definitions).
    pub anteversion_deg: f64,
    /// Radiographic inclination, degrees.
    pub inclination_deg: f64,
    /// Sphere centre in the world (x lateral, y anterior, z superior).
    pub center: Point3<f64>,
    /// Resolution of the generated surface.
    pub vertices: usize,
}

impl Default for PhantomParams {
    fn default() -> Self {
        PhantomParams {
            radius: 26.0,
            ellipticity: [1.04, 0.97],
            depth_deg: 80.0,
            notch_width_deg: 40.0,
            notch_start_deg: 58.0,
            fossa_depth: 1.5,
            fossa_radius_deg: 25.0,
            fossa_offset_deg: 20.0,
            anteversion_deg: 20.0,
            inclination_deg: 45.0,
            center: Point3::origin(),
            vertices: 3000,
        }
    }
}

/// A generated phantom: the surface and the hemisphere it was built around.
#[derive(Clone, Debug)]
pub struct Phantom {
    /// The surface.
    pub mesh: Mesh,
    /// The undeformed sphere's centre, radius and opening axis.
    pub placement: Placement,
}

/// Opening axis from radiographic anteversion A and inclination I: (cos A sin I, sin A, -cos A cos I)
/// with x lateral, y anterior, z superior.
pub fn radiographic_axis(anteversion_deg: f64, inclination_deg: f64) -> Unit<Vector3<f64>> {
    let (a, i) = (anteversion_deg.to_radians(), inclination_deg.to_radians());
    Unit::new_normalize(Vector3::new(a.cos() * i.sin(), a.sin(), -a.cos() * i.cos()))
}

/// A phantom setting no acetabulum has (see `PhantomParams::validate`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("phantom: {field} = {value}: must be {expected}")]
pub struct PhantomError {
    /// The setting.
    pub field: &'static str,
    /// Its value.
    pub value: String,
    /// What it must be.
    pub expected: &'static str,
}

impl PhantomParams {
    /// Every length and angle finite; the radius and the ellipticity factors > 0; the rim's
    /// polar angle in (0, 180) degrees; the notch 0-360 degrees wide; the fossa's angular radius
    /// >= 0; at most `MAX_CAP_VERTICES` vertices.
    pub fn validate(&self) -> Result<(), PhantomError> {
        let bad = |field, value: String, expected| PhantomError {
            field,
            value: crate::io::shown(&value),
            expected,
        };
        let finite = [
            ("fossa_depth", self.fossa_depth),
            ("fossa_offset_deg", self.fossa_offset_deg),
            ("notch_start_deg", self.notch_start_deg),
            ("anteversion_deg", self.anteversion_deg),
            ("inclination_deg", self.inclination_deg),
            ("center.x", self.center.x),
            ("center.y", self.center.y),
            ("center.z", self.center.z),
        ];
        if let Some((field, v)) = finite.iter().find(|(_, v)| !v.is_finite()) {
            return Err(bad(field, v.to_string(), "finite"));
        }
        for (field, v) in [
            ("radius", self.radius),
            ("ellipticity[0]", self.ellipticity[0]),
            ("ellipticity[1]", self.ellipticity[1]),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(field, v.to_string(), "finite and > 0"));
            }
        }
        if !(self.depth_deg > 0.0 && self.depth_deg < 180.0) {
            return Err(bad(
                "depth_deg",
                self.depth_deg.to_string(),
                "in (0, 180) degrees",
            ));
        }
        if !(0.0..=360.0).contains(&self.notch_width_deg) {
            return Err(bad(
                "notch_width_deg",
                self.notch_width_deg.to_string(),
                "0 to 360 degrees",
            ));
        }
        if !(self.fossa_radius_deg.is_finite() && self.fossa_radius_deg >= 0.0) {
            return Err(bad(
                "fossa_radius_deg",
                self.fossa_radius_deg.to_string(),
                "finite and >= 0",
            ));
        }
        if self.vertices > MAX_CAP_VERTICES {
            return Err(bad(
                "vertices",
                self.vertices.to_string(),
                "at most 1,000,000",
            ));
        }
        Ok(())
    }
}

/// `phantom` after `PhantomParams::validate`: the checked way to build a phantom from settings
/// that come from outside.
pub fn try_phantom(p: &PhantomParams) -> Result<Phantom, PhantomError> {
    p.validate()?;
    Ok(phantom(p))
}

/// Generate the phantom. The local frame has the opening along +z and the notch at local -y;
/// the pose maps local +y to the superior direction within the rim plane. The settings are
/// taken as they are (the defaults, or ones `PhantomParams::validate` passes); `try_phantom`
/// checks them first.
pub fn phantom(p: &PhantomParams) -> Phantom {
    let cap = spherical_cap(1.0, p.vertices, p.depth_deg.to_radians());
    let fossa_dir = {
        let o = p.fossa_offset_deg.to_radians();
        Vector3::new(0.0, -o.sin(), -o.cos())
    };
    let fossa_r = p.fossa_radius_deg.to_radians();
    let vertices: Vec<Point3<f64>> = cap
        .vertices
        .iter()
        .map(|v| {
            let u = v.coords; // unit sphere point
            let ang = u.dot(&fossa_dir).clamp(-1.0, 1.0).acos();
            let bump = if ang < fossa_r {
                0.5 * (1.0 + (std::f64::consts::PI * ang / fossa_r).cos())
            } else {
                0.0
            };
            let r = p.radius + p.fossa_depth * bump;
            Point3::new(
                u.x * r * p.ellipticity[0],
                u.y * r * p.ellipticity[1],
                u.z * r,
            )
        })
        .collect();
    // Cut the notch: drop triangles whose centroid lies in the inferior wedge below the start angle.
    let half = 0.5 * p.notch_width_deg.to_radians();
    let start = p.notch_start_deg.to_radians();
    let keep: Vec<usize> = (0..cap.triangles.len())
        .filter(|&t| {
            let c = cap.triangles[t]
                .iter()
                .map(|&i| cap.vertices[i as usize].coords)
                .sum::<Vector3<f64>>()
                / 3.0;
            let polar = (-c.z / c.norm()).clamp(-1.0, 1.0).acos();
            let az = c.y.atan2(c.x); // inferior is -pi/2
            let off = (az + std::f64::consts::FRAC_PI_2 + std::f64::consts::PI)
                .rem_euclid(2.0 * std::f64::consts::PI)
                - std::f64::consts::PI;
            !(polar > start && off.abs() < half)
        })
        .collect();
    // A notch so wide and deep that it would take the whole cap is not cut.
    let whole = cap.with_vertices(vertices);
    let local = whole.submesh(&keep).unwrap_or(whole);
    let axis = radiographic_axis(p.anteversion_deg, p.inclination_deg);
    let superior = Vector3::z() - axis.into_inner() * axis.z;
    let ey = superior.try_normalize(1e-9).unwrap_or_else(Vector3::y);
    let ex = ey.cross(&axis);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[ex, ey, axis.into_inner()]));
    let mesh = local.transformed(1.0, &rot, &p.center.coords);
    Phantom {
        mesh,
        placement: Placement {
            center: p.center,
            radius: p.radius,
            axis,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_no_acetabulum_has_are_named() {
        assert!(try_phantom(&PhantomParams::default()).is_ok());
        let d = PhantomParams::default();
        let cases = [
            (
                "radius",
                PhantomParams {
                    radius: 0.0,
                    ..d.clone()
                },
            ),
            (
                "radius",
                PhantomParams {
                    radius: f64::NAN,
                    ..d.clone()
                },
            ),
            (
                "ellipticity[0]",
                PhantomParams {
                    ellipticity: [0.0, 1.0],
                    ..d.clone()
                },
            ),
            (
                "depth_deg",
                PhantomParams {
                    depth_deg: 360.0,
                    ..d.clone()
                },
            ),
            (
                "notch_width_deg",
                PhantomParams {
                    notch_width_deg: -1.0,
                    ..d.clone()
                },
            ),
            (
                "fossa_depth",
                PhantomParams {
                    fossa_depth: f64::NAN,
                    ..d.clone()
                },
            ),
            (
                "fossa_radius_deg",
                PhantomParams {
                    fossa_radius_deg: -5.0,
                    ..d.clone()
                },
            ),
            (
                "vertices",
                PhantomParams {
                    vertices: usize::MAX,
                    ..d.clone()
                },
            ),
            (
                "center.x",
                PhantomParams {
                    center: Point3::new(f64::INFINITY, 0.0, 0.0),
                    ..d.clone()
                },
            ),
        ];
        for (field, p) in cases {
            assert_eq!(try_phantom(&p).err().map(|e| e.field), Some(field));
        }
        // Companion: a spherical phantom without notch or fossa is a valid one.
        let plain = PhantomParams {
            ellipticity: [1.0, 1.0],
            notch_width_deg: 0.0,
            fossa_depth: 0.0,
            fossa_radius_deg: 0.0,
            ..d
        };
        assert!(try_phantom(&plain).is_ok());
    }

    #[test]
    fn phantom_is_not_a_hemisphere() {
        let p = PhantomParams::default();
        let ph = phantom(&p);
        let d: Vec<f64> = ph
            .mesh
            .vertices
            .iter()
            .map(|v| (v - p.center).norm())
            .collect();
        let max = d.iter().cloned().fold(0.0, f64::max);
        let min = d.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(max > 26.9 && min < 25.5, "radii {min}..{max}");
        // Shallower than a hemisphere: no point beyond the rim plane, the rim well inside it.
        let depth_min = ph
            .mesh
            .vertices
            .iter()
            .map(|v| (v - p.center).dot(&ph.placement.axis))
            .fold(f64::INFINITY, f64::min);
        let depth_max = ph
            .mesh
            .vertices
            .iter()
            .map(|v| (v - p.center).dot(&ph.placement.axis))
            .fold(-1e9, f64::max);
        assert!(depth_max < -2.0, "rim offset {depth_max}");
        assert!(depth_min < -25.0);
        // The notch opens a gap: the rim boundary dips towards the pole.
        let boundary = ph.mesh.boundary_edges();
        let dips = boundary
            .iter()
            .filter(|[i, _]| {
                (ph.mesh.vertices[*i as usize] - p.center).dot(&ph.placement.axis) < -10.0
            })
            .count();
        assert!(dips > 3, "notch edges {dips}");
    }

    /// A notch that would take every triangle leaves the cap whole instead of panicking; a wide
    /// notch that leaves some keeps fewer triangles than the default (the companion).
    #[test]
    fn a_notch_over_the_whole_cap_is_not_cut() {
        let base = phantom(&PhantomParams::default()).mesh.triangles.len();
        let all = phantom(&PhantomParams {
            notch_width_deg: 400.0,
            notch_start_deg: -1.0,
            ..Default::default()
        });
        let uncut = phantom(&PhantomParams {
            notch_width_deg: 0.0,
            ..Default::default()
        });
        assert_eq!(all.mesh.triangles.len(), uncut.mesh.triangles.len());
        let wide = phantom(&PhantomParams {
            notch_width_deg: 120.0,
            ..Default::default()
        });
        assert!(wide.mesh.triangles.len() < base && base < uncut.mesh.triangles.len());
    }

    #[test]
    fn axis_follows_radiographic_angles() {
        let a = radiographic_axis(20.0, 45.0);
        assert!(a.x > 0.0 && a.y > 0.0 && a.z < 0.0);
        let coronal = Vector3::new(a.x, 0.0, a.z);
        let incl = coronal.x.atan2(-coronal.z).to_degrees();
        assert!((incl - 45.0).abs() < 1e-9);
        assert!((a.y.asin().to_degrees() - 20.0).abs() < 1e-9);
    }
}
