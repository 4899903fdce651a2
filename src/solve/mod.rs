//! Stage 5: the deformation. An embedded deformation graph over the template, the energy
//! w_rot E_rot + w_reg E_reg + w_obs E_obs, and Gauss-Newton / Levenberg-Marquardt on its sparse
//! normal equations (faer). A 7-parameter similarity stage runs first.

mod energy;
mod graph;
mod limb;
mod lm;
mod normal;
mod pose;
mod reprojection;
mod rim;
mod similarity;

pub use energy::{EdProblem, EdWeights, ShapeTerms, SpherePrior};
pub use graph::{farthest_point_sample, DeformationGraph, GraphParams, NODE_PARAMS};
pub use limb::{limb_sphere, LimbError, LimbSphere};
pub use lm::{
    levenberg_marquardt, levenberg_marquardt_cached, LmInfo, LmParams, Problem, SolveError,
};
pub use normal::{LinearSolveError, Linearization, NormalEquations, SymbolicCache};
pub use pose::{corrected_camera, PoseParams, PoseProblem};
pub use reprojection::{behind, reprojection, Reprojection};
pub use rim::{radiographic_angles, rim_orientation, RimError, RimFit, RIM_WITHIN};
pub use similarity::{apply_similarity, full_state, SimilarityProblem, SIM_PARAMS};
