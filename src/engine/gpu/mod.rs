//! The GPU engine: one module per kernel in `shaders/`, each owning its pipeline, bind-group
//! layout and dispatch maths; CPU twins live in `crate::engine::cpu`. The engine borrows the caller's
//! `wgpu::Device` and `wgpu::Queue` (`Gpu::new`), so a planning tool that already renders with
//! wgpu can embed it; `GpuDevice::from_env` builds a device for the command-line tool.

pub mod batcher;
mod buffers;
mod context;
pub mod deform;
pub mod project;
mod raster;
pub mod silhouette;
pub mod srvf_band;
pub mod srvf_dp;
pub mod surface;

pub use batcher::{BatcherStats, GpuBatcher, KernelStats};
pub use context::{GlTurn, Gpu, GpuDevice, GpuError};

/// The WGSL sources, by kernel name (validated by the naga test and compiled by `Gpu::new`).
pub const SHADERS: [(&str, &str); 6] = [
    ("deform", include_str!("../../../shaders/deform.wgsl")),
    ("project", include_str!("../../../shaders/project.wgsl")),
    (
        "silhouette",
        include_str!("../../../shaders/silhouette.wgsl"),
    ),
    ("srvf_band", include_str!("../../../shaders/srvf_band.wgsl")),
    ("srvf_dp", include_str!("../../../shaders/srvf_dp.wgsl")),
    ("surface", include_str!("../../../shaders/surface.wgsl")),
];

/// The WGSL source of the named kernel (every name the engine compiles is in `SHADERS`).
pub(crate) fn shader(name: &str) -> &'static str {
    SHADERS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| *s)
        .expect("every kernel name is in SHADERS")
}
