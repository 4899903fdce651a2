//! GPU module of `shaders/silhouette.wgsl` (CPU twin: `crate::engine::cpu::silhouette`): a render pass
//! draws the projected mesh into an R32Uint id texture, then the `edges` compute pass marks the
//! silhouette texels with their vertex ids; the host traces them into an ordered loop.

use super::buffers::{
    bind, bytes_of, copy_square_texture, fill, render_pipeline, square_texture, storage, uniform,
    uniform_entry, SENTINEL_U32,
};
use super::raster::{
    check_square, check_triangles, draw_triangles, padded_row_bytes, unpadded, Targets,
};
use super::{Gpu, GpuError};
use crate::engine::cpu::project::ViewRows;
use crate::engine::cpu::silhouette::{trace, Window};

/// Keep in sync with `Window` in shaders/silhouette.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SilhouetteWindow {
    /// Image x of the texture's top-left corner, pixels.
    pub x0: f32,
    /// Image y of the texture's top-left corner, pixels.
    pub y0: f32,
    /// Image pixels per texel.
    pub scale: f32,
    /// Texels per side.
    pub size: u32,
}

impl From<&Window> for SilhouetteWindow {
    fn from(w: &Window) -> Self {
        SilhouetteWindow {
            x0: w.x0,
            y0: w.y0,
            scale: w.scale,
            size: w.size,
        }
    }
}

pub(crate) struct SilhouetteKernel {
    raster: wgpu::RenderPipeline,
    raster_layout: wgpu::BindGroupLayout,
    edges: wgpu::ComputePipeline,
    edges_layout: wgpu::BindGroupLayout,
}

const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;

impl SilhouetteKernel {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        let source = super::shader("silhouette");
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("silhouette"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let raster_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("silhouette raster"),
            entries: &[uniform_entry(0), storage(1, true), storage(2, true)],
        });
        let raster = render_pipeline(
            device,
            "silhouette raster",
            &module,
            &raster_layout,
            FORMAT,
            None,
        );
        let edges_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("silhouette edges"),
            entries: &[
                uniform_entry(0),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                storage(2, false),
            ],
        });
        let epl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("silhouette edges"),
            bind_group_layouts: &[Some(&edges_layout)],
            immediate_size: 0,
        });
        let edges = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("silhouette edges"),
            layout: Some(&epl),
            module: &module,
            entry_point: Some("edges"),
            compilation_options: Default::default(),
            cache: None,
        });
        SilhouetteKernel {
            raster,
            raster_layout,
            edges,
            edges_layout,
        }
    }
}

/// What one silhouette run returns: the id image (render pass), the mask (edge kernel) and the
/// traced loop of vertex ids.
#[derive(Clone, Debug, PartialEq)]
pub struct Silhouette {
    /// Where the texture lies in the image.
    pub window: Window,
    /// Per texel, the id of the triangle drawn there (u32::MAX for none).
    pub ids: Vec<u32>,
    /// Per texel, 1 on the silhouette's edge.
    pub mask: Vec<u32>,
    /// The traced loop of vertex ids.
    pub contour: Vec<u32>,
}

impl Gpu<'_> {
    /// Rasterise already projected vertices (u, v, depth, valid) of one mesh with its triangles.
    pub fn silhouette_of_projected(
        &self,
        projected: &[[f32; 4]],
        triangles: &[u32],
        window: &Window,
    ) -> Result<Silhouette, GpuError> {
        let _turn = self.turn();
        const K: &str = "silhouette";
        let pbuf = self.pool.upload(
            self.device,
            self.queue,
            K,
            bytes_of(projected),
            wgpu::BufferUsages::empty(),
        );
        let r = self.silhouette_from_buffer(&pbuf, projected.len(), triangles, window);
        self.pool.give([pbuf]);
        r
    }

    /// Project one mesh into one view on the GPU and rasterise its silhouette there, with a
    /// `size` x `size` texture around the projection.
    pub fn silhouette(
        &self,
        vertices: &[[f32; 4]],
        triangles: &[u32],
        view: &ViewRows,
        size: u32,
    ) -> Result<Silhouette, GpuError> {
        let _turn = self.turn();
        let empty = GpuError::Input {
            kernel: "silhouette",
            message: "no vertex lies in front of the source".into(),
        };
        // The projections stay on the device for the raster pass; they are read back once, for
        // the window around them.
        let (buf, bytes) = self
            .project_to_buffer(vertices, vertices.len(), std::slice::from_ref(view))?
            .ok_or(empty.clone())?;
        let result = self
            .submit_and_read("project", |_| {}, &[(&buf, bytes)])
            .and_then(|read| {
                let projected: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&read[0]);
                let window = Window::around(&projected, size).ok_or(empty)?;
                self.silhouette_from_buffer(&buf, projected.len(), triangles, &window)
            });
        self.pool.give([buf]);
        result
    }

    fn silhouette_from_buffer(
        &self,
        projected: &wgpu::Buffer,
        vertex_count: usize,
        triangles: &[u32],
        window: &Window,
    ) -> Result<Silhouette, GpuError> {
        const K: &str = "silhouette";
        check_input(&self.device.limits(), window, vertex_count, triangles)?;
        let n = window.size;
        let texels = (n as usize) * (n as usize);
        let row_bytes = padded_row_bytes(n);
        let (d, q, pool) = (self.device, self.queue, &self.pool);
        let w = SilhouetteWindow::from(window);
        let u = uniform(d, K, bytemuck::bytes_of(&w));
        let tb = pool.upload(d, q, K, bytes_of(triangles), wgpu::BufferUsages::empty());
        let texture = square_texture(
            d,
            "silhouette ids",
            n,
            FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let view = texture.create_view(&Default::default());
        let mask = pool.take(
            d,
            K,
            (texels * 4) as u64,
            wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        );
        fill(q, &mask, texels, SENTINEL_U32);
        let ids_buf = pool.take(
            d,
            K,
            (row_bytes * n) as u64,
            wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        );
        let raster_group = bind(
            d,
            &self.silhouette.raster_layout,
            "silhouette raster",
            &[&u, projected, &tb],
        );
        let edges_group = edges_bind_group(d, &self.silhouette.edges_layout, &u, &view, &mask);
        let targets = Targets {
            color: &view,
            clear: wgpu::Color::TRANSPARENT,
            depth: None,
        };
        let sil = &self.silhouette;
        let read = self.submit_and_read(
            K,
            |enc| {
                let corners = triangles.len() as u32;
                draw_triangles(
                    enc,
                    "silhouette raster",
                    &targets,
                    &sil.raster,
                    &raster_group,
                    corners,
                );
                {
                    let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                        label: Some("silhouette edges"),
                        timestamp_writes: None,
                    });
                    pass.set_pipeline(&sil.edges);
                    pass.set_bind_group(0, &edges_group, &[]);
                    pass.dispatch_workgroups(n.div_ceil(8), n.div_ceil(8), 1);
                }
                copy_square_texture(enc, &texture, &ids_buf, n, row_bytes);
            },
            &[
                (&mask, (texels * 4) as u64),
                (&ids_buf, (row_bytes * n) as u64),
            ],
        );
        pool.give([tb, mask, ids_buf]);
        let read = read?;
        let mask: Vec<u32> = bytemuck::pod_collect_to_vec(&read[0]);
        let ids: Vec<u32> = unpadded(&read[1], n, row_bytes);
        let contour = trace(&mask, n);
        Ok(Silhouette {
            window: *window,
            ids,
            mask,
            contour,
        })
    }
}

/// The silhouette's input: a window the device's textures can hold, and triangles (a positive
/// multiple of 3 corners) whose corners are among the `vertex_count` projected vertices.
fn check_input(
    lim: &wgpu::Limits,
    window: &Window,
    vertex_count: usize,
    triangles: &[u32],
) -> Result<(), GpuError> {
    const K: &str = "silhouette";
    check_square(lim, K, "texture size", window.size)?;
    check_triangles(K, vertex_count, triangles)
}

/// The edge pass's bindings: the window's uniform `u`, the raster's ids `view`, the `mask` it
/// writes.
fn edges_bind_group(
    d: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    u: &wgpu::Buffer,
    view: &wgpu::TextureView,
    mask: &wgpu::Buffer,
) -> wgpu::BindGroup {
    d.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("silhouette edges"),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: u.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(view),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: mask.as_entire_binding(),
            },
        ],
    })
}
