// The result's picture (reconstruction.png): one square panel of the surface seen along a
// direction, orthographic. Every triangle is drawn depth-tested with its corners' colours
// (interpolated) shaded by how squarely the triangle faces the viewer: 0.45 + 0.55 |n . w|.
// CPU twin: src/engine/cpu/surface.rs. Keep `View` in sync with `SurfaceView` in
// src/engine/gpu/surface.rs.

struct View {
    u: vec4<f32>,  // xyz: panel right, pixels per mm; w: the centre's x in the panel, pixels
    v: vec4<f32>,  // xyz: panel up, pixels per mm; w: the centre's y in the panel, pixels
    w: vec4<f32>,  // xyz: the viewing direction (unit, away from the viewer); w: 1 / depth range, per mm
    c: vec4<f32>,  // xyz: the centre, mm; w: the panel's size, pixels
}

@group(0) @binding(0) var<uniform> view: View;
// Vertices (x, y, z, unused), mm.
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
// Vertex colours (r, g, b, unused), 0..1.
@group(0) @binding(2) var<storage, read> colors: array<vec4<f32>>;
// Triangle corner vertex ids, 3 per triangle.
@group(0) @binding(3) var<storage, read> triangles: array<u32>;

struct VsOut {
    @builtin(position) position: vec4<f32>,
    @location(0) color: vec3<f32>,
    @location(1) world: vec3<f32>,
}

@vertex
fn vs_main(@builtin(vertex_index) vi: u32) -> VsOut {
    let id = triangles[vi];
    let p = points[id].xyz;
    let d = p - view.c.xyz;
    let size = view.c.w;
    let px = view.u.w + dot(d, view.u.xyz);
    let py = view.v.w - dot(d, view.v.xyz);
    let depth = clamp(0.5 + 0.5 * dot(d, view.w.xyz) * view.w.w, 0.0, 1.0);
    var out: VsOut;
    out.position = vec4<f32>(px / size * 2.0 - 1.0, 1.0 - py / size * 2.0, depth, 1.0);
    out.color = colors[id].xyz;
    out.world = p;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let n = cross(dpdx(in.world), dpdy(in.world));
    let len = length(n);
    var facing = 1.0;
    if (len > 0.0) {
        facing = abs(dot(n / len, view.w.xyz));
    }
    return vec4<f32>(in.color * (0.45 + 0.55 * facing), 1.0);
}
