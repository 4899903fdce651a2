//! Stage 6: what comes out: accuracy metrics, the fitted sphere and cup size, coloured meshes and
//! the JSON report.

mod cup;
mod metrics;
mod sphere;

pub use cup::{CupCatalogue, CupSize};
pub use metrics::{error_colors, surface_distance, surface_samples, DistanceStats, SurfaceQuery};
pub use sphere::{fit_sphere, fit_sphere_robust, Sphere, SphereFitError};
