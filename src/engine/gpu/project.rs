//! GPU module of `shaders/project.wgsl` (CPU twin: `crate::engine::cpu::project`).

use super::buffers::{
    bind, bytes_of, compute_pipeline, fill, kernel_entries, uniform, SENTINEL_F32,
};
use super::{Gpu, GpuError};
use crate::engine::cpu::project::ViewRows;

/// Keep in sync with `Params` in shaders/project.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ProjectParams {
    /// Vertices per mesh.
    pub vertex_count: u32,
    /// Meshes in the batch.
    pub mesh_count: u32,
    /// Views per mesh.
    pub view_count: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

/// Keep in sync with `View` in shaders/project.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuView {
    /// First row of [R | t].
    pub r0: [f32; 4],
    /// Second row of [R | t].
    pub r1: [f32; 4],
    /// Third row of [R | t].
    pub r2: [f32; 4],
    /// fx, fy, cx, cy.
    pub k: [f32; 4],
}

impl From<&ViewRows> for GpuView {
    fn from(v: &ViewRows) -> Self {
        GpuView {
            r0: v.r[0],
            r1: v.r[1],
            r2: v.r[2],
            k: v.k,
        }
    }
}

pub(crate) struct ProjectKernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl ProjectKernel {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let entries = kernel_entries(2, 1);
        let (pipeline, layout) = compute_pipeline(device, "project", "main", &entries);
        ProjectKernel { pipeline, layout }
    }
}

impl Gpu<'_> {
    /// Project B meshes of `vertex_count` vertices each into every view; output as
    /// `cpu::project::project`, index (mesh * C + view) * V + vertex.
    pub fn project(
        &self,
        vertices: &[[f32; 4]],
        vertex_count: usize,
        views: &[ViewRows],
    ) -> Result<Vec<[f32; 4]>, GpuError> {
        let _turn = self.turn();
        let out = self.project_to_buffer(vertices, vertex_count, views)?;
        let Some((buf, bytes)) = out else {
            return Ok(Vec::new());
        };
        let read = self.submit_and_read("project", |_| {}, &[(&buf, bytes)]);
        self.pool.give([buf]);
        Ok(bytemuck::pod_collect_to_vec(&read?[0]))
    }

    /// Run the projection and leave the result on the device (the silhouette pass reads it).
    pub(crate) fn project_to_buffer(
        &self,
        vertices: &[[f32; 4]],
        vertex_count: usize,
        views: &[ViewRows],
    ) -> Result<Option<(wgpu::Buffer, u64)>, GpuError> {
        const K: &str = "project";
        if vertex_count == 0 || views.is_empty() || vertices.is_empty() {
            return Ok(None);
        }
        if !vertices.len().is_multiple_of(vertex_count) {
            return Err(GpuError::Input {
                kernel: K,
                message: format!(
                    "{} vertices is not a whole number of meshes of {vertex_count}",
                    vertices.len()
                ),
            });
        }
        let meshes = vertices.len() / vertex_count;
        let n_out = meshes * views.len() * vertex_count;
        let out_bytes = (n_out * 16) as u64;
        self.check_size(K, "output bytes", out_bytes)?;
        let max_groups = self.device.limits().max_compute_workgroups_per_dimension as u64;
        let (gx, gy) = (
            (vertex_count as u64).div_ceil(64),
            (meshes * views.len()) as u64,
        );
        if gx > max_groups || gy > max_groups {
            return Err(GpuError::TooLarge {
                kernel: K,
                what: "workgroups per dimension",
                value: gx.max(gy),
                limit: max_groups,
            });
        }
        let params = ProjectParams {
            vertex_count: vertex_count as u32,
            mesh_count: meshes as u32,
            view_count: views.len() as u32,
            _pad: 0,
        };
        let gv: Vec<GpuView> = views.iter().map(GpuView::from).collect();
        let (d, q, pool) = (self.device, self.queue, &self.pool);
        let u = uniform(d, K, bytemuck::bytes_of(&params));
        let none = wgpu::BufferUsages::empty();
        let vb = pool.upload(d, q, K, bytes_of(vertices), none);
        let cb = pool.upload(d, q, K, bytes_of(&gv), none);
        let out = pool.take(
            d,
            K,
            out_bytes,
            wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        );
        fill(q, &out, n_out * 4, SENTINEL_F32);
        let group = bind(d, &self.project.layout, K, &[&u, &vb, &cb, &out]);
        let scope = d.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut enc = d.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(K) });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(K),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.project.pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(gx as u32, gy as u32, 1);
        }
        q.submit([enc.finish()]);
        pool.give([vb, cb]);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Wgpu {
                kernel: K,
                message: e.to_string(),
            });
        }
        Ok(Some((out, out_bytes)))
    }
}
