//! A small pool of storage buffers keyed by usage, reused across dispatches (sizes rounded up to
//! powers of two so that a sweep of similar batches allocates once).

use std::sync::Mutex;
use wgpu::util::DeviceExt;

#[derive(Default)]
pub(crate) struct BufferPool {
    free: Mutex<Vec<(wgpu::BufferUsages, u64, wgpu::Buffer)>>,
}

impl BufferPool {
    /// A buffer of at least `bytes` with `usage` (taken from the pool when one fits).
    pub(crate) fn take(
        &self,
        device: &wgpu::Device,
        label: &str,
        bytes: u64,
        usage: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        let size = bytes.max(16).next_power_of_two();
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(k) = free.iter().position(|(u, s, _)| *u == usage && *s == size) {
            return free.swap_remove(k).2;
        }
        drop(free);
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        })
    }

    /// Give buffers back for reuse (at most 64 kept).
    pub(crate) fn give(&self, bufs: impl IntoIterator<Item = wgpu::Buffer>) {
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        for b in bufs {
            if free.len() < 64 {
                free.push((b.usage(), b.size(), b));
            }
        }
    }

    /// A pooled storage buffer filled with `data`.
    pub(crate) fn upload(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        label: &str,
        data: &[u8],
        extra: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra;
        let buf = self.take(device, label, data.len() as u64, usage);
        if !data.is_empty() {
            queue.write_buffer(&buf, 0, data);
        }
        buf
    }
}

/// A uniform buffer (small, not pooled).
pub(crate) fn uniform(device: &wgpu::Device, label: &str, data: &[u8]) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: data,
        usage: wgpu::BufferUsages::UNIFORM,
    })
}

/// Bytes of `n` values of `T`, padded to 4 bytes.
pub(crate) fn bytes_of<T: bytemuck::Pod>(v: &[T]) -> &[u8] {
    bytemuck::cast_slice(v)
}

/// Bind-group layout entry: a storage buffer (read-only ones also visible to vertex shaders).
pub(crate) fn storage(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    // Writable storage is compute-only (vertex stages may not write without a feature).
    let visibility = if read_only {
        wgpu::ShaderStages::COMPUTE | wgpu::ShaderStages::VERTEX
    } else {
        wgpu::ShaderStages::COMPUTE
    };
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Bind-group layout entry: a uniform buffer (compute and vertex stages).
pub(crate) fn uniform_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    uniform_entry_in(
        binding,
        wgpu::ShaderStages::COMPUTE | wgpu::ShaderStages::VERTEX,
    )
}

/// Bind-group layout entry: a uniform buffer read by `stages`.
pub(crate) fn uniform_entry_in(
    binding: u32,
    stages: wgpu::ShaderStages,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: stages,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The layout every single-group kernel uses: the uniform at binding 0, then `read` read-only
/// storage buffers, then `write` writable ones (keep in the shaders' binding order).
pub(crate) fn kernel_entries(read: u32, write: u32) -> Vec<wgpu::BindGroupLayoutEntry> {
    std::iter::once(uniform_entry(0))
        .chain((1..=read).map(|b| storage(b, true)))
        .chain((read + 1..=read + write).map(|b| storage(b, false)))
        .collect()
}

/// A compute pipeline for `entry` of the named shader with one bind group of `entries`.
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    name: &'static str,
    entry: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> (wgpu::ComputePipeline, wgpu::BindGroupLayout) {
    let source = super::shader(name);
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(name),
        entries,
    });
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(name),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(name),
        layout: Some(&pl),
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    });
    (pipeline, layout)
}

/// Bind buffers 0..n in order.
pub(crate) fn bind(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    label: &str,
    bufs: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = bufs
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// Sentinel byte patterns written into output buffers before a dispatch, so that cells a
/// kernel fails to write stand out: NaN for floats, 0xA5A5A5A5 for integers.
pub(crate) const SENTINEL_F32: u32 = 0x7fc0_0000;
pub(crate) const SENTINEL_U32: u32 = 0xa5a5_a5a5;

pub(crate) fn fill(queue: &wgpu::Queue, buf: &wgpu::Buffer, words: usize, pattern: u32) {
    if words > 0 {
        queue.write_buffer(buf, 0, bytemuck::cast_slice(&vec![pattern; words]));
    }
}

/// A render pipeline drawing triangle lists from `vs_main` / `fs_main` of `module` (no vertex
/// buffers: the shaders read storage), both faces, into one `format` target, depth-tested
/// (less, written) when `depth` names a depth format.
pub(crate) fn render_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
    format: wgpu::TextureFormat,
    depth: Option<wgpu::TextureFormat>,
) -> wgpu::RenderPipeline {
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(&pl),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: depth.map(|format| wgpu::DepthStencilState {
            format,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A square `n` x `n` 2D texture.
pub(crate) fn square_texture(
    device: &wgpu::Device,
    label: &str,
    n: u32,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: n,
            height: n,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// Copy the square `n` x `n` `texture` into `buffer`, rows `row_bytes` apart (256-aligned).
pub(crate) fn copy_square_texture(
    enc: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    buffer: &wgpu::Buffer,
    n: u32,
    row_bytes: u32,
) {
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row_bytes),
                rows_per_image: Some(n),
            },
        },
        wgpu::Extent3d {
            width: n,
            height: n,
            depth_or_array_layers: 1,
        },
    );
}
