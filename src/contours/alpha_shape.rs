//! Alpha-shape boundary of projected vertices (spade Delaunay), as one ordered closed polyline of
//! model vertex indices.

use crate::geom::signed_area;
use crate::geom::Mesh;
use crate::views::{Camera, ProjectionError};
use nalgebra::Point2;
use spade::{DelaunayTriangulation, HasPosition, Triangulation};

/// Why a contour could not be formed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ContourError {
    /// A vertex cannot be projected.
    #[error("vertex {vertex} cannot be projected: {source}")]
    Projection {
        /// The vertex.
        vertex: usize,
        /// Why.
        source: ProjectionError,
    },
    /// Too few distinct projected points for an outline.
    #[error("too few distinct projected points ({count}) for a contour")]
    TooFewPoints {
        /// How many.
        count: usize,
    },
    /// No outline: the triangulation failed or found no simple boundary (the reason).
    #[error("the Delaunay triangulation failed: {0}")]
    Delaunay(String),
}

/// The model contour in one view.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelContour {
    /// Model vertex index of each contour point, in order around the outline.
    pub vertex_ids: Vec<u32>,
    /// Projected positions (pixels) of those vertices; positive signed area.
    pub points: Vec<Point2<f64>>,
}

#[derive(Clone, Copy, Debug)]
struct Site {
    p: spade::Point2<f64>,
    id: u32,
}

impl HasPosition for Site {
    type Scalar = f64;
    fn position(&self) -> spade::Point2<f64> {
        self.p
    }
}

/// Default alpha (circumradius bound, pixels): 1.2 times the 95th percentile of projected edge lengths.
pub fn default_alpha(mesh: &Mesh, projected: &[Point2<f64>]) -> f64 {
    alpha_from_edges(&mesh.edges(), projected)
}

/// `default_alpha` with the mesh's edges given (they depend on its triangles only).
fn alpha_from_edges(edges: &[[u32; 2]], projected: &[Point2<f64>]) -> f64 {
    let mut l: Vec<f64> = edges
        .iter()
        .map(|[a, b]| (projected[*a as usize] - projected[*b as usize]).norm())
        .collect();
    if l.is_empty() {
        return 1.0;
    }
    let k = ((l.len() - 1) as f64 * 0.95) as usize;
    let (_, kth, _) = l.select_nth_unstable_by(k, f64::total_cmp);
    1.2 * kth.max(1e-9)
}

/// Project the mesh into the camera and take the alpha-shape outline (alpha from `default_alpha`
/// unless given).
pub fn model_contour(
    mesh: &Mesh,
    cam: &Camera,
    alpha: Option<f64>,
) -> Result<ModelContour, ContourError> {
    let alpha = match alpha {
        Some(a) => Alpha::Given(a),
        None => Alpha::FromEdges(&mesh.edges()),
    };
    contour_in_view(mesh, cam, alpha)
}

/// `model_contour` with the default alpha in every view, the mesh's edges listed once.
pub fn model_contours(mesh: &Mesh, cams: &[Camera]) -> Vec<Result<ModelContour, ContourError>> {
    with_edges(mesh, |edges| {
        cams.iter()
            .map(|c| contour_in_view(mesh, c, Alpha::FromEdges(edges)))
            .collect()
    })
}

/// Triangles and the edges they make.
type Topology = (Vec<[u32; 3]>, Vec<[u32; 2]>);

thread_local! {
    /// The triangles of the last mesh whose contours this thread took, and their edges: a
    /// reconstruction takes the contours of one topology (the template's, deformed) dozens of
    /// times, and listing the edges means sorting every triangle side.
    static EDGES: std::cell::RefCell<Topology> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// `f` of `mesh.edges()`, listed again only when the triangles differ from the last call's on
/// this thread (compared in full, so the edges are always the mesh's own).
fn with_edges<R>(mesh: &Mesh, f: impl FnOnce(&[[u32; 2]]) -> R) -> R {
    EDGES.with(|memo| {
        let Ok(mut memo) = memo.try_borrow_mut() else {
            // Re-entered from within `f` (it is not, today): no memo.
            return f(&mesh.edges());
        };
        // Invariant: memo.1 lists the edges of memo.0 (at first, of no triangles: none).
        if memo.0 != mesh.triangles {
            memo.1 = mesh.edges();
            memo.0.clone_from(&mesh.triangles);
        }
        f(&memo.1)
    })
}

enum Alpha<'a> {
    Given(f64),
    FromEdges(&'a [[u32; 2]]),
}

fn contour_in_view(
    mesh: &Mesh,
    cam: &Camera,
    alpha: Alpha<'_>,
) -> Result<ModelContour, ContourError> {
    let mut projected = Vec::with_capacity(mesh.vertex_count());
    for (vertex, v) in mesh.vertices.iter().enumerate() {
        projected.push(
            cam.project(v)
                .map_err(|source| ContourError::Projection { vertex, source })?,
        );
    }
    let alpha = match alpha {
        Alpha::Given(a) => a,
        Alpha::FromEdges(e) => alpha_from_edges(e, &projected),
    };
    alpha_shape_contour(&projected, alpha)
}

/// Alpha shape of `points`: Delaunay triangles with circumradius <= alpha are kept and their
/// outline is traced. If the outline is not one simple loop (holes, pinches, islands), alpha is
/// raised by half until it is; the convex hull (alpha -> infinity) always is.
pub fn alpha_shape_contour(
    points: &[Point2<f64>],
    alpha: f64,
) -> Result<ModelContour, ContourError> {
    let sites: Vec<Site> = points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.x.is_finite() && p.y.is_finite())
        .map(|(i, p)| Site {
            p: spade::Point2::new(p.x, p.y),
            id: i as u32,
        })
        .collect();
    let sites = in_bulk_load_order(sites);
    let tri = DelaunayTriangulation::<Site>::bulk_load(sites)
        .map_err(|e| ContourError::Delaunay(format!("{e:?}")))?;
    if tri.num_inner_faces() == 0 {
        return Err(ContourError::TooFewPoints {
            count: tri.num_vertices(),
        });
    }
    let mut alpha = alpha.max(1e-9);
    for _ in 0..60 {
        if let Some(ids) = trace_single_loop(&tri, alpha) {
            let mut pts: Vec<Point2<f64>> = ids.iter().map(|&i| points[i as usize]).collect();
            let mut ids = ids;
            if signed_area(&pts) < 0.0 {
                pts.reverse();
                ids.reverse();
            }
            return Ok(ModelContour {
                vertex_ids: ids,
                points: pts,
            });
        }
        alpha *= 1.5;
    }
    Err(ContourError::Delaunay("no simple outline found".into()))
}

/// spade's bulk load (2.15) first sorts its input by (distance to the input's centroid,
/// descending; x; y), recomputing that key at every comparison of a general-purpose sort, and
/// inserts the points nearest first; the triangulation's vertex and face numbers, and so where
/// the traced outline starts, follow that order. Here the same order is found with each key
/// computed once, so spade's sort meets a sorted input and only checks it. The input is given
/// back as it came whenever that order might not be spade's own: two sites with the same key
/// (the same position), or an order that the centroid of the sorted list (summed in another
/// order, so perhaps a rounding apart) would not keep. Either way the triangulation is the one
/// spade builds from `sites` (test: `presorting_keeps_spades_triangulation`).
fn in_bulk_load_order(sites: Vec<Site>) -> Vec<Site> {
    if sites.len() < 3 {
        return sites;
    }
    // spade's centroid: the positions summed in list order, times 1 / len.
    let centroid = |s: &[Site]| {
        let (mut x, mut y) = (0.0, 0.0);
        for v in s {
            x += v.p.x;
            y += v.p.y;
        }
        let f = 1.0 / s.len() as f64;
        (x * f, y * f)
    };
    let dist2 = |c: (f64, f64), p: spade::Point2<f64>| {
        let (dx, dy) = (c.0 - p.x, c.1 - p.y);
        dx * dx + dy * dy
    };
    // spade's order: farther first, then x, then y (its pop takes the nearest first).
    let before = |da: f64, a: &Site, db: f64, b: &Site| {
        db.partial_cmp(&da)
            .and_then(|o| Some(o.then(a.p.x.partial_cmp(&b.p.x)?)))
            .and_then(|o| Some(o.then(a.p.y.partial_cmp(&b.p.y)?)))
    };
    let strictly_sorted = |s: &[Site], c: (f64, f64)| {
        s.windows(2).all(|w| {
            before(dist2(c, w[0].p), &w[0], dist2(c, w[1].p), &w[1])
                == Some(std::cmp::Ordering::Less)
        })
    };
    let c0 = centroid(&sites);
    // Sort keys as integers in f64::total_cmp's order (the distance descending); the checks
    // below use spade's comparison, under which -0 and +0 are one value.
    let ordered = |v: f64| {
        let b = v.to_bits();
        if b >> 63 == 1 {
            !b
        } else {
            b | 1 << 63
        }
    };
    let mut keys: Vec<(u64, u64, u64, u32)> = Vec::with_capacity(sites.len());
    for (i, s) in sites.iter().enumerate() {
        let d = dist2(c0, s.p);
        if !d.is_finite() {
            return sites;
        }
        keys.push((!ordered(d), ordered(s.p.x), ordered(s.p.y), i as u32));
    }
    keys.sort_unstable();
    let sorted: Vec<Site> = keys.iter().map(|k| sites[k.3 as usize]).collect();
    if strictly_sorted(&sorted, c0) && strictly_sorted(&sorted, centroid(&sorted)) {
        sorted
    } else {
        sites
    }
}

/// Circumradius of a triangle.
fn circumradius(a: spade::Point2<f64>, b: spade::Point2<f64>, c: spade::Point2<f64>) -> f64 {
    let (ab, bc, ca) = (dist(a, b), dist(b, c), dist(c, a));
    let cross = ((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)).abs();
    if cross <= 0.0 {
        f64::INFINITY
    } else {
        ab * bc * ca / (2.0 * cross)
    }
}

fn dist(a: spade::Point2<f64>, b: spade::Point2<f64>) -> f64 {
    ((a.x - b.x).powi(2) + (a.y - b.y).powi(2)).sqrt()
}

/// Trace the boundary of the kept faces. Holes (clockwise loops, e.g. the fossa of a
/// horseshoe-shaped surface) are ignored; the outline is the largest counter-clockwise loop.
/// `None` when a vertex is pinched (two outgoing boundary edges) or when that loop holds less
/// than 95 % of the outer area (the shape fell apart into islands): alpha must grow.
fn trace_single_loop(tri: &DelaunayTriangulation<Site>, alpha: f64) -> Option<Vec<u32>> {
    let kept: Vec<bool> = tri
        .all_faces()
        .map(|f| match f.as_inner() {
            Some(inner) => {
                let [a, b, c] = inner.vertices().map(|v| v.position());
                circumradius(a, b, c) <= alpha
            }
            None => false,
        })
        .collect();
    // Directed boundary edges (kept face on the left): from -> to, by spade vertex index.
    let mut next = vec![usize::MAX; tri.num_vertices()];
    let mut starts = Vec::new();
    for f in tri.inner_faces() {
        if !kept[f.fix().index()] {
            continue;
        }
        for e in f.adjacent_edges() {
            let other = e.rev().face().fix().index();
            if !kept[other] {
                let (from, to) = (e.from().fix().index(), e.to().fix().index());
                if next[from] != usize::MAX {
                    return None; // a pinch vertex: two outgoing boundary edges
                }
                next[from] = to;
                starts.push(from);
            }
        }
    }
    let pos = |v: usize| {
        let p = tri
            .vertex(spade::handles::FixedVertexHandle::from_index(v))
            .position();
        Point2::new(p.x, p.y)
    };
    let mut visited = vec![false; tri.num_vertices()];
    let mut best: Option<(f64, Vec<usize>)> = None;
    let mut outer_total = 0.0;
    for &s in &starts {
        if visited[s] {
            continue;
        }
        let mut lp = Vec::new();
        let mut v = s;
        while !visited[v] {
            visited[v] = true;
            lp.push(v);
            v = next[v];
            if v == usize::MAX {
                return None;
            }
        }
        if v != s || lp.len() < 3 {
            return None;
        }
        let area = signed_area(&lp.iter().map(|&v| pos(v)).collect::<Vec<_>>());
        if area > 0.0 {
            outer_total += area;
            if best.as_ref().is_none_or(|b| area > b.0) {
                best = Some((area, lp));
            }
        }
    }
    let (area, lp) = best?;
    if area < 0.95 * outer_total {
        return None;
    }
    Some(
        lp.iter()
            .map(|&v| {
                tri.vertex(spade::handles::FixedVertexHandle::from_index(v))
                    .data()
                    .id
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alpha_shape_of_a_filled_square_is_its_outline() {
        let mut pts = Vec::new();
        for i in 0..=10 {
            for j in 0..=10 {
                pts.push(Point2::new(i as f64, j as f64));
            }
        }
        let c = alpha_shape_contour(&pts, 1.0).unwrap();
        assert_eq!(c.points.len(), 40);
        assert!(signed_area(&c.points) > 99.0);
        for p in &c.points {
            assert!(p.x == 0.0 || p.x == 10.0 || p.y == 0.0 || p.y == 10.0);
        }
    }

    #[test]
    fn alpha_shape_follows_a_concavity_that_the_hull_would_bridge() {
        // An L shape: the hull would cut the inner corner at (5, 5).
        let mut pts = Vec::new();
        for i in 0..=10 {
            for j in 0..=10 {
                if i <= 5 || j <= 5 {
                    pts.push(Point2::new(i as f64, j as f64));
                }
            }
        }
        let c = alpha_shape_contour(&pts, 1.0).unwrap();
        // At most the one small triangle at the inner corner (area 0.5) is bridged.
        let a = signed_area(&c.points);
        assert!((75.0..=75.5 + 1e-9).contains(&a), "area {a}");
        let hull = alpha_shape_contour(&pts, 1e9).unwrap();
        assert!(signed_area(&hull.points) > 85.0);
    }

    #[test]
    fn a_hole_is_left_out_and_the_outline_kept_tight() {
        // A 20 x 20 grid with a 10 x 10 hole in the middle (a horseshoe's fossa seen en face).
        let mut pts = Vec::new();
        for i in 0..=20 {
            for j in 0..=20 {
                if !((6..=14).contains(&i) && (6..=14).contains(&j)) {
                    pts.push(Point2::new(i as f64, j as f64));
                }
            }
        }
        let c = alpha_shape_contour(&pts, 1.0).unwrap();
        assert_eq!(c.points.len(), 80, "the outer square's 80 boundary points");
        assert!((signed_area(&c.points) - 400.0).abs() < 1e-9);
    }

    /// Vertices (position, id) in handle order and faces (vertex handles) of a triangulation.
    type Fingerprint = (Vec<(f64, f64, u32)>, Vec<[usize; 3]>);

    fn fingerprint(tri: &DelaunayTriangulation<Site>) -> Fingerprint {
        let v = tri
            .vertices()
            .map(|v| (v.position().x, v.position().y, v.data().id))
            .collect();
        let f = tri
            .inner_faces()
            .map(|f| f.vertices().map(|v| v.fix().index()))
            .collect();
        (v, f)
    }

    fn sites_of(points: &[(f64, f64)]) -> Vec<Site> {
        points
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| Site {
                p: spade::Point2::new(x, y),
                id: i as u32,
            })
            .collect()
    }

    fn both_ways(sites: Vec<Site>) -> (Fingerprint, Fingerprint) {
        let plain = DelaunayTriangulation::<Site>::bulk_load(sites.clone()).unwrap();
        let pre = DelaunayTriangulation::<Site>::bulk_load(in_bulk_load_order(sites)).unwrap();
        (fingerprint(&plain), fingerprint(&pre))
    }

    /// Point sets like the model's: random clouds, a hemisphere's rings seen along and across
    /// its axis (many equal distances to the centroid, told apart by x and y), a grid, and
    /// points a rounding apart.
    fn point_sets() -> Vec<Vec<(f64, f64)>> {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut sets = Vec::new();
        for n in [3, 4, 10, 100, 2000] {
            sets.push(
                (0..n)
                    .map(|_| (rng.random_range(0.0..800.0), rng.random_range(-50.0..300.0)))
                    .collect(),
            );
        }
        for tilt in [0.0f64, 0.3, 1.2] {
            let mut pts = Vec::new();
            for ring in 0..=20 {
                let polar = ring as f64 / 20.0 * std::f64::consts::FRAC_PI_2;
                let count = (ring * 6).max(1);
                for k in 0..count {
                    let az = k as f64 / count as f64 * std::f64::consts::TAU;
                    let (x, y, z) = (polar.sin() * az.cos(), polar.sin() * az.sin(), polar.cos());
                    let (y, _z) = (
                        y * tilt.cos() - z * tilt.sin(),
                        y * tilt.sin() + z * tilt.cos(),
                    );
                    pts.push((512.0 + 100.0 * x, 400.0 + 100.0 * y));
                }
            }
            sets.push(pts);
        }
        sets.push(
            (0..30)
                .flat_map(|i| (0..30).map(move |j| (i as f64, j as f64)))
                .collect(),
        );
        sets.push(
            (0..200)
                .map(|i| (1.0 + i as f64 * f64::EPSILON, 1.0 + (i % 7) as f64))
                .collect(),
        );
        sets
    }

    #[test]
    fn presorting_keeps_spades_triangulation() {
        let mut presorted = 0;
        for (k, pts) in point_sets().into_iter().enumerate() {
            let sites = sites_of(&pts);
            let moved = in_bulk_load_order(sites.clone());
            if moved.iter().zip(&sites).any(|(a, b)| a.id != b.id) {
                presorted += 1;
            }
            let (plain, pre) = both_ways(sites);
            assert_eq!(plain, pre, "point set {k}");
            let alpha = 1.0e9;
            assert_eq!(
                alpha_shape_contour(
                    &pts.iter()
                        .map(|&(x, y)| Point2::new(x, y))
                        .collect::<Vec<_>>(),
                    alpha
                )
                .unwrap(),
                {
                    let tri = DelaunayTriangulation::<Site>::bulk_load(sites_of(&pts)).unwrap();
                    let ids = trace_single_loop(&tri, alpha).unwrap();
                    let mut pts: Vec<Point2<f64>> = ids
                        .iter()
                        .map(|&i| Point2::new(pts[i as usize].0, pts[i as usize].1))
                        .collect();
                    let mut ids = ids;
                    if signed_area(&pts) < 0.0 {
                        pts.reverse();
                        ids.reverse();
                    }
                    ModelContour {
                        vertex_ids: ids,
                        points: pts,
                    }
                },
                "point set {k}"
            );
        }
        // Every set but the three smallest (which may come sorted) went the presorted way.
        assert!(presorted >= 7, "{presorted} of 10 sets presorted");
    }

    #[test]
    fn an_order_that_matters_is_left_to_spade() {
        // Two sites at one position: which of them the triangulation keeps depends on the
        // order, and the fingerprint tells the two orders apart...
        let mut pts: Vec<(f64, f64)> = point_sets().swap_remove(3);
        pts.push(pts[17]);
        let sites = sites_of(&pts);
        let mut swapped = sites.clone();
        let last = swapped.len() - 1;
        swapped.swap(17, last);
        let a = fingerprint(&DelaunayTriangulation::<Site>::bulk_load(sites.clone()).unwrap());
        let b = fingerprint(&DelaunayTriangulation::<Site>::bulk_load(swapped).unwrap());
        assert_ne!(a, b, "the comparison sees a different order");
        // ... so the presort gives such an input back untouched.
        let kept = in_bulk_load_order(sites.clone());
        assert!(kept.iter().zip(&sites).all(|(x, y)| x.id == y.id));
        let (plain, pre) = both_ways(sites);
        assert_eq!(plain, pre);
    }

    #[test]
    fn the_edges_are_always_the_meshs_own() {
        let grid = |flip: bool| {
            let mut m = Mesh::default();
            for i in 0..6 {
                for j in 0..6 {
                    m.vertices
                        .push(nalgebra::Point3::new(i as f64, j as f64, 0.0));
                }
            }
            for i in 0..5u32 {
                for j in 0..5u32 {
                    let (a, b, c, d) = (
                        i * 6 + j,
                        i * 6 + j + 1,
                        (i + 1) * 6 + j,
                        (i + 1) * 6 + j + 1,
                    );
                    m.triangles.extend(if flip {
                        [[a, c, d], [a, d, b]]
                    } else {
                        [[a, c, b], [b, c, d]]
                    });
                }
            }
            m
        };
        let (a, b) = (grid(false), grid(true));
        // The two meshes share their vertices but not their edges (the cells' diagonals), so
        // a memo that kept the other mesh's edges would be caught.
        assert_ne!(a.edges(), b.edges());
        for m in [&a, &b, &b, &a, &Mesh::default(), &a] {
            assert_eq!(with_edges(m, |e| e.to_vec()), m.edges());
        }
    }

    #[test]
    fn too_few_points_is_an_error() {
        let pts = vec![Point2::new(0.0, 0.0), Point2::new(1.0, 0.0)];
        assert!(alpha_shape_contour(&pts, 1.0).is_err());
    }
}
