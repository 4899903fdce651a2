//! Stage 1: the standard hemisphere template and the built-in acetabulum phantom.

mod hemisphere;
mod phantom;

pub use hemisphere::{hemisphere, spherical_cap, Placement, MAX_CAP_VERTICES};
pub use phantom::{phantom, try_phantom, Phantom, PhantomError, PhantomParams};
