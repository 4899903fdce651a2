//! Stage 2: X-ray views, each a pinhole camera p ~ K (R P + t), and the simulated view geometry.

mod camera;
mod geometry;

pub use camera::{Camera, Intrinsics, ProjectionError};
pub use geometry::{simulated_views, GeometryError, XrayGeometry};
