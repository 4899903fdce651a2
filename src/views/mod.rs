//! Stage 2: X-ray views, each a pinhole camera p ~ K (R P + t).

mod camera;

pub use camera::{Camera, Intrinsics, ProjectionError};
