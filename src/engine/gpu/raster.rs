//! What the two raster kernels (the surface picture and the silhouette) share: the checks of a
//! square texture and of triangles, the render pass that draws triangles into one, and the rows
//! of its read-back without their copy padding.

use super::GpuError;

/// A square texture of `n` texels a side that the device can hold; `what` names it in the error.
pub(crate) fn check_square(
    lim: &wgpu::Limits,
    kernel: &'static str,
    what: &'static str,
    n: u32,
) -> Result<(), GpuError> {
    if n == 0 || n > lim.max_texture_dimension_2d {
        return Err(GpuError::TooLarge {
            kernel,
            what,
            value: n as u64,
            limit: lim.max_texture_dimension_2d as u64,
        });
    }
    Ok(())
}

/// Triangles as `kernel` draws them: a positive multiple of 3 corners, each one of the
/// `vertex_count` vertices.
pub(crate) fn check_triangles(
    kernel: &'static str,
    vertex_count: usize,
    triangles: &[u32],
) -> Result<(), GpuError> {
    let input = |message: String| GpuError::Input { kernel, message };
    if triangles.is_empty() || !triangles.len().is_multiple_of(3) {
        return Err(input(format!(
            "{} triangle corners is not a positive multiple of 3",
            triangles.len()
        )));
    }
    if let Some(&bad) = triangles.iter().find(|&&i| i as usize >= vertex_count) {
        return Err(input(format!(
            "triangle corner {bad} is not one of the {vertex_count} vertices"
        )));
    }
    Ok(())
}

/// Where a render pass draws: a colour target cleared to `clear` and, where given, a depth
/// target cleared to 1 and not kept.
pub(crate) struct Targets<'a> {
    pub(crate) color: &'a wgpu::TextureView,
    pub(crate) clear: wgpu::Color,
    pub(crate) depth: Option<&'a wgpu::TextureView>,
}

/// A render pass labelled `label` that draws `corners` triangle corners with `pipeline` and its
/// bind `group` into `targets`.
pub(crate) fn draw_triangles(
    enc: &mut wgpu::CommandEncoder,
    label: &str,
    targets: &Targets<'_>,
    pipeline: &wgpu::RenderPipeline,
    group: &wgpu::BindGroup,
    corners: u32,
) {
    let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: targets.color,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(targets.clear),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: targets.depth.map(|view| {
            wgpu::RenderPassDepthStencilAttachment {
                view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, group, &[]);
    pass.draw(0..corners, 0..1);
}

/// Bytes between the rows of an `n`-wide texture of 4-byte texels copied to a buffer (a copy's
/// rows are 256-byte aligned).
pub(crate) fn padded_row_bytes(n: u32) -> u32 {
    (n * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
}

/// The `n` x `n` 4-byte texels of a square texture read back as `read`, rows `row_bytes` apart:
/// row by row from the top, without the rows' padding.
pub(crate) fn unpadded<T: bytemuck::Pod>(read: &[u8], n: u32, row_bytes: u32) -> Vec<T> {
    let (n, stride) = (n as usize, row_bytes as usize);
    let rows: Vec<u8> = (0..n)
        .flat_map(|y| &read[y * stride..y * stride + 4 * n])
        .copied()
        .collect();
    bytemuck::pod_collect_to_vec(&rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangles_and_squares_are_checked_and_padded_rows_unpadded() {
        let lim = wgpu::Limits::downlevel_defaults();
        assert!(check_triangles("k", 3, &[0, 1, 2, 2, 1, 0]).is_ok());
        assert!(check_square(&lim, "k", "panel size", 64).is_ok());
        // Companions: each wrong input refused, naming what is wrong.
        let msg = |r: Result<(), GpuError>| r.unwrap_err().to_string();
        assert!(msg(check_triangles("k", 3, &[0, 1])).contains("2 triangle corners"));
        assert!(msg(check_triangles("k", 3, &[])).contains("0 triangle corners"));
        assert!(msg(check_triangles("k", 3, &[0, 1, 3])).contains("corner 3 is not one of the 3"));
        assert!(msg(check_square(&lim, "k", "panel size", 0)).contains("panel size is 0"));
        let big = lim.max_texture_dimension_2d + 1;
        assert!(msg(check_square(&lim, "k", "texture size", big)).contains("texture size"));
        // Two rows of two texels, each row padded to 256 bytes: the padding is dropped.
        let row = padded_row_bytes(2);
        assert_eq!(row, 256);
        let mut read = vec![0xEEu8; 2 * row as usize];
        read[..8].copy_from_slice(&[1, 0, 0, 0, 2, 0, 0, 0]);
        read[256..264].copy_from_slice(&[3, 0, 0, 0, 4, 0, 0, 0]);
        assert_eq!(unpadded::<u32>(&read, 2, row), vec![1, 2, 3, 4]);
        let px = unpadded::<[u8; 4]>(&read, 2, row);
        assert_eq!(
            px,
            vec![[1, 0, 0, 0], [2, 0, 0, 0], [3, 0, 0, 0], [4, 0, 0, 0]]
        );
        // Companion: read as if unpadded, the padding shows.
        assert_ne!(unpadded::<u32>(&read, 2, 8)[2], 3);
    }
}
