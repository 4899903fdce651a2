// Perspective projection of a batch of meshes into a batch of views, p ~ K (R P + t), with the
// depth z of the point in the camera frame. Points at depth <= MIN_DEPTH are marked invalid.
// CPU twin: src/cpu/project.rs. Keep `Params` and `View` in sync with src/gpu/project.rs.

struct Params {
    vertex_count: u32,  // V, per mesh
    mesh_count: u32,    // B
    view_count: u32,    // C
    _pad: u32,
}

struct View {
    r0: vec4<f32>,  // R row 0, t.x
    r1: vec4<f32>,  // R row 1, t.y
    r2: vec4<f32>,  // R row 2, t.z
    k: vec4<f32>,   // fx, fy, cx, cy
}

const MIN_DEPTH: f32 = 1e-3;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> vertices: array<vec4<f32>>;  // B * V
@group(0) @binding(2) var<storage, read> views: array<View>;          // C
// (B * C + view) * V + vertex: u, v (pixels), depth (mm), 1 if in front of the source else 0.
@group(0) @binding(3) var<storage, read_write> projected: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let bc = gid.y;  // mesh * C + view
    if (i >= params.vertex_count || bc >= params.mesh_count * params.view_count) {
        return;
    }
    let b = bc / params.view_count;
    let c = bc % params.view_count;
    let p = vertices[b * params.vertex_count + i].xyz;
    let view = views[c];
    let x = dot(view.r0.xyz, p) + view.r0.w;
    let y = dot(view.r1.xyz, p) + view.r1.w;
    let z = dot(view.r2.xyz, p) + view.r2.w;
    var out = vec4<f32>(0.0, 0.0, z, 0.0);
    if (z > MIN_DEPTH) {
        out = vec4<f32>(view.k.x * x / z + view.k.z, view.k.y * y / z + view.k.w, z, 1.0);
    }
    projected[bc * params.vertex_count + i] = out;
}
