//! Stage 1: the standard hemisphere template and where it is placed.

mod hemisphere;

pub use hemisphere::{hemisphere, spherical_cap, Placement, MAX_CAP_VERTICES};
