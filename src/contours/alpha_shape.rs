//! Alpha-shape boundary of projected vertices (spade Delaunay), as one ordered closed polyline of
//! model vertex indices.

use super::bulk_order::{in_bulk_load_order, Site};
use crate::geom::signed_area;
use crate::geom::Mesh;
use crate::views::{Camera, ProjectionError};
use nalgebra::Point2;
use spade::{DelaunayTriangulation, Triangulation};

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
