//! GPU module of `shaders/surface.wgsl` (CPU twin: `crate::engine::cpu::surface`): one render
//! pass draws the surface, depth-tested, into an RGBA8 panel that is read back.

use super::buffers::{
    bind, bytes_of, copy_square_texture, render_pipeline, square_texture, storage, uniform,
    uniform_entry_in,
};
use super::raster::{
    check_square, check_triangles, draw_triangles, padded_row_bytes, unpadded, Targets,
};
use super::{Gpu, GpuError};
pub use crate::engine::cpu::surface::SurfaceView;

pub(crate) struct SurfaceKernel {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
}

const K: &str = "surface";
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
        let n = view.size() as u32;
        check_input(&self.device.limits(), n, points, colors, triangles)?;
        let (d, q, pool) = (self.device, self.queue, &self.pool);
        let row_bytes = padded_row_bytes(n);
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
        let targets = Targets {
            color: &cv,
            clear: wgpu::Color::WHITE,
            depth: Some(&dv),
        };
        let read = self.submit_and_read(
            K,
            |enc| {
                let corners = triangles.len() as u32;
                draw_triangles(enc, K, &targets, &self.surface.pipeline, &group, corners);
                copy_square_texture(enc, &color, &out, n, row_bytes);
            },
            &[(&out, (row_bytes * n) as u64)],
        );
        pool.give([pb, cb, tb, out]);
        Ok(unpadded(&read?[0], n, row_bytes))
    }
}

/// The picture's input: a panel the device's textures can hold, one colour a vertex and at least
/// one vertex, and triangles among the vertices.
fn check_input(
    lim: &wgpu::Limits,
    n: u32,
    points: &[[f32; 4]],
    colors: &[[f32; 4]],
    triangles: &[u32],
) -> Result<(), GpuError> {
    check_square(lim, K, "panel size", n)?;
    if points.is_empty() || colors.len() != points.len() {
        return Err(GpuError::Input {
            kernel: K,
            message: format!(
                "{} vertices and {} colours: one colour a vertex, at least one vertex",
                points.len(),
                colors.len()
            ),
        });
    }
    check_triangles(K, points.len(), triangles)
}
