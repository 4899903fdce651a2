//! One acetabulum's shape as a deviation field: how far its surface departs from its own sphere,
//! by direction from the sphere's centre, in body axes.
//!
//! Body axes are the frame of the studies and of case files made like them: z along the body's
//! long axis, y antero-posterior (the AP view looks along it), x left-right. A left and a right
//! hip are mirror images; every field is stored as a hip that opens towards -x (a hip opening
//! towards +x is mirrored in x first), so both sides share one prior.

use crate::geom::{centroid, Sphere};
use nalgebra::{Point3, Vector3};

/// Directions of the field's grid: a Fibonacci sphere of this many points (about 5 degrees
/// apart).
pub const GRID_POINTS: usize = 1600;

/// The Gaussian kernel's SD over the angle between directions, degrees: a coarse atlas mesh's
/// vertices (about 8 degrees apart) still cover every direction they span.
pub const KERNEL_DEG: f64 = 4.0;

/// A grid direction is covered by a mesh when its vertices' kernel weights sum to this much.
pub const MIN_WEIGHT: f64 = 0.1;

/// The unit directions of the grid (deterministic).
pub fn grid(n: usize) -> Vec<Vector3<f64>> {
    let golden = std::f64::consts::PI * (1.0 + 5f64.sqrt());
    (0..n)
        .map(|i| {
            let t = (i as f64 + 0.5) / n as f64;
            let phi = (1.0 - 2.0 * t).clamp(-1.0, 1.0).acos();
            let th = golden * (i as f64 + 0.5);
            Vector3::new(th.cos() * phi.sin(), th.sin() * phi.sin(), phi.cos())
        })
        .collect()
}

/// The kernel weight of two unit directions whose dot product is `cos`.
pub fn kernel(cos: f64, sigma_rad: f64) -> f64 {
    let a = cos.clamp(-1.0, 1.0).acos();
    (-(a * a) / (2.0 * sigma_rad * sigma_rad)).exp()
}

/// Dot products below this cannot carry weight worth summing (four kernel SDs).
pub fn kernel_reach(sigma_rad: f64) -> f64 {
    (4.0 * sigma_rad).min(std::f64::consts::PI).cos()
}

/// Whether a surface around `center` opens towards +x (and is mirrored into the prior's frame):
/// the opening points from the surface's centroid to its sphere's centre.
pub fn opens_to_plus_x(vertices: &[Point3<f64>], center: &Point3<f64>) -> bool {
    (center - centroid(vertices)).x > 0.0
}

/// A body-axes direction in the prior's frame (mirrored in x when `mirrored`).
pub fn to_prior_frame(d: Vector3<f64>, mirrored: bool) -> Vector3<f64> {
    if mirrored {
        Vector3::new(-d.x, d.y, d.z)
    } else {
        d
    }
}

/// The relative radial deviation field of a surface with sphere `sphere`: at each grid direction
/// the kernel-weighted mean of (|v - c| - r) / r over the vertices, None where the vertices do not
/// cover it. Also says whether the surface was mirrored.
pub fn deviation_field(vertices: &[Point3<f64>], sphere: &Sphere) -> (Vec<Option<f64>>, bool) {
    let c = sphere.center_point();
    let mirrored = opens_to_plus_x(vertices, &c);
    let g = grid(GRID_POINTS);
    let sigma = KERNEL_DEG.to_radians();
    let reach = kernel_reach(sigma);
    let mut sums = vec![(0.0, 0.0); g.len()];
    for v in vertices {
        let d = v - c;
        let len = d.norm();
        if len <= 1e-9 {
            continue;
        }
        let u = to_prior_frame(d / len, mirrored);
        let dev = (len - sphere.radius) / sphere.radius;
        for (gi, s) in g.iter().zip(sums.iter_mut()) {
            let cos = gi.dot(&u);
            if cos < reach {
                continue;
            }
            let w = kernel(cos, sigma);
            s.0 += w;
            s.1 += w * dev;
        }
    }
    let field = sums
        .into_iter()
        .map(|(w, wd)| (w >= MIN_WEIGHT).then(|| wd / w))
        .collect();
    (field, mirrored)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::fit_sphere;
    use crate::template::hemisphere;

    #[test]
    fn the_grid_is_unit_and_spread_evenly() {
        let g = grid(GRID_POINTS);
        assert!(g.iter().all(|d| (d.norm() - 1.0).abs() < 1e-12));
        let mean: Vector3<f64> = g.iter().sum::<Vector3<f64>>() / g.len() as f64;
        assert!(mean.norm() < 1e-3, "{mean}");
        // Every direction has a grid point within 4 degrees.
        for probe in grid(97) {
            let best = g.iter().map(|d| d.dot(&probe)).fold(-1.0, f64::max);
            assert!(best > 4f64.to_radians().cos(), "{best}");
        }
    }

    /// A hemisphere of radius 25 opening to `x_sign` x, flattened by `flat` along y.
    fn cap(x_sign: f64, flat: f64) -> Vec<Point3<f64>> {
        let m = hemisphere(25.0, 1500);
        // hemisphere() opens to +z; turn it to open to x_sign x.
        m.vertices
            .iter()
            .map(|p| Point3::new(x_sign * p.z, p.y * (1.0 - flat), -x_sign * p.x))
            .collect()
    }

    #[test]
    fn a_flattened_cap_shows_its_flattening_where_it_is_and_both_sides_agree() {
        for x_sign in [-1.0, 1.0] {
            let v = cap(x_sign, 0.08);
            let s = fit_sphere(&v).unwrap();
            let (f, mirrored) = deviation_field(&v, &s);
            assert_eq!(mirrored, x_sign > 0.0);
            let g = grid(GRID_POINTS);
            let at = |dir: Vector3<f64>| {
                let i = (0..g.len())
                    .max_by(|&a, &b| g[a].dot(&dir).total_cmp(&g[b].dot(&dir)))
                    .unwrap();
                f[i]
            };
            // In the prior's frame the cap opens to -x: its walls lie towards +x.
            let front = at(Vector3::new(0.3, 0.95, 0.0)).unwrap();
            let top = at(Vector3::new(0.3, 0.0, 0.95)).unwrap();
            assert!(front < top - 0.03, "front {front} top {top}");
            assert!(at(Vector3::new(-1.0, 0.0, 0.0)).is_none());
        }
    }

    #[test]
    fn a_round_cap_has_no_deviation_and_a_flattened_one_is_told_apart() {
        let round = cap(-1.0, 0.0);
        let (f, _) = deviation_field(&round, &fit_sphere(&round).unwrap());
        let worst = f.iter().flatten().fold(0.0f64, |a, d| a.max(d.abs()));
        assert!(worst < 2e-3, "{worst}");
        let flat = cap(-1.0, 0.08);
        let (f, _) = deviation_field(&flat, &fit_sphere(&flat).unwrap());
        let worst = f.iter().flatten().fold(0.0f64, |a, d| a.max(d.abs()));
        assert!(worst > 0.02, "{worst}");
    }
}
