//! Stage 6: what comes out: accuracy metrics, the fitted sphere and cup size, coloured meshes and
//! the JSON report.

mod accuracy;
mod cup;
mod metrics;
mod picture;
#[cfg(feature = "plots")]
pub mod plots;
mod provenance;

pub use accuracy::{
    accuracy, accuracy_and_shift, accuracy_from, accuracy_samples, shifted_accuracy, vertex_errors,
    write_error_ply, write_errors_ply, Accuracy, Shifted,
};
pub use cup::{CupCatalogue, CupSize};
pub use metrics::{
    error_colors, interior_distance, surface_distance, surface_samples, DistanceStats,
    InteriorQuery, SurfaceQuery, NO_ERROR_COLOR,
};
pub use picture::{PanelPixels, SurfacePanel};
pub use provenance::Provenance;
