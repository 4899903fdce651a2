//! Stage 2: X-ray views, each a pinhole camera p ~ K (R P + t).

mod camera;
mod turn;

pub use camera::{Camera, Intrinsics, ProjectionError};
pub use turn::{view_set_mismatch_deg, BodyAxis, ViewRotation, MAX_PAIRED_VIEWS};

use nalgebra::Vector3;

/// The least angle, degrees, between the viewing directions of some two views of a set: below
/// it the views see the same outline and the depth of the cap is not determined (the paper's
/// views differ by 20). Case files and simulated view sets are held to it alike.
pub const MIN_VIEW_SPREAD_DEG: f64 = 2.0;

/// The largest angle, degrees, between any two of `directions` (0 for fewer than two).
pub fn widest_spread_deg(directions: &[Vector3<f64>]) -> f64 {
    directions
        .iter()
        .enumerate()
        .flat_map(|(i, a)| directions[i + 1..].iter().map(move |b| a.angle(b)))
        .fold(0.0_f64, f64::max)
        .to_degrees()
}
