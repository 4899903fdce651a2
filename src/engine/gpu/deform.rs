//! GPU module of `shaders/deform.wgsl` (CPU twin: `crate::engine::cpu::deform`).

use super::buffers::{
    bind, bytes_of, compute_pipeline, fill, kernel_entries, uniform, SENTINEL_F32,
};
use super::{Gpu, GpuError};
use crate::engine::cpu::deform::DeformBatch;

/// Keep in sync with `Params` in shaders/deform.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DeformParams {
    /// Vertices per mesh.
    pub vertex_count: u32,
    /// Graph nodes per mesh.
    pub node_count: u32,
    /// Nodes each vertex follows.
    pub neighbours: u32,
    /// Meshes in the batch.
    pub mesh_count: u32,
}

pub(crate) struct DeformKernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl DeformKernel {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let entries = kernel_entries(5, 1);
        let (pipeline, layout) = compute_pipeline(device, "deform", "main", &entries);
        DeformKernel { pipeline, layout }
    }
}

/// Workgroups for `vertex_count` x `meshes` (64 vertices per group in x).
pub fn dispatch_size(vertex_count: u32, meshes: u32) -> (u32, u32) {
    (vertex_count.div_ceil(64), meshes)
}

impl Gpu<'_> {
    /// Deform every mesh of the batch; output as `cpu::deform::deform`.
    pub fn deform(&self, b: &DeformBatch) -> Result<Vec<[f32; 4]>, GpuError> {
        let _turn = self.turn();
        const K: &str = "deform";
        if b.mesh_count == 0 || b.vertex_count == 0 {
            return Ok(Vec::new());
        }
        let max_groups = self.device.limits().max_compute_workgroups_per_dimension;
        let (gx, gy) = dispatch_size(b.vertex_count, b.mesh_count);
        if gx > max_groups || gy > max_groups {
            return Err(GpuError::TooLarge {
                kernel: K,
                what: "workgroups per dimension",
                value: gx.max(gy) as u64,
                limit: max_groups as u64,
            });
        }
        let out_bytes = (b.rest.len() * 16) as u64;
        self.check_size(K, "output bytes", out_bytes)?;
        self.check_size(K, "weight table bytes", (b.weight.len() * 4) as u64)?;
        let params = DeformParams {
            vertex_count: b.vertex_count,
            node_count: b.node_count,
            neighbours: b.neighbours,
            mesh_count: b.mesh_count,
        };
        let (d, q, pool) = (self.device, self.queue, &self.pool);
        let u = uniform(d, K, bytemuck::bytes_of(&params));
        let none = wgpu::BufferUsages::empty();
        let bufs = [
            pool.upload(d, q, K, bytes_of(&b.rest), none),
            pool.upload(d, q, K, bytes_of(&b.nodes), none),
            pool.upload(d, q, K, bytes_of(&b.affine), none),
            pool.upload(d, q, K, bytes_of(&b.node_index), none),
            pool.upload(d, q, K, bytes_of(&b.weight), none),
        ];
        let out = pool.take(
            d,
            K,
            out_bytes,
            wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        );
        fill(q, &out, b.rest.len() * 4, SENTINEL_F32);
        let group = bind(
            d,
            &self.deform.layout,
            K,
            &[&u, &bufs[0], &bufs[1], &bufs[2], &bufs[3], &bufs[4], &out],
        );
        let read = self.dispatch_and_read(
            K,
            &self.deform.pipeline,
            &group,
            (gx, gy, 1),
            &[(&out, out_bytes)],
        );
        pool.give(bufs);
        pool.give([out]);
        let read = read?;
        Ok(bytemuck::pod_collect_to_vec(&read[0]))
    }
}
