//! What stage 4 hands to stage 5: one 2D-3D correspondence and the frame its residual is
//! measured in.

use nalgebra::{Matrix2, Point2, Vector2};

/// One 2D-3D correspondence: model vertex `vertex` should project onto `target` in view `view`.
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// The view the vertex is seen in.
    pub view: usize,
    /// The model vertex.
    pub vertex: u32,
    /// Where it should project, pixels.
    pub target: Point2<f64>,
    /// Robustness weight in [0, 1] (multiplies the squared residual).
    pub weight: f64,
    /// Unit normal of the observed contour at `target` (zero when unknown).
    pub normal: Vector2<f64>,
}

impl Observation {
    /// The 2x2 map applied to the pixel residual: rows n^T and `tangential` t^T (t the contour
    /// tangent). A silhouette point may slide along the outline, so the component along the
    /// contour is down-weighted (point-to-line distance plus a little point-to-point); with no
    /// normal it is the identity (plain reprojection error).
    pub fn residual_frame(&self, tangential: f64) -> Matrix2<f64> {
        let n = self.normal;
        if n.norm_squared() < 0.5 {
            return Matrix2::identity();
        }
        Matrix2::new(n.x, n.y, -tangential * n.y, tangential * n.x)
    }
}
