//! acetab: reconstruct the acetabular surface from three pelvic X-rays and size the cup.
//!
//! The pipeline, one module per stage:
//! template (hemisphere) -> views (cameras) -> contours (alpha shape) -> correspond (SRVF | ICP |
//! ICP-NormVec) -> solve (similarity, then the embedded deformation graph by Gauss-Newton with
//! faer) -> report (metrics, sphere fit, cup size). `pipeline` runs them in order; `case` reads
//! case files; `simulate` makes synthetic cases from a ground-truth surface.

// `!(x > y)` is how this crate turns away NaN along with the values that fail the test; the
// lint's `partial_cmp` rewrite would hide that.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod backend;
pub mod bench;
pub mod case;
pub mod case_run;
pub mod contours;
pub mod correspond;
pub mod cpu;
pub mod demo;
pub mod fsutil;
pub mod gpu;
pub mod mesh;
pub mod pipeline;
pub mod report;
pub mod simulate;
pub mod solve;
pub mod study;
pub mod template;
pub mod uncertainty;
pub mod views;
