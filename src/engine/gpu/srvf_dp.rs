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
        let _turn = self.turn();
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
        let params = DpParams {
            samples: b.samples,
            problems: b.problems,
            step_count: b.steps.len() as u32,
            _pad: 0,
        };
        let steps: Vec<GpuStep> = b.steps.iter().map(GpuStep::from).collect();
        let taps: Vec<GpuTap> = b.taps.iter().map(GpuTap::from).collect();
        self.dp_tables_on_device(
            K,
            (&self.srvf_dp.pipeline, &self.srvf_dp.layout),
            bytemuck::bytes_of(&params),
            &[
                bytes_of(&b.q1),
                bytes_of(&b.q2),
                bytes_of(&steps),
                bytes_of(&taps),
            ],
            cells,
            b.problems,
        )
    }

    /// One dispatch of a DP kernel (`kernel`'s pipeline and layout): the uniform, the input
    /// buffers in binding order, then the cost and back-pointer tables of `cells` cells
    /// (pre-filled with sentinels), one workgroup a problem; the two tables read back.
    pub(super) fn dp_tables_on_device(
        &self,
        kernel: &'static str,
        (pipeline, layout): (&wgpu::ComputePipeline, &wgpu::BindGroupLayout),
        params: &[u8],
        inputs: &[&[u8]],
        cells: usize,
        problems: u32,
    ) -> Result<(Vec<f32>, Vec<u32>), GpuError> {
        let table_bytes = (cells * 4) as u64;
        self.check_size(kernel, "table bytes", table_bytes)?;
        for data in inputs {
            self.check_size(kernel, "input bytes", data.len() as u64)?;
        }
        let (d, q, pool) = (self.device, self.queue, &self.pool);
        let u = uniform(d, kernel, params);
        let none = wgpu::BufferUsages::empty();
        let ins: Vec<wgpu::Buffer> = inputs
            .iter()
            .map(|data| pool.upload(d, q, kernel, data, none))
            .collect();
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let cost = pool.take(d, kernel, table_bytes, usage);
        let back = pool.take(d, kernel, table_bytes, usage);
        fill(q, &cost, cells, SENTINEL_F32);
        fill(q, &back, cells, SENTINEL_U32);
        let mut entries: Vec<&wgpu::Buffer> = vec![&u];
        entries.extend(ins.iter());
        entries.extend([&cost, &back]);
        let group = bind(d, layout, kernel, &entries);
        let read = self.dispatch_and_read(
            kernel,
            pipeline,
            &group,
            (problems, 1, 1),
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
