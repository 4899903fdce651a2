// Batched SRVF dynamic-programming tables: one alignment problem per workgroup. The cells of the
// n x n grid are filled by anti-diagonals (every step (a, b) of the coprime set reaches back to
// an earlier diagonal), the workgroup's threads sharing each diagonal, with a storage barrier
// between diagonals. Cell (i, j) keeps the cheapest path cost from (0, 0) and the index of the
// step that reached it (the back-pointer); the traceback runs on the host.
//   edge cost of step (a, b) into (i, j) from (k, l) = (i - a, j - b):
//     sum_{r < a} |q1[k + r] - sqrt(b / a) q2(l + r b / a)|^2,  q2 interpolated linearly.
// CPU twin: src/cpu/srvf_dp.rs (same loops, same operation order, so the back-pointers agree
// exactly). Keep `Params`, `Step` and `Tap` in sync with src/gpu/srvf_dp.rs.

struct Params {
    samples: u32,    // n, per curve
    problems: u32,   // P
    step_count: u32,
    _pad: u32,
}

struct Step {
    a: u32,
    b: u32,
    sqrt_slope: f32,
    tap_start: u32,  // first of this step's `a` taps
}

struct Tap {
    offset: u32,  // integer part of r b / a
    frac: f32,    // fractional part
}

const UNREACHED: f32 = 1e30;
const NO_STEP: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> q1: array<vec2<f32>>;  // P * n
@group(0) @binding(2) var<storage, read> q2: array<vec2<f32>>;  // P * n
@group(0) @binding(3) var<storage, read> steps: array<Step>;
@group(0) @binding(4) var<storage, read> taps: array<Tap>;
@group(0) @binding(5) var<storage, read_write> cost: array<f32>;  // P * n * n
@group(0) @binding(6) var<storage, read_write> back: array<u32>;  // P * n * n

const WG: u32 = 64u;

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let problem = wg.x;
    let n = params.samples;
    if (problem >= params.problems) {
        return;
    }
    let base = problem * n * n;
    let qb = problem * n;
    // Row 0 and column 0 are unreachable except the start.
    for (var c = lid; c < n; c = c + WG) {
        cost[base + c] = UNREACHED;
        back[base + c] = NO_STEP;
        cost[base + c * n] = UNREACHED;
        back[base + c * n] = NO_STEP;
    }
    storageBarrier();
    if (lid == 0u) {
        cost[base] = 0.0;
    }
    storageBarrier();
    for (var d = 2u; d <= 2u * (n - 1u); d = d + 1u) {
        let i_lo = max(1u, d - min(d, n - 1u));
        let i_hi = min(n - 1u, d - 1u);
        for (var i = i_lo + lid; i <= i_hi; i = i + WG) {
            let j = d - i;
            var best = UNREACHED;
            var arg = NO_STEP;
            for (var s = 0u; s < params.step_count; s = s + 1u) {
                let st = steps[s];
                if (st.a > i || st.b > j) {
                    continue;
                }
                let k = i - st.a;
                let l = j - st.b;
                let prev = cost[base + k * n + l];
                if (prev >= UNREACHED) {
                    continue;
                }
                var c = 0.0;
                for (var r = 0u; r < st.a; r = r + 1u) {
                    let tap = taps[st.tap_start + r];
                    let p = l + tap.offset;
                    var qx = q2[qb + p].x;
                    var qy = q2[qb + p].y;
                    if (tap.frac != 0.0) {
                        qx = qx + (q2[qb + p + 1u].x - qx) * tap.frac;
                        qy = qy + (q2[qb + p + 1u].y - qy) * tap.frac;
                    }
                    let dx = q1[qb + k + r].x - qx * st.sqrt_slope;
                    let dy = q1[qb + k + r].y - qy * st.sqrt_slope;
                    c = c + dx * dx;
                    c = c + dy * dy;
                }
                let total = prev + c;
                if (total < best) {
                    best = total;
                    arg = s;
                }
            }
            cost[base + i * n + j] = best;
            back[base + i * n + j] = arg;
        }
        storageBarrier();
    }
}
