//! CPU twins of the GPU kernels in `shaders/`: the same inputs, the same loops and the same
//! operation order in f32, so each GPU module can be checked against its twin (exactly for
//! integer outputs, within a stated bound for floats). They are also the `cpu` side of
//! `acetab bench`.

pub mod deform;
pub mod project;
pub mod silhouette;
pub mod srvf_band;
pub mod srvf_dp;
pub mod surface;
