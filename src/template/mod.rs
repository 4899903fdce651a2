//! Stage 1: the standard hemisphere template and where it is placed.

mod hemisphere;
mod unit;

pub use hemisphere::{hemisphere, spherical_cap, Placement, MAX_CAP_VERTICES};
pub use unit::{Template, TemplateError, TemplateParams, MAX_TEMPLATE_VERTICES};
