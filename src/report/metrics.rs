//! Surface distances: points spread evenly over one surface, true closest points on the other's
//! triangles (parry3d's triangle-mesh point query), and summary statistics.

use crate::geom::Mesh;
use crate::geom::{mean_sd, quantile_sorted};
use nalgebra::Point3;
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::TriMesh;
use rand::{RngExt, SeedableRng};

/// Mean, SD and 95th percentile of a set of distances (mm).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct DistanceStats {
    /// Mean, mm.
    pub mean: f64,
    /// SD (dividing by n), mm.
    pub sd: f64,
    /// 95th percentile (nearest rank), mm.
    pub p95: f64,
    /// Largest, mm.
    pub max: f64,
    /// How many distances.
    pub count: usize,
}

impl DistanceStats {
    /// The statistics of the distances `d` (all zero for none).
    pub fn from(d: &[f64]) -> DistanceStats {
        if d.is_empty() {
            return DistanceStats::default();
        }
        let (mean, sd) = mean_sd(d, false);
        let mut s = d.to_vec();
        s.sort_by(f64::total_cmp);
        let p95 = quantile_sorted(&s, 0.95);
        DistanceStats {
            mean,
            sd,
            p95,
            max: s[s.len() - 1],
            count: d.len(),
        }
    }
}

/// Closest-point queries against a mesh's triangles.
pub struct SurfaceQuery {
    shape: TriMesh,
}

impl SurfaceQuery {
    /// Closest-point queries against `mesh` (None for a mesh parry cannot take).
    pub fn new(mesh: &Mesh) -> Option<SurfaceQuery> {
        let v: Vec<PVec> = mesh
            .vertices
            .iter()
            .map(|p| PVec::new(p.x, p.y, p.z))
            .collect();
        TriMesh::new(v, mesh.triangles.clone())
            .ok()
            .map(|shape| SurfaceQuery { shape })
    }

    /// Distance from p to the closest point on the surface.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        (self.closest_point(p) - p).norm()
    }

    /// The closest point on the surface's triangles.
    pub fn closest_point(&self, p: &Point3<f64>) -> Point3<f64> {
        let proj = self
            .shape
            .project_local_point(PVec::new(p.x, p.y, p.z), false);
        Point3::new(proj.point.x, proj.point.y, proj.point.z)
    }
}

/// `count` points spread evenly (area-weighted, seeded) over the mesh surface.
pub fn surface_samples(mesh: &Mesh, count: usize, seed: u64) -> Vec<Point3<f64>> {
    let areas: Vec<f64> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            0.5 * (b - a).cross(&(c - a)).norm()
        })
        .collect();
    let total: f64 = areas.iter().sum();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(count);
    // Stratified: each triangle gets its expected share; the fractional part is drawn.
    for (t, a) in mesh.triangles.iter().zip(&areas) {
        let expect = count as f64 * a / total.max(1e-300);
        let mut k = expect.floor() as usize;
        if rng.random::<f64>() < expect - k as f64 {
            k += 1;
        }
        let [p0, p1, p2] = t.map(|i| mesh.vertices[i as usize]);
        for _ in 0..k {
            let (mut u, mut v) = (rng.random::<f64>(), rng.random::<f64>());
            if u + v > 1.0 {
                u = 1.0 - u;
                v = 1.0 - v;
            }
            out.push(p0 + (p1 - p0) * u + (p2 - p0) * v);
        }
    }
    out
}

/// Distances from `points` to the surface of `to`.
pub fn surface_distance(points: &[Point3<f64>], to: &Mesh) -> Vec<f64> {
    match SurfaceQuery::new(to) {
        Some(q) => points.iter().map(|p| q.distance(p)).collect(),
        None => vec![f64::INFINITY; points.len()],
    }
}

/// Distances from the vertices of `from` to the surface `to`, leaving out vertices whose closest
/// point lies on the border of `to` (within 1e-6 mm of a boundary edge): where `to` simply ends
/// (a horseshoe's notch and fossa) the distance says nothing about the fit.
pub fn interior_distance(from: &Mesh, to: &Mesh) -> Vec<f64> {
    InteriorQuery::new(to).map_or_else(Vec::new, |q| q.distances(from))
}

/// `interior_distance` to one surface, prepared once for many meshes.
pub struct InteriorQuery {
    query: SurfaceQuery,
    border: Vec<(Point3<f64>, Point3<f64>)>,
}

impl InteriorQuery {
    /// Distance queries to `to`'s triangles (None for a mesh parry cannot take).
    pub fn new(to: &Mesh) -> Option<InteriorQuery> {
        let query = SurfaceQuery::new(to)?;
        let border = to
            .boundary_edges()
            .iter()
            .map(|[a, b]| (to.vertices[*a as usize], to.vertices[*b as usize]))
            .collect();
        Some(InteriorQuery { query, border })
    }

    /// From each vertex of `from` to the surface, mm, leaving out the vertices whose closest
    /// point lies on the surface's border.
    pub fn distances(&self, from: &Mesh) -> Vec<f64> {
        self.per_vertex(from)
            .into_iter()
            .filter(|d| !d.is_nan())
            .collect()
    }

    /// From each vertex of `from` to the surface, mm, in vertex order; NaN where the closest
    /// point lies on the surface's border (no surface under the vertex: the distance there is to
    /// the edge, not an error of the shape).
    pub fn per_vertex(&self, from: &Mesh) -> Vec<f64> {
        from.vertices
            .iter()
            .map(|p| {
                let c = self.query.closest_point(p);
                let on_border = self.border.iter().any(|(a, b)| {
                    let ab = b - a;
                    let u = if ab.norm_squared() > 0.0 {
                        ((c - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    (a + ab * u - c).norm() < 1e-6
                });
                if on_border {
                    f64::NAN
                } else {
                    (c - p).norm()
                }
            })
            .collect()
    }
}

/// Colour of a vertex with no error to show (NaN): neutral grey.
pub const NO_ERROR_COLOR: [u8; 3] = [160, 160, 160];

/// Per-vertex colours for an error map: blue (0 mm) through green to red (>= `max_mm`); grey
/// (`NO_ERROR_COLOR`) where the error is NaN.
pub fn error_colors(errors: &[f64], max_mm: f64) -> Vec<[u8; 3]> {
    errors
        .iter()
        .map(|e| {
            if e.is_nan() {
                return NO_ERROR_COLOR;
            }
            let u = (e / max_mm.max(1e-9)).clamp(0.0, 1.0);
            let (r, g, b) = if u < 0.5 {
                (0.0, 2.0 * u, 1.0 - 2.0 * u)
            } else {
                (2.0 * u - 1.0, 2.0 - 2.0 * u, 0.0)
            };
            [(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::template::hemisphere;

    #[test]
    fn distance_to_a_concentric_sphere_is_the_radius_gap() {
        let inner = hemisphere(20.0, 3000);
        let outer = hemisphere(22.0, 3000);
        let pts = surface_samples(&inner, 2000, 1);
        assert!((1900..2100).contains(&pts.len()));
        let d = surface_distance(&pts, &outer);
        let s = DistanceStats::from(&d);
        assert!((s.mean - 2.0).abs() < 0.05, "mean {}", s.mean);
        // Closest point on triangles, not nearest vertex: well below the vertex spacing.
        let same = DistanceStats::from(&surface_distance(&pts, &inner));
        assert!(same.mean < 0.02, "self distance {}", same.mean);
    }

    #[test]
    fn stats_are_right_on_known_numbers() {
        let d: Vec<f64> = (1..=100).map(|x| x as f64).collect();
        let s = DistanceStats::from(&d);
        assert_eq!(s.mean, 50.5);
        assert_eq!(s.p95, 95.0);
        assert_eq!(s.max, 100.0);
    }
}
