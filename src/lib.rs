//! acetab: reconstruct the acetabular surface from three pelvic X-rays and size the cup.
//!
//! The pipeline, one module per stage, data flowing forward:
//! `template` (hemisphere) -> `views` (cameras) -> `contours` (alpha shape | silhouette) ->
//! `correspond` (SRVF | ICP | ICP-NormVec) -> `solve` (similarity, then the embedded deformation
//! graph by Gauss-Newton with faer) -> `report` (metrics, cup catalogue, plots). `geom` and `io`
//! are the ground floor every stage stands on; `engine` runs the per-iteration kernels on the CPU
//! or the GPU; `pipeline` is the method, stage after stage; `sim` makes synthetic truths and
//! X-rays; `case` reads and runs case files; `study` runs simulation studies and the bench.
//!
//! The usual entry points are re-exported here:
//!
//! ```no_run
//! use acetab::{reconstruct, Kernels, ReconParams, Template};
//! # fn go(case: &acetab::case::Case) -> Result<(), acetab::ReconError> {
//! let template = Template::standard();
//! let rec = reconstruct(&case.input(&template), &ReconParams::default(), Kernels::Cpu)?;
//! println!("cup {:.1} mm -> {} mm", rec.sphere.diameter(), rec.cup.catalogue_mm);
//! # Ok(())
//! # }
//! ```

// `!(x > y)` is how this crate turns away NaN along with the values that fail the test; the
// lint's `partial_cmp` rewrite would hide that.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![warn(missing_docs)]

pub mod geom;
pub mod io;

pub mod contours;
pub mod correspond;
pub mod report;
pub mod solve;
pub mod template;
pub mod views;

pub mod prior;

pub mod engine;
pub mod pipeline;

pub mod case;
pub mod sim;
pub mod study;

pub use case::{Case, CaseFile};
pub use contours::{ContourSource, ModelContour};
pub use correspond::{Method, Observation};
pub use engine::gpu::{GlTurn, Gpu, GpuDevice, GpuError};
pub use engine::{BackendChoice, Kernels};
pub use geom::{Curve, Mesh, Sphere};
pub use pipeline::{
    cup_report, reconstruct, CupReport, Input, ReconError, ReconParams, Reconstruction,
    UncertaintyParams,
};
pub use report::{CupCatalogue, CupSize};
pub use template::{Placement, Template};
pub use views::{Camera, Intrinsics};
