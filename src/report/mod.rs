//! Stage 6: what comes out: accuracy metrics, the fitted sphere and cup size, coloured meshes and
//! the JSON report.

mod cup;
mod metrics;
pub mod plots;
mod sphere;

pub use cup::{CupCatalogue, CupSize};
pub use metrics::{
    error_colors, interior_distance, surface_distance, surface_samples, DistanceStats,
    InteriorQuery, SurfaceQuery,
};
pub use sphere::{fit_sphere, fit_sphere_robust, Sphere, SphereFitError};
