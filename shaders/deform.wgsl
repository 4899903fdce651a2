// Embedded-deformation vertex update for a batch of meshes (Sumner 2007):
//   v_i = sum_k w_ik (A_j (P_i - g_j) + g_j + t_j),  j = node[i, k], over the m nearest nodes.
// With the weights summing to one this is v_i = P_i + sum_k w_ik ((A_j - I)(P_i - g_j) + t_j);
// the kernel returns that displacement, from the rows of A_j - I, so that f32 only carries the
// (small) motion and the host adds it to the f64 rest position.
// CPU twin: src/cpu/deform.rs. Keep `Params` in sync with `DeformParams` in src/gpu/deform.rs.

struct Params {
    vertex_count: u32,  // V, per mesh
    node_count: u32,    // J, per mesh
    neighbours: u32,    // m, weights per vertex
    mesh_count: u32,    // B
}

@group(0) @binding(0) var<uniform> params: Params;
// Rest positions, B * V, xyz (w unused).
@group(0) @binding(1) var<storage, read> rest: array<vec4<f32>>;
// Node positions, B * J, xyz.
@group(0) @binding(2) var<storage, read> nodes: array<vec4<f32>>;
// Per node three rows (row r of A - I, t_r): B * J * 3.
@group(0) @binding(3) var<storage, read> affine: array<vec4<f32>>;
// Per vertex m (node index within its mesh, weight) pairs: B * V * m.
@group(0) @binding(4) var<storage, read> node_index: array<u32>;
@group(0) @binding(5) var<storage, read> weight: array<f32>;
// Output displacement, B * V, xyz and w = 1.
@group(0) @binding(6) var<storage, read_write> deformed: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let b = gid.y;
    if (i >= params.vertex_count || b >= params.mesh_count) {
        return;
    }
    let v = b * params.vertex_count + i;
    let p = rest[v].xyz;
    var acc = vec3<f32>(0.0, 0.0, 0.0);
    for (var k = 0u; k < params.neighbours; k = k + 1u) {
        let e = v * params.neighbours + k;
        let j = b * params.node_count + node_index[e];
        let g = nodes[j].xyz;
        let d = p - g;
        let r0 = affine[3u * j];
        let r1 = affine[3u * j + 1u];
        let r2 = affine[3u * j + 2u];
        let moved = vec3<f32>(
            dot(r0.xyz, d) + r0.w,
            dot(r1.xyz, d) + r1.w,
            dot(r2.xyz, d) + r2.w,
        );
        acc = acc + weight[e] * moved;
    }
    deformed[v] = vec4<f32>(acc, 1.0);
}
