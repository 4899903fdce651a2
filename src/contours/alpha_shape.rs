//! Alpha-shape boundary of projected vertices, as one ordered closed polyline of model vertex
//! indices. The Delaunay triangles come from delaunator (robust orientation tests, flat index
//! arrays): on the template's 2,500 projected vertices it triangulates in half the time spade's
//! bulk load took, and a reconstruction takes dozens of outlines. The outline starts at its
//! lowest vertex index, so it does not depend on the order a triangulation numbers its triangles.

use crate::geom::signed_area;
use crate::geom::Mesh;
use crate::views::{Camera, ProjectionError};
use nalgebra::Point2;

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
    /// A triangle's corner that is no vertex of the mesh (its fields are public).
    #[error("{0}")]
    Mesh(crate::geom::MeshError),
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

impl ModelContour {
    /// The same closed outline entered at its `k`-th point (points and vertex ids together).
    pub fn start_at(&mut self, k: usize) {
        self.vertex_ids.rotate_left(k);
        self.points.rotate_left(k);
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
    mesh.check_corners().map_err(ContourError::Mesh)?;
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
    // The finite points, and the input index of each.
    let (ids, sites): (Vec<u32>, Vec<delaunator::Point>) = points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.x.is_finite() && p.y.is_finite())
        .map(|(i, p)| (i as u32, delaunator::Point { x: p.x, y: p.y }))
        .unzip();
    let tri = delaunator::triangulate(&sites);
    if tri.triangles.is_empty() {
        return Err(ContourError::TooFewPoints { count: sites.len() });
    }
    let radii: Vec<f64> = tri
        .triangles
        .chunks_exact(3)
        .map(|t| circumradius(&sites[t[0]], &sites[t[1]], &sites[t[2]]))
        .collect();
    let mut alpha = alpha.max(1e-9);
    for _ in 0..60 {
        if let Some(lp) = trace_single_loop(&tri, &sites, &radii, alpha) {
            let mut ids: Vec<u32> = lp.iter().map(|&v| ids[v]).collect();
            let mut pts: Vec<Point2<f64>> = ids.iter().map(|&i| points[i as usize]).collect();
            if signed_area(&pts) < 0.0 {
                pts.reverse();
                ids.reverse();
            }
            // The outline starts at its lowest vertex index: where a loop is entered is the
            // triangulation's accident, and a closed curve's first point is where its
            // resampling starts.
            let first = (0..ids.len()).min_by_key(|&k| ids[k]).unwrap_or(0);
            let mut contour = ModelContour {
                vertex_ids: ids,
                points: pts,
            };
            contour.start_at(first);
            return Ok(contour);
        }
        alpha *= 1.5;
    }
    Err(ContourError::Delaunay("no simple outline found".into()))
}

/// Circumradius of a triangle.
fn circumradius(a: &delaunator::Point, b: &delaunator::Point, c: &delaunator::Point) -> f64 {
    let (ab, bc, ca) = (dist(a, b), dist(b, c), dist(c, a));
    let cross = ((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)).abs();
    if cross <= 0.0 {
        f64::INFINITY
    } else {
        ab * bc * ca / (2.0 * cross)
    }
}

fn dist(a: &delaunator::Point, b: &delaunator::Point) -> f64 {
    ((a.x - b.x).powi(2) + (a.y - b.y).powi(2)).sqrt()
}

/// Trace the boundary of the kept triangles (circumradius <= alpha). Holes (clockwise loops,
/// e.g. the fossa of a horseshoe-shaped surface) are ignored; the outline is the largest
/// counter-clockwise loop, as indices into `sites`. `None` when a vertex is pinched (two
/// outgoing boundary edges) or when that loop holds less than 95 % of the outer area (the shape
/// fell apart into islands): alpha must grow.
fn trace_single_loop(
    tri: &delaunator::Triangulation,
    sites: &[delaunator::Point],
    radii: &[f64],
    alpha: f64,
) -> Option<Vec<usize>> {
    let kept = |t: usize| radii[t] <= alpha;
    // Directed boundary edges (kept triangle on the left): from -> to. delaunator's triangles
    // turn counter-clockwise with y pointing down, clockwise in this crate's y-up sense, so a
    // kept triangle's side a -> b is walked b -> a.
    let mut next = vec![usize::MAX; sites.len()];
    let mut starts = Vec::new();
    for e in 0..tri.triangles.len() {
        if !kept(e / 3) {
            continue;
        }
        let o = tri.halfedges[e];
        if o != delaunator::EMPTY && kept(o / 3) {
            continue;
        }
        let (from, to) = (
            tri.triangles[delaunator::next_halfedge(e)],
            tri.triangles[e],
        );
        if next[from] != usize::MAX {
            return None; // a pinch vertex: two outgoing boundary edges
        }
        next[from] = to;
        starts.push(from);
    }
    let pos = |v: usize| Point2::new(sites[v].x, sites[v].y);
    let mut visited = vec![false; sites.len()];
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
    Some(lp)
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

    /// The outline does not depend on the order the points come in (the triangulation numbers
    /// its triangles by insertion), and it starts at its lowest vertex index. Companion: the
    /// same points with one outline corner pulled inwards give another outline.
    #[test]
    fn the_outline_is_the_same_for_any_order_of_the_points() {
        // A ragged disc: 400 points on a jittered spiral, as projected vertices lie.
        let pts: Vec<Point2<f64>> = (0..400)
            .map(|k| {
                let t = k as f64 * 2.399_963;
                let r = 40.0 * ((k as f64 + 0.5) / 400.0).sqrt() + (k % 7) as f64 * 0.05;
                Point2::new(300.0 + r * t.cos(), 200.0 + r * t.sin())
            })
            .collect();
        let alpha = 6.0;
        let outline = |p: &[Point2<f64>]| {
            let c = alpha_shape_contour(p, alpha).unwrap();
            assert_eq!(c.vertex_ids[0], *c.vertex_ids.iter().min().unwrap());
            assert!(signed_area(&c.points) > 0.0);
            c.points
        };
        let a = outline(&pts);
        assert!(a.len() > 20, "{} outline points", a.len());
        // The points reversed and interleaved; the outline compared as positions from its
        // leftmost point.
        let mut shuffled: Vec<Point2<f64>> = pts.iter().rev().step_by(2).copied().collect();
        shuffled.extend(pts.iter().rev().skip(1).step_by(2));
        let from_left = |mut p: Vec<Point2<f64>>| {
            let k = crate::geom::fixed_start(&p);
            p.rotate_left(k);
            p
        };
        assert_eq!(from_left(outline(&shuffled)), from_left(a.clone()));
        let last = pts.len() - 1; // the spiral's last point lies on the outline
        assert!(a.contains(&pts[last]));
        let mut pulled = pts.clone();
        pulled[last] = Point2::new(300.0, 200.0) + (pts[last] - Point2::new(300.0, 200.0)) * 0.8;
        assert_ne!(from_left(outline(&pulled)), from_left(a));
    }

    #[test]
    fn too_few_points_is_an_error() {
        let pts = vec![Point2::new(0.0, 0.0), Point2::new(1.0, 0.0)];
        assert!(alpha_shape_contour(&pts, 1.0).is_err());
    }
}
