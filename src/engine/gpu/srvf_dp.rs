//! GPU module of `shaders/srvf_dp.wgsl` (CPU twin: `crate::engine::cpu::srvf_dp`): one DP problem per
//! workgroup, filled by anti-diagonals; back-pointers come back and are traced on the host.

use super::buffers::{
    bind, bytes_of, compute_pipeline, fill, kernel_entries, uniform, SENTINEL_F32, SENTINEL_U32,
};
use super::{Gpu, GpuError};
use crate::correspond::srvf::{CurvePair, Warp};
use crate::engine::cpu::srvf_dp::{warps_from_tables, DpBatch, StepEntry, TapEntry};

/// Keep in sync with `Params` in shaders/srvf_dp.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DpParams {
    /// Samples per curve.
    pub samples: u32,
    /// Problems in the batch.
    pub problems: u32,
    /// DP steps.
    pub step_count: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

/// Keep in sync with `Step` in shaders/srvf_dp.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuStep {
    /// Step in A's samples.
    pub a: u32,
    /// Step in B's samples.
    pub b: u32,
    /// sqrt(b / a).
    pub sqrt_slope: f32,
    /// First of its taps.
    pub tap_start: u32,
}

/// Keep in sync with `Tap` in shaders/srvf_dp.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuTap {
    /// Whole-sample offset along B.
    pub offset: u32,
    /// Fraction towards the next sample.
    pub frac: f32,
}

impl From<&StepEntry> for GpuStep {
    fn from(s: &StepEntry) -> Self {
        GpuStep {
            a: s.a,
            b: s.b,
            sqrt_slope: s.sqrt_slope,
            tap_start: s.tap_start,
        }
    }
}

impl From<&TapEntry> for GpuTap {
    fn from(t: &TapEntry) -> Self {
        GpuTap {
            offset: t.offset,
            frac: t.frac,
        }
    }
}

pub(crate) struct SrvfDpKernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl SrvfDpKernel {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let entries = kernel_entries(4, 2);
        let (pipeline, layout) = compute_pipeline(device, "srvf_dp", "main", &entries);
        SrvfDpKernel { pipeline, layout }
    }
}

impl Gpu<'_> {
    /// The (cost, back-pointer) tables of every problem, as `cpu::srvf_dp::dp_tables`.
    pub fn srvf_dp_tables(&self, b: &DpBatch) -> Result<(Vec<f32>, Vec<u32>), GpuError> {
        const K: &str = "srvf_dp";
        if b.problems == 0 {
            return Ok((Vec::new(), Vec::new()));
        }
        let max_groups = self.device.limits().max_compute_workgroups_per_dimension;
        if b.problems > max_groups {
            return Err(GpuError::TooLarge {
                kernel: K,
                what: "problems per batch",
                value: b.problems as u64,
                limit: max_groups as u64,
            });
        }
        let cells = b.problems as usize * b.cells();
        let table_bytes = (cells * 4) as u64;
        self.check_size(K, "table bytes", table_bytes)?;
        let params = DpParams {
            samples: b.samples,
            problems: b.problems,
            step_count: b.steps.len() as u32,
            _pad: 0,
        };
        let steps: Vec<GpuStep> = b.steps.iter().map(GpuStep::from).collect();
        let taps: Vec<GpuTap> = b.taps.iter().map(GpuTap::from).collect();
        let (d, q, pool) = (self.device, self.queue, &self.pool);
        let u = uniform(d, K, bytemuck::bytes_of(&params));
        let none = wgpu::BufferUsages::empty();
        let ins = [
            pool.upload(d, q, K, bytes_of(&b.q1), none),
            pool.upload(d, q, K, bytes_of(&b.q2), none),
            pool.upload(d, q, K, bytes_of(&steps), none),
            pool.upload(d, q, K, bytes_of(&taps), none),
        ];
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let cost = pool.take(d, K, table_bytes, usage);
        let back = pool.take(d, K, table_bytes, usage);
        fill(q, &cost, cells, SENTINEL_F32);
        fill(q, &back, cells, SENTINEL_U32);
        let group = bind(
            d,
            &self.srvf_dp.layout,
            K,
            &[&u, &ins[0], &ins[1], &ins[2], &ins[3], &cost, &back],
        );
        let read = self.dispatch_and_read(
            K,
            &self.srvf_dp.pipeline,
            &group,
            (b.problems, 1, 1),
            &[(&cost, table_bytes), (&back, table_bytes)],
        );
        pool.give(ins);
        pool.give([cost, back]);
        let read = read?;
        Ok((
            bytemuck::pod_collect_to_vec(&read[0]),
            bytemuck::pod_collect_to_vec(&read[1]),
        ))
    }

    /// Optimal warps of a batch of SRVF pairs (full-grid DP on the GPU, traceback on the host).
    pub fn srvf_warps(
        &self,
        pairs: &[CurvePair<'_>],
        steps: &[(usize, usize)],
    ) -> Result<Vec<Warp>, GpuError> {
        if pairs.is_empty() {
            return Ok(Vec::new());
        }
        let b = DpBatch::new(pairs, steps)?;
        let (_, back) = self.srvf_dp_tables(&b)?;
        Ok(warps_from_tables(pairs, &b, &back))
    }
}
