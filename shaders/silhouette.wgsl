// Rasterised silhouette of a projected mesh in one view, in two passes.
// 1. Render pass (vs_main / fs_main): every triangle is drawn into an R32Uint id texture that
//    covers the image window [x0, x0 + size * scale) x [y0, y0 + size * scale); each covered
//    texel holds 1 + the id of the triangle corner nearest to its centre (0 = background).
// 2. Compute pass (edges): a texel is on the silhouette when it is covered and one of its four
//    neighbours (or the texture border) is not; its vertex id + 1 goes to the mask, 0 elsewhere.
// CPU twin: src/cpu/silhouette.rs. Keep `Window` in sync with `SilhouetteWindow` in
// src/gpu/silhouette.rs.

struct Window {
    x0: f32,     // image x of the texture's left edge, pixels
    y0: f32,     // image y of the texture's top edge, pixels
    scale: f32,  // image pixels per texel
    size: u32,   // texture width = height, texels
}

@group(0) @binding(0) var<uniform> window: Window;
// Projected vertices (u, v, depth, valid), as written by project.wgsl.
@group(0) @binding(1) var<storage, read> projected: array<vec4<f32>>;
// Triangle corner vertex ids, 3 per triangle.
@group(0) @binding(2) var<storage, read> triangles: array<u32>;

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(linear) bary: vec3<f32>,
    @location(1) @interpolate(flat) ids: vec3<u32>,
}

@vertex
fn vs_main(@builtin(vertex_index) vi: u32) -> VsOut {
    let tri = vi / 3u;
    let corner = vi % 3u;
    let ids = vec3<u32>(triangles[3u * tri], triangles[3u * tri + 1u], triangles[3u * tri + 2u]);
    let p = projected[ids[corner]];
    let extent = window.scale * f32(window.size);
    let nx = (p.x - window.x0) / extent * 2.0 - 1.0;
    let ny = 1.0 - (p.y - window.y0) / extent * 2.0;
    var out: VsOut;
    // A corner behind the source drops the triangle (w = 0 would divide; push it outside).
    if (p.w > 0.5) {
        out.position = vec4<f32>(nx, ny, 0.5, 1.0);
    } else {
        out.position = vec4<f32>(2.0, 2.0, 2.0, 1.0);
    }
    var bary = vec3<f32>(0.0, 0.0, 0.0);
    bary[corner] = 1.0;
    out.bary = bary;
    out.ids = ids;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) u32 {
    var k = 0u;
    if (in.bary.y > in.bary[k]) {
        k = 1u;
    }
    if (in.bary.z > in.bary[k]) {
        k = 2u;
    }
    return in.ids[k] + 1u;
}

@group(0) @binding(0) var<uniform> edge_window: Window;
@group(0) @binding(1) var ids_texture: texture_2d<u32>;
// One u32 per texel, row-major: vertex id + 1 on the silhouette, 0 elsewhere.
@group(0) @binding(2) var<storage, read_write> mask: array<u32>;

fn covered(x: i32, y: i32) -> bool {
    let n = i32(edge_window.size);
    if (x < 0 || y < 0 || x >= n || y >= n) {
        return false;
    }
    return textureLoad(ids_texture, vec2<i32>(x, y), 0).x != 0u;
}

@compute @workgroup_size(8, 8)
fn edges(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = edge_window.size;
    if (gid.x >= n || gid.y >= n) {
        return;
    }
    let x = i32(gid.x);
    let y = i32(gid.y);
    let id = textureLoad(ids_texture, vec2<i32>(x, y), 0).x;
    var out = 0u;
    if (id != 0u && !(covered(x - 1, y) && covered(x + 1, y) && covered(x, y - 1) && covered(x, y + 1))) {
        out = id;
    }
    mask[gid.y * n + gid.x] = out;
}
