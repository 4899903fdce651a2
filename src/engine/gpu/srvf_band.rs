//! GPU module of `shaders/srvf_band.wgsl` (CPU twin: `crate::engine::cpu::srvf_band`): the
//! banded SRVF DPs of alignments, one problem per workgroup, rows in order; the back-pointers
//! come back and are traced on the host (`correspond::srvf::trace_band`).

use super::buffers::{bytes_of, compute_pipeline, kernel_entries};
use super::srvf_dp::{GpuStep, GpuTap};
use super::{Gpu, GpuError};
use crate::engine::cpu::srvf_band::BandBatch;

/// Keep in sync with `Params` in shaders/srvf_band.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BandParams {
    /// Problems in the batch.
    pub problems: u32,
    /// DP steps.
    pub step_count: u32,
    /// Padding to 16 bytes.
    pub _pad: [u32; 2],
}

pub(crate) struct SrvfBandKernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl SrvfBandKernel {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let entries = kernel_entries(6, 2);
        let (pipeline, layout) = compute_pipeline(device, "srvf_band", "main", &entries);
        SrvfBandKernel { pipeline, layout }
    }
}

impl Gpu<'_> {
    /// The (cost, back-pointer) tables of every problem, as `cpu::srvf_band::band_tables`.
    pub fn srvf_band_tables(&self, b: &BandBatch) -> Result<(Vec<f32>, Vec<u32>), GpuError> {
        let _turn = self.turn();
        const K: &str = "srvf_band";
        let problems = b.headers.len() as u32;
        if problems == 0 {
            return Ok((Vec::new(), Vec::new()));
        }
        let max_groups = self.device.limits().max_compute_workgroups_per_dimension;
        if problems > max_groups {
            return Err(GpuError::TooLarge {
                kernel: K,
                what: "problems per batch",
                value: problems as u64,
                limit: max_groups as u64,
            });
        }
        let params = BandParams {
            problems,
            step_count: b.steps.len() as u32,
            _pad: [0; 2],
        };
        let steps: Vec<GpuStep> = b.steps.iter().map(GpuStep::from).collect();
        let taps: Vec<GpuTap> = b.taps.iter().map(GpuTap::from).collect();
        self.dp_tables_on_device(
            K,
            (&self.srvf_band.pipeline, &self.srvf_band.layout),
            bytemuck::bytes_of(&params),
            &[
                bytes_of(&b.headers),
                bytes_of(&b.rows),
                bytes_of(&b.curves),
                bytes_of(&b.positions),
                bytes_of(&steps),
                bytes_of(&taps),
            ],
            b.cells,
            problems,
        )
    }
}

/// One problem per dispatch on the engine (a reconstruction's alignments on a borrowed device;
/// the study merges its runs' problems through `GpuBatcher` instead). A problem the device
/// cannot take is left to the host.
impl crate::correspond::srvf::BandSolver for Gpu<'_> {
    fn back_pointers(&self, p: &crate::correspond::srvf::BandProblem) -> Option<Vec<u32>> {
        self.back_pointers_many(std::slice::from_ref(p))?.pop()
    }

    /// The problems in one dispatch.
    fn back_pointers_many(
        &self,
        ps: &[crate::correspond::srvf::BandProblem],
    ) -> Option<Vec<Vec<u32>>> {
        let b = BandBatch::new(ps).ok()?;
        let (_, back) = self.srvf_band_tables(&b).ok()?;
        Some(b.ranges().into_iter().map(|r| back[r].to_vec()).collect())
    }
}
