//! GPU module of `shaders/surface.wgsl` (CPU twin: `crate::engine::cpu::surface`): one render
//! pass draws the surface, depth-tested, into an RGBA8 panel that is read back.

use super::buffers::{
    bind, bytes_of, copy_square_texture, render_pipeline, square_texture, storage, uniform,
    uniform_entry_in,
};
use super::{Gpu, GpuError};
pub use crate::engine::cpu::surface::SurfaceView;

pub(crate) struct SurfaceKernel {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
}

const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

impl SurfaceKernel {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let source = super::shader("surface");
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("surface"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        // The view is read by both stages.
        let stages = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("surface"),
            entries: &[
                uniform_entry_in(0, stages),
                storage(1, true),
                storage(2, true),
                storage(3, true),
            ],
        });
        let pipeline = render_pipeline(device, "surface", &module, &layout, FORMAT, Some(DEPTH));
        SurfaceKernel { pipeline, layout }
    }
}

impl Gpu<'_> {
    /// As `cpu::surface::render_surface`: the panel's RGBA pixels, row-major from the top-left.
    pub fn render_surface(
        &self,
        points: &[[f32; 4]],
        colors: &[[f32; 4]],
        triangles: &[u32],
        view: &SurfaceView,
    ) -> Result<Vec<[u8; 4]>, GpuError> {
        let _turn = self.turn();
        const K: &str = "surface";
        let input = |message: String| GpuError::Input { kernel: K, message };
        let n = view.size() as u32;
        let lim = self.device.limits();
        if n == 0 || n > lim.max_texture_dimension_2d {
            return Err(GpuError::TooLarge {
                kernel: K,
                what: "panel size",
                value: n as u64,
                limit: lim.max_texture_dimension_2d as u64,
            });
        }
        if points.is_empty() || colors.len() != points.len() {
            return Err(input(format!(
                "{} vertices and {} colours: one colour a vertex, at least one vertex",
                points.len(),
                colors.len()
            )));
        }
        if triangles.is_empty() || !triangles.len().is_multiple_of(3) {
            return Err(input(format!(
                "{} triangle corners is not a positive multiple of 3",
                triangles.len()
            )));
        }
        if let Some(&bad) = triangles.iter().find(|&&i| i as usize >= points.len()) {
            return Err(input(format!(
                "triangle corner {bad} is not one of the {} vertices",
                points.len()
            )));
        }
        let (d, q, pool) = (self.device, self.queue, &self.pool);
        let row_bytes = (n * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let u = uniform(d, K, bytemuck::bytes_of(view));
        let none = wgpu::BufferUsages::empty();
        let pb = pool.upload(d, q, K, bytes_of(points), none);
        let cb = pool.upload(d, q, K, bytes_of(colors), none);
        let tb = pool.upload(d, q, K, bytes_of(triangles), none);
        let color = square_texture(
            d,
            "surface colour",
            n,
            FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let depth = square_texture(
            d,
            "surface depth",
            n,
            DEPTH,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let (cv, dv) = (
            color.create_view(&Default::default()),
            depth.create_view(&Default::default()),
        );
        let out = pool.take(
            d,
            K,
            (row_bytes * n) as u64,
            wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        );
        let group = bind(d, &self.surface.layout, K, &[&u, &pb, &cb, &tb]);
        let read = self.submit_and_read(
            K,
            |enc| {
                {
                    let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("surface"),
                        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                            view: &cv,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations {
                                load: wgpu::LoadOp::Clear(wgpu::Color::WHITE),
                                store: wgpu::StoreOp::Store,
                            },
                        })],
                        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                            view: &dv,
                            depth_ops: Some(wgpu::Operations {
                                load: wgpu::LoadOp::Clear(1.0),
                                store: wgpu::StoreOp::Discard,
                            }),
                            stencil_ops: None,
                        }),
                        timestamp_writes: None,
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    pass.set_pipeline(&self.surface.pipeline);
                    pass.set_bind_group(0, &group, &[]);
                    pass.draw(0..triangles.len() as u32, 0..1);
                }
                copy_square_texture(enc, &color, &out, n, row_bytes);
            },
            &[(&out, (row_bytes * n) as u64)],
        );
        pool.give([pb, cb, tb, out]);
        let read = read?;
        let stride = row_bytes as usize;
        Ok((0..n as usize)
            .flat_map(|y| {
                read[0][y * stride..y * stride + 4 * n as usize]
                    .chunks_exact(4)
                    .map(|p| [p[0], p[1], p[2], p[3]])
                    .collect::<Vec<_>>()
            })
            .collect())
    }
}
