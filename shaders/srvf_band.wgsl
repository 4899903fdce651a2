// The banded SRVF DP of an alignment: one problem per workgroup, rows in order (every step
// (a, b) reaches back to an earlier row), the workgroup's threads sharing a row's band cells,
// with a storage barrier between rows. Cell (i, j) keeps the cheapest path cost from (0, 0) and
// the index of the step that reached it (the back-pointer); the traceback runs on the host.
//   cost of step (a, b) into (i, j) from (k, l) = (i - a, j - b):
//     sum_{r < a} |q1[k + r] - sqrt(b / a) q2(l + r b / a)|^2
//     + weight * sum_{r < a} |pa[k + r] - pb(l + r b / a)|^2,  q2 and pb interpolated linearly.
// The predecessor must lie in row k's band. CPU twin: src/engine/cpu/srvf_band.rs (same sums in
// the same order, so the back-pointers agree exactly). Keep `Params`, `Problem`, `Row`, `Step`
// and `Tap` in sync with src/engine/gpu/srvf_band.rs and the twin.

struct Params {
    problems: u32,
    step_count: u32,
    _pad0: u32,
    _pad1: u32,
}

struct Problem {
    n: u32,
    rows: u32,    // first row in `rows`
    cells: u32,   // first cell in the tables
    curve: u32,   // first sample in `curves` and `positions`
    weight: f32,  // position term (0: none)
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

struct Row {
    lo: u32,
    hi: u32,
    offset: u32,  // the row's first cell, from the problem's first
    _pad: u32,
}

struct Step {
    a: u32,
    b: u32,
    sqrt_slope: f32,
    tap_start: u32,
}

struct Tap {
    offset: u32,
    frac: f32,
}

const UNREACHED: f32 = 1e30;
const NO_STEP: u32 = 0xffffffffu;
const WG: u32 = 32u;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> problems: array<Problem>;
@group(0) @binding(2) var<storage, read> rows: array<Row>;
@group(0) @binding(3) var<storage, read> curves: array<vec4<f32>>;     // q1.xy, q2.xy
@group(0) @binding(4) var<storage, read> positions: array<vec4<f32>>;  // pa.xy, pb.xy
@group(0) @binding(5) var<storage, read> steps: array<Step>;
@group(0) @binding(6) var<storage, read> taps: array<Tap>;
@group(0) @binding(7) var<storage, read_write> cost: array<f32>;
@group(0) @binding(8) var<storage, read_write> back: array<u32>;

// The best (cost, step) of cell (i, j) of problem `pr` over the steps, in order.
fn relax(pr: Problem, i: u32, j: u32) -> vec2<u32> {
    let qb = pr.curve;
    var best = UNREACHED;
    var arg = NO_STEP;
    for (var s = 0u; s < params.step_count; s = s + 1u) {
        let st = steps[s];
        if (st.a > i || st.b > j) {
            continue;
        }
        let k = i - st.a;
        let l = j - st.b;
        let rk = rows[pr.rows + k];
        if (l < rk.lo || l > rk.hi) {
            continue;
        }
        let prev = cost[pr.cells + rk.offset + l - rk.lo];
        var c = 0.0;
        for (var r = 0u; r < st.a; r = r + 1u) {
            let tap = taps[st.tap_start + r];
            let p = l + tap.offset;
            let q = curves[qb + p];
            var x = q.z * st.sqrt_slope;
            var y = q.w * st.sqrt_slope;
            if (tap.frac != 0.0) {
                let q_next = curves[qb + p + 1u];
                x = (q.z + (q_next.z - q.z) * tap.frac) * st.sqrt_slope;
                y = (q.w + (q_next.w - q.w) * tap.frac) * st.sqrt_slope;
            }
            let a = curves[qb + k + r];
            let dx = a.x - x;
            let dy = a.y - y;
            c = c + (dx * dx + dy * dy);
        }
        if (pr.weight > 0.0) {
            var e = 0.0;
            for (var r = 0u; r < st.a; r = r + 1u) {
                let tap = taps[st.tap_start + r];
                let p = l + tap.offset;
                let p1 = min(p + 1u, pr.n - 1u);
                let b0 = positions[qb + p];
                let b1 = positions[qb + p1];
                let x = b0.z + (b1.z - b0.z) * tap.frac;
                let y = b0.w + (b1.w - b0.w) * tap.frac;
                let a = positions[qb + k + r];
                let dx = a.x - x;
                let dy = a.y - y;
                e = e + (dx * dx + dy * dy);
            }
            c = c + pr.weight * e;
        }
        let v = prev + c;
        if (v < best) {
            best = v;
            arg = s;
        }
    }
    return vec2<u32>(bitcast<u32>(best), arg);
}

@compute @workgroup_size(32)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let index = wg.x;
    if (index >= params.problems) {
        return;
    }
    let pr = problems[index];
    // Every cell unreached, then the start.
    let last = rows[pr.rows + pr.n - 1u];
    let cells = last.offset + last.hi + 1u - last.lo;
    for (var c = lid; c < cells; c = c + WG) {
        cost[pr.cells + c] = UNREACHED;
        back[pr.cells + c] = NO_STEP;
    }
    storageBarrier();
    if (lid == 0u) {
        cost[pr.cells] = 0.0;
    }
    storageBarrier();
    for (var i = 1u; i < pr.n; i = i + 1u) {
        let row = rows[pr.rows + i];
        for (var j = row.lo + lid; j <= row.hi; j = j + WG) {
            let r = relax(pr, i, j);
            let at = pr.cells + row.offset + j - row.lo;
            cost[at] = bitcast<f32>(r.x);
            back[at] = r.y;
        }
        storageBarrier();
    }
}
