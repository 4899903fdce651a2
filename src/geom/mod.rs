//! Geometry every stage shares: triangle meshes, 2D polylines and curves, sphere fits, nearest
//! neighbours in 3D, the summary statistics (one mean, SD, quantile and centroid), and the one
//! thread pool (`pool_map`).

mod knn;
mod mesh;
mod polyline;
mod pool;
mod segments;
mod sphere;
mod stats;
mod stray;
mod through;

pub use knn::Knn3;
pub use mesh::{Mesh, MeshError};
pub use polyline::{
    convex_hull_area, distance_to_polyline, fixed_start, hull_fill, longest_segment,
    polyline_length, resample_closed, resample_open, signed_area, turns_round_centroid,
    widest_extent, winding_number, ClosedPolyline, Curve,
};
pub use pool::{par_map, pool_map};
pub use segments::Segments;
pub use sphere::{fit_sphere, fit_sphere_robust, Sphere, SphereFitError};
pub use stats::{centroid, mean, mean_sd, opening_axis, quantile_sorted};
pub use stray::{stray_point, StrayPoint};
pub use through::{MAX_ARC_TURN_DEG, THROUGH_STEP_PX};
