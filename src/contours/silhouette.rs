//! Model contours from silhouettes: how the contour of each view is found (alpha shape or
//! rasterised silhouette), the contour from a traced silhouette loop, and the f64 re-projection
//! of the vertices a kernel chose. The raster and edge kernels themselves live in
//! `engine::{cpu, gpu}::silhouette`.

use super::{ContourError, ModelContour};
use crate::geom::{signed_area, Mesh};
use crate::views::Camera;
use nalgebra::Point2;

/// How the model contour of each view is found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum ContourSource {
    /// Alpha shape of the projected vertices (Delaunay triangulation by delaunator).
    #[default]
    AlphaShape,
    /// Rasterised silhouette (render pass + edge kernel on the GPU, its twin on the CPU).
    Silhouette,
}

/// The kernels choose the contour's vertices; their positions are re-projected in f64 so that
/// the correspondence stage sees the same numbers on either backend.
pub fn exact_points(
    mut c: ModelContour,
    mesh: &Mesh,
    cam: &Camera,
) -> Result<ModelContour, ContourError> {
    for (p, &id) in c.points.iter_mut().zip(&c.vertex_ids) {
        *p = cam.project(&mesh.vertices[id as usize]).map_err(|source| {
            ContourError::Projection {
                vertex: id as usize,
                source,
            }
        })?;
    }
    Ok(c)
}

/// A model contour from a traced loop of vertex ids, turned to positive signed area.
pub fn silhouette_contour(ids: &[u32], pts: &[Point2<f64>]) -> Result<ModelContour, ContourError> {
    if ids.len() < 3 {
        return Err(ContourError::TooFewPoints { count: ids.len() });
    }
    let mut vertex_ids = ids.to_vec();
    let mut points: Vec<Point2<f64>> = ids.iter().map(|&i| pts[i as usize]).collect();
    if signed_area(&points) < 0.0 {
        vertex_ids.reverse();
        points.reverse();
    }
    Ok(ModelContour { vertex_ids, points })
}
