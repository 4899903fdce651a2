//! A population prior of the acetabulum's shape (issue 17): how its surface departs from its own
//! sphere, by direction in body axes, learned from a set of meshes (`acetab prior build`) as a
//! mean deviation field and its principal modes. The deformation's sphere prior uses it where no
//! outline watches: the unseen walls follow the population's shape around the solved sphere
//! instead of the bare sphere (`solve::SpherePrior::shape`).

mod field;
mod file;
mod model;

pub use field::{deviation_field, opens_to_plus_x, to_prior_frame, GRID_POINTS, KERNEL_DEG};
pub use file::{
    choose_prior, PriorFile, PriorFileError, PriorMesh, DEFAULT_MODES, FORMAT, SHIPPED_JSON,
};
pub use model::{PriorError, ShapePrior, MAX_MODES};
