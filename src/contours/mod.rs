//! Stage 3: contours. The model contour of a view is the alpha-shape boundary of the projected
//! template vertices; observed contours are pixel polylines annotated on the X-ray.

mod alpha_shape;
mod curve_file;
mod silhouette;

pub use alpha_shape::{
    alpha_shape_contour, default_alpha, model_contour, model_contours, ContourError, ModelContour,
};
pub use curve_file::{read_curve_csv, CurveFileError};
pub use silhouette::{exact_points, silhouette_contour, ContourSource};
