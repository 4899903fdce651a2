//! A host application that owns its wgpu device (as a planning tool that renders with wgpu
//! would) and lends it to acetab: acetab compiles its kernels on the borrowed device, the host
//! keeps using the same device for its own work (inside `GlTurn`s, which on OpenGL keep its
//! threads and acetab's from waiting on each other past wgpu's limit), and both read back their
//! results.
//!
//! Run: cargo run --release --example embed

use acetab::engine::gpu::Gpu;
use acetab::engine::Kernels;
use acetab::pipeline::{reconstruct, ReconParams};
use acetab::report::accuracy;
use acetab::template::Template;
use std::process::ExitCode;

/// The host's own device: any adapter the environment allows (WGPU_BACKEND, WGPU_ADAPTER_NAME).
fn host_device() -> Result<(wgpu::Device, wgpu::Queue, String), String> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle().with_env());
    let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
        &instance, None,
    ))
    .map_err(|e| format!("no adapter: {e}"))?;
    let name = format!(
        "{} ({:?})",
        adapter.get_info().name,
        adapter.get_info().backend
    );
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("host application"),
        ..Default::default()
    }))
    .map_err(|e| format!("no device: {e}"))?;
    Ok((device, queue, name))
}

/// The host's own rendering: clear a 64 x 64 target to a colour and read one texel back.
fn host_render(device: &wgpu::Device, queue: &wgpu::Queue) -> Result<[u8; 4], String> {
    // On an OpenGL device the host's work takes turns with acetab's kernel calls, so that a host
    // thread never waits past wgpu's 6 s context lock behind one (None, and no waiting, on
    // Vulkan, Metal and DX12).
    let _turn = acetab::GlTurn::take(device);
    let tex = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("host target"),
        size: wgpu::Extent3d {
            width: 64,
            height: 64,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Unorm,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let view = tex.create_view(&Default::default());
    let buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("host readback"),
        size: 256 * 64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let _pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("host clear"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: 0.2,
                        g: 0.4,
                        b: 0.6,
                        a: 1.0,
                    }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
    }
    enc.copy_texture_to_buffer(
        tex.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(256),
                rows_per_image: Some(64),
            },
        },
        wgpu::Extent3d {
            width: 64,
            height: 64,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([enc.finish()]);
    buf.slice(..).map_async(wgpu::MapMode::Read, |_| {});
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| e.to_string())?;
    let view = buf
        .slice(..)
        .get_mapped_range()
        .map_err(|e| e.to_string())?;
    Ok([view[0], view[1], view[2], view[3]])
}

fn main() -> ExitCode {
    let run = || -> Result<(), String> {
        let (device, queue, name) = host_device()?;
        println!("host: device on {name}");
        println!(
            "host: rendered texel {:?} before acetab",
            host_render(&device, &queue)?
        );
        // Lend the device to acetab: its kernels compile once on it.
        let gpu = Gpu::new(&device, &queue).map_err(|e| e.to_string())?;
        let (truth, sim) = acetab::sim::phantom_case(3, 1).map_err(|e| e.to_string())?;
        let t = std::time::Instant::now();
        let template = Template::standard();
        let rec = reconstruct(
            &sim.input(&template),
            &ReconParams::default(),
            Kernels::Gpu(&gpu),
        )
        .map_err(|e| e.to_string())?;
        let acc = accuracy(&truth, &rec.mesh);
        println!(
            "acetab on the host's device: phantom (seed 1, level 3) MAE {:.3} mm, cup {:.2} mm (catalogue {:.0} mm, truth {:.2} mm), {:.2} s",
            acc.mae_mm,
            rec.sphere.diameter(),
            rec.cup.catalogue_mm,
            sim.truth_sphere.diameter(),
            t.elapsed().as_secs_f64()
        );
        // The host keeps using its device afterwards.
        println!(
            "host: rendered texel {:?} after acetab",
            host_render(&device, &queue)?
        );
        Ok(())
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("embed: {e}");
            ExitCode::FAILURE
        }
    }
}
