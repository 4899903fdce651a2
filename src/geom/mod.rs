//! Geometry every stage shares: triangle meshes, 2D polylines and curves, sphere fits, nearest
//! neighbours in 3D, and the summary statistics (one mean, SD, quantile and centroid).

mod knn;
mod mesh;
mod polyline;
mod sphere;
mod stats;

pub use knn::Knn3;
pub use mesh::{Mesh, MeshError};
pub use polyline::{
    polyline_length, resample_closed, resample_open, signed_area, ClosedPolyline, Curve,
};
pub use sphere::{fit_sphere, fit_sphere_robust, Sphere, SphereFitError};
pub use stats::{centroid, mean, mean_sd, quantile_sorted};
