//! The host's banded DP: the cost and back-pointer tables of `dp::dp_in_band`, row by row (every
//! step's candidates over a run of cells at once, fused with the comparison), built for the
//! baseline x86-64 and for AVX2 and chosen at run time, the same tables to the bit either way.
//! The reference every engine's banded DP (`BandSolver`, the GPU's `srvf_band`) is tested
//! against; its own oracle is the cell-by-cell loop in the tests.

use super::band::{band_rows, prepare, trace_band, PreparedStep};
use super::curve::Anchor;
use nalgebra::Vector2;

/// The working memory of a banded DP, kept between DPs: the per-step tap tables (all steps in
/// one buffer, step `si` from `starts[si]`), the candidate rows and the band's row layout.
#[derive(Default)]
pub(super) struct Scratch {
    prepared: Vec<PreparedStep>,
    prepared_for: Vec<(usize, usize)>,
    starts: Vec<usize>,
    /// The position tables' starts (the same layout as `starts`).
    pstarts: Vec<usize>,
    wx: Vec<f64>,
    wy: Vec<f64>,
    px: Vec<f64>,
    py: Vec<f64>,
    x1: Vec<f64>,
    y1: Vec<f64>,
    x2: Vec<f64>,
    y2: Vec<f64>,
    ax: Vec<f64>,
    ay: Vec<f64>,
    bx: Vec<f64>,
    by: Vec<f64>,
    cand: Vec<f64>,
    near: Vec<f64>,
}

/// What the tap tables hold: q2 interpolated at the tap and times the step's sqrt slope (the
/// SRVF part), or B's positions interpolated at the tap (the position term), x and y apart.
enum TapSource<'a> {
    Scaled(&'a [f64], &'a [f64]),
    Positions(&'a [f64], &'a [f64]),
}

/// Fill `starts`, and `x`, `y` with the source's value at every tap (p, u) of every step, for
/// each start column l < n - b (the tap's sample is p = l + its offset), tap by tap: the DP's
/// per-step tables, all steps in one buffer. One tight loop per tap (it vectorises), each value
/// computed as the per-value expressions below always were.
#[inline(always)]
fn fill_taps(
    prepared: &[PreparedStep],
    n: usize,
    starts: &mut Vec<usize>,
    x: &mut Vec<f64>,
    y: &mut Vec<f64>,
    source: TapSource,
) {
    starts.clear();
    let total: usize = prepared
        .iter()
        .map(|st| st.taps.len() * n.saturating_sub(st.b))
        .sum();
    x.clear();
    x.resize(total, 0.0);
    y.clear();
    y.resize(total, 0.0);
    let mut at = 0;
    for st in prepared {
        starts.push(at);
        let cols = n.saturating_sub(st.b);
        if cols == 0 {
            continue;
        }
        for &(off, u) in &st.taps {
            let (tx, ty) = (&mut x[at..at + cols], &mut y[at..at + cols]);
            match source {
                TapSource::Scaled(qx, qy) => {
                    let s = st.sqrt_slope;
                    if u == 0.0 {
                        let (qx, qy) = (&qx[off..off + cols], &qy[off..off + cols]);
                        for l in 0..cols {
                            tx[l] = qx[l] * s;
                            ty[l] = qy[l] * s;
                        }
                    } else {
                        // p + 1 <= n - 1: off <= b - 1 and l < n - b.
                        let (qx, qy) = (&qx[off..off + cols + 1], &qy[off..off + cols + 1]);
                        for l in 0..cols {
                            tx[l] = (qx[l] + (qx[l + 1] - qx[l]) * u) * s;
                            ty[l] = (qy[l] + (qy[l + 1] - qy[l]) * u) * s;
                        }
                    }
                }
                TapSource::Positions(bx, by) => {
                    for l in 0..cols {
                        let p = l + off;
                        let p1 = (p + 1).min(n - 1);
                        tx[l] = bx[p] + (bx[p1] - bx[p]) * u;
                        ty[l] = by[p] + (by[p1] - by[p]) * u;
                    }
                }
            }
            at += cols;
        }
    }
}

/// The banded DP's tables (into `tables`) and its path from (0, 0) to (n-1, n-1), or None when
/// the band cuts every path. Compiled for AVX2 too, which runs where the CPU has it (4 doubles
/// a vector against SSE2's 2): only separate multiplies and adds are emitted either way (Rust
/// never fuses them into a multiply-add), so both give the same tables to the bit.
pub(super) fn band_path(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    band: &[(usize, usize)],
    anchor: Option<Anchor>,
    tables: &mut (Vec<f64>, Vec<u32>),
    scratch: &mut Scratch,
) -> Option<Vec<(usize, usize)>> {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { band_path_avx2(q1, q2, steps, band, anchor, tables, scratch) };
    }
    band_path_in::<false>(q1, q2, steps, band, anchor, tables, scratch)
}

/// `band_path_in` compiled with AVX2 (call only where the CPU has it).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn band_path_avx2(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    band: &[(usize, usize)],
    anchor: Option<Anchor>,
    tables: &mut (Vec<f64>, Vec<u32>),
    scratch: &mut Scratch,
) -> Option<Vec<(usize, usize)>> {
    band_path_in::<true>(q1, q2, steps, band, anchor, tables, scratch)
}

/// `band_path`'s body; with `AVX2` (only inside `band_path_avx2`) the fused relaxation of runs
/// of four cells or more goes through `relax_avx2` (`relax_step`).
#[inline(always)]
fn band_path_in<const AVX2: bool>(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    band: &[(usize, usize)],
    anchor: Option<Anchor>,
    tables: &mut (Vec<f64>, Vec<u32>),
    scratch: &mut Scratch,
) -> Option<Vec<(usize, usize)>> {
    let n = q1.len();
    debug_assert_eq!(n, q2.len());
    let Scratch {
        prepared,
        prepared_for,
        starts,
        pstarts,
        wx,
        wy,
        px,
        py,
        x1,
        y1,
        x2,
        y2,
        ax,
        ay,
        bx,
        by,
        cand,
        near,
    } = scratch;
    if prepared_for.as_slice() != steps {
        *prepared = prepare(steps);
        *prepared_for = steps.to_vec();
    }
    let (lo, hi, offset) = band_rows(band, n);
    let cells = offset[n];
    let (cost, back) = tables;
    cost.clear();
    cost.resize(cells, f64::INFINITY);
    back.clear();
    back.resize(cells, u32::MAX);
    cost[0] = 0.0;
    x1.clear();
    y1.clear();
    x1.extend(q1.iter().map(|v| v.x));
    y1.extend(q1.iter().map(|v| v.y));
    // q2 at every tap of every step, times the step's sqrt slope, for each start column l
    // (0 <= l < n - b): it does not depend on the row, so it is computed once, not per cell.
    // x and y apart, so the row loops below run over contiguous columns (SIMD).
    x2.clear();
    y2.clear();
    x2.extend(q2.iter().map(|v| v.x));
    y2.extend(q2.iter().map(|v| v.y));
    fill_taps(prepared, n, starts, wx, wy, TapSource::Scaled(x2, y2));
    // B's positions at the same taps (not scaled: the position term ignores the slope).
    let weight = anchor.map_or(0.0, |a| a.weight);
    let anchored = anchor.filter(|_| weight > 0.0);
    if let Some(an) = anchored {
        ax.clear();
        ay.clear();
        ax.extend(an.a.iter().map(|v| v.x));
        ay.extend(an.a.iter().map(|v| v.y));
        bx.clear();
        by.clear();
        bx.extend(an.b.iter().map(|v| v.x));
        by.extend(an.b.iter().map(|v| v.y));
        fill_taps(prepared, n, pstarts, px, py, TapSource::Positions(bx, by));
    }
    // Row by row: for each step, every cell of the row it can reach at once (the candidates of
    // one step over a run of columns), then the best step per cell. Per cell this is the same
    // arithmetic, in the same order, with the same strict "<" over the steps in order, as a
    // cell-by-cell loop: the same costs and back-pointers to the bit.
    let widest = (0..n).map(|i| hi[i] + 1 - lo[i]).max().unwrap_or(0);
    cand.clear();
    cand.resize(widest, 0.0);
    near.clear();
    near.resize(widest, 0.0);
    for i in 1..n {
        // Rows before i are final: read from `done`, write row i.
        let (done, rest) = cost.split_at_mut(offset[i]);
        // Row i still holds the INFINITY and u32::MAX the tables were filled with.
        let best_row = &mut rest[..offset[i + 1] - offset[i]];
        let arg_row = &mut back[offset[i]..offset[i + 1]];
        for (si, st) in prepared.iter().enumerate() {
            if st.a > i {
                continue;
            }
            let k = i - st.a;
            // Columns j of row i whose predecessor l = j - b lies in row k's band.
            let j0 = lo[i].max(lo[k] + st.b);
            let j1 = hi[i].min(hi[k] + st.b);
            if j0 > j1 {
                continue;
            }
            let m = j1 + 1 - j0;
            let l0 = j0 - st.b;
            let cols = n - st.b;
            let base = starts[si];
            let prev = &done[offset[k] + l0 - lo[k]..][..m];
            let at = j0 - lo[i];
            let best = &mut best_row[at..][..m];
            let arg = &mut arg_row[at..][..m];
            let shape = Taps {
                qx: x1,
                qy: y1,
                tx: wx,
                ty: wy,
            };
            let position = anchored.map(|_| Taps {
                qx: ax,
                qy: ay,
                tx: px,
                ty: py,
            });
            let run = Run {
                k,
                first: base + l0,
                stride: cols,
            };
            let out = Out {
                prev,
                best,
                arg,
                step: si as u32,
            };
            match (st.a, position) {
                (1, None) => relax_step::<1, false, AVX2>(&shape, &shape, 0.0, &run, out, cand),
                (2, None) => relax_step::<2, false, AVX2>(&shape, &shape, 0.0, &run, out, cand),
                (3, None) => relax_step::<3, false, AVX2>(&shape, &shape, 0.0, &run, out, cand),
                (4, None) => relax_step::<4, false, AVX2>(&shape, &shape, 0.0, &run, out, cand),
                (5, None) => relax_step::<5, false, AVX2>(&shape, &shape, 0.0, &run, out, cand),
                (1, Some(p)) => relax_step::<1, true, AVX2>(&shape, &p, weight, &run, out, cand),
                (2, Some(p)) => relax_step::<2, true, AVX2>(&shape, &p, weight, &run, out, cand),
                (3, Some(p)) => relax_step::<3, true, AVX2>(&shape, &p, weight, &run, out, cand),
                (4, Some(p)) => relax_step::<4, true, AVX2>(&shape, &p, weight, &run, out, cand),
                (5, Some(p)) => relax_step::<5, true, AVX2>(&shape, &p, weight, &run, out, cand),
                (a, p) => relax_any(a, &shape, p.as_ref(), weight, &run, out, cand, near),
            }
        }
    }
    trace_band(back, &lo, &hi, steps)
}

/// A banded DP's costs and back-pointers, row-major (`band_rows`' layout).
pub(super) type CostTables = (Vec<f64>, Vec<u32>);

/// One tap's table entries over a run of cells, x and y.
type TapRun<'a> = (&'a [f64], &'a [f64]);

/// One part of a step's cost: the row curve's samples (q1, or A's positions) and the tap tables
/// of the column curve (q2 scaled by the step's sqrt slope, or B's positions), x and y apart.
struct Taps<'a> {
    qx: &'a [f64],
    qy: &'a [f64],
    tx: &'a [f64],
    ty: &'a [f64],
}

/// Where one step's candidates of a row read: the predecessor row k (the samples k..k+a of the
/// row curve) and, in the tap tables, the first candidate's entry of tap 0 and the distance
/// from one tap's entries to the next's.
struct Run {
    k: usize,
    first: usize,
    stride: usize,
}

/// A run of cells of row i, and the predecessors' costs they are relaxed from by one step.
struct Out<'a> {
    prev: &'a [f64],
    best: &'a mut [f64],
    arg: &'a mut [u32],
    step: u32,
}

/// One step of A samples relaxed over a run: four cells a vector (`relax_avx2`) in the AVX2
/// build where the run holds four cells or more, else `relax`; the same tables either way.
#[inline(always)]
fn relax_step<const A: usize, const POSITION: bool, const AVX2: bool>(
    shape: &Taps,
    position: &Taps,
    weight: f64,
    run: &Run,
    out: Out,
    cand: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    if AVX2 && out.prev.len() >= LANES {
        // SAFETY: AVX2 is only set inside `band_path_avx2`, which runs where the CPU has AVX2;
        // the run holds at least LANES cells (checked here), and `relax_avx2` checks its reads
        // of the tap tables once for the run (`lane_taps`).
        return unsafe { relax_avx2::<A, POSITION>(shape, position, weight, run, out) };
    }
    relax::<A, POSITION>(shape, position, weight, run, out, cand)
}

/// Relax a run of cells by one step of A samples, fused: per cell the step's SRVF cost (and,
/// with POSITION, the position term times `weight`), then the predecessor's cost plus it against
/// the best so far (a strict "<"). The sums run over the taps in order from 0.0, as `relax_any`
/// does, so the costs and back-pointers are the same to the bit; with A fixed the tap loop
/// unrolls and the cells vectorise, with no candidate row stored between passes.
#[inline(always)]
fn relax<const A: usize, const POSITION: bool>(
    shape: &Taps,
    position: &Taps,
    weight: f64,
    run: &Run,
    out: Out,
    cand: &mut [f64],
) {
    let m = out.prev.len();
    let q: [(f64, f64); A] = std::array::from_fn(|r| (shape.qx[run.k + r], shape.qy[run.k + r]));
    let w: [TapRun; A] = std::array::from_fn(|r| {
        let at = run.first + r * run.stride;
        (&shape.tx[at..][..m], &shape.ty[at..][..m])
    });
    let (pq, pw): ([(f64, f64); A], [TapRun; A]) = if POSITION {
        (
            std::array::from_fn(|r| (position.qx[run.k + r], position.qy[run.k + r])),
            std::array::from_fn(|r| {
                let at = run.first + r * run.stride;
                (&position.tx[at..][..m], &position.ty[at..][..m])
            }),
        )
    } else {
        ([(0.0, 0.0); A], [(&[][..], &[][..]); A])
    };
    // The candidates first (no branch: the cells vectorise), then the comparison as selects.
    let cand = &mut cand[..m];
    for (t, cand) in cand.iter_mut().enumerate() {
        let mut c = 0.0;
        for r in 0..A {
            let dx = q[r].0 - w[r].0[t];
            let dy = q[r].1 - w[r].1[t];
            c += dx * dx + dy * dy;
        }
        if POSITION {
            let mut e = 0.0;
            for r in 0..A {
                let dx = pq[r].0 - pw[r].0[t];
                let dy = pq[r].1 - pw[r].1[t];
                e += dx * dx + dy * dy;
            }
            c += weight * e;
        }
        *cand = c;
    }
    keep_better(out, cand);
}

/// best = prev + cand where that is strictly lower, its back-pointer the step's.
#[inline(always)]
fn keep_better(out: Out, cand: &[f64]) {
    let m = cand.len();
    let (prev, best, arg) = (&out.prev[..m], &mut out.best[..m], &mut out.arg[..m]);
    for t in 0..m {
        let v = prev[t] + cand[t];
        let take = v < best[t];
        best[t] = if take { v } else { best[t] };
        arg[t] = if take { out.step } else { arg[t] };
    }
}

/// A step's row-curve samples and where its taps' table entries over a run of `m` cells start,
/// x and y apart: the reads checked once for the whole run (the last tap's m entries lie in the
/// tables, and the samples k..k+A in the row curve), not once a tap.
#[cfg(target_arch = "x86_64")]
type LaneTaps<const A: usize> = ([f64; A], [f64; A], [*const f64; A], [*const f64; A]);

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn lane_taps<const A: usize>(t: &Taps, run: &Run, m: usize) -> LaneTaps<A> {
    let end = run.first + (A - 1) * run.stride + m;
    assert!(
        A >= 1
            && end <= t.tx.len()
            && end <= t.ty.len()
            && run.k + A <= t.qx.len()
            && run.k + A <= t.qy.len(),
        "a step's reads leave its tables"
    );
    let at = |r: usize| run.first + r * run.stride;
    // SAFETY: every index below is at most the ones checked just above (taps r < A start at
    // at(r) <= at(A - 1) and run m entries; samples k + r < k + A).
    unsafe {
        (
            std::array::from_fn(|r| *t.qx.get_unchecked(run.k + r)),
            std::array::from_fn(|r| *t.qy.get_unchecked(run.k + r)),
            std::array::from_fn(|r| t.tx.as_ptr().add(at(r))),
            std::array::from_fn(|r| t.ty.as_ptr().add(at(r))),
        )
    }
}

/// Cells `relax_avx2` takes at a time: one AVX2 vector of doubles.
#[cfg(target_arch = "x86_64")]
const LANES: usize = 4;

/// `relax` with AVX2 intrinsics, four cells a vector: per cell the same operations in the same
/// order (the taps' squared differences summed from 0.0, each as dx * dx + dy * dy, then the
/// position term times `weight`, then prev + cost against the best with a strict "<"), so the
/// same costs and back-pointers to the bit, without the scalar tail a run of 13 cells leaves:
/// the last four cells end at the run's end, and the cells they share with the four before are
/// computed again from the same inputs and compared again, which changes nothing (a cost equal
/// to the best is not strictly lower). Needs at least four cells.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn relax_avx2<const A: usize, const POSITION: bool>(
    shape: &Taps,
    position: &Taps,
    weight: f64,
    run: &Run,
    out: Out,
) {
    use std::arch::x86_64::*;
    let Out {
        prev,
        best,
        arg,
        step,
    } = out;
    let m = prev.len();
    debug_assert!(m >= LANES && best.len() == m && arg.len() == m);
    let (sqx, sqy, stx, sty) = lane_taps::<A>(shape, run, m);
    let sum = |qx: &[f64; A], qy: &[f64; A], tx: &[*const f64; A], ty: &[*const f64; A], t0| {
        let mut c = _mm256_setzero_pd();
        for r in 0..A {
            // SAFETY: t0 + LANES <= m, and each tap's m entries lie in its table
            // (`lane_taps` checked it).
            let (wx, wy) = unsafe {
                (
                    _mm256_loadu_pd(tx[r].add(t0)),
                    _mm256_loadu_pd(ty[r].add(t0)),
                )
            };
            let dx = _mm256_sub_pd(_mm256_set1_pd(qx[r]), wx);
            let dy = _mm256_sub_pd(_mm256_set1_pd(qy[r]), wy);
            c = _mm256_add_pd(
                c,
                _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
            );
        }
        c
    };
    let near = POSITION.then(|| lane_taps::<A>(position, run, m));
    let w = _mm256_set1_pd(weight);
    let steps = _mm_set1_epi32(step as i32);
    // The low 32 bits of each 64-bit lane, in order.
    let low = _mm256_setr_epi32(0, 2, 4, 6, 0, 0, 0, 0);
    let mut t = 0;
    loop {
        let t0 = t.min(m - LANES);
        let mut c = sum(&sqx, &sqy, &stx, &sty, t0);
        if let Some((pqx, pqy, ptx, pty)) = &near {
            c = _mm256_add_pd(c, _mm256_mul_pd(w, sum(pqx, pqy, ptx, pty, t0)));
        }
        // SAFETY: t0 + LANES <= m = prev.len() = best.len() = arg.len().
        unsafe {
            let v = _mm256_add_pd(_mm256_loadu_pd(prev.as_ptr().add(t0)), c);
            let b = _mm256_loadu_pd(best.as_ptr().add(t0));
            let take = _mm256_cmp_pd::<_CMP_LT_OQ>(v, b);
            // min(v, b) is v where v < b and b otherwise (b also where either is NaN): the
            // blend by `take`, written as a plain store (a blend into the loaded value is
            // compiled as a masked store, which later loads of the same cells wait on).
            _mm256_storeu_pd(best.as_mut_ptr().add(t0), _mm256_min_pd(v, b));
            let take32 =
                _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(_mm256_castpd_si256(take), low));
            let a = arg.as_mut_ptr().add(t0) as *mut __m128i;
            _mm_storeu_si128(a, _mm_blendv_epi8(_mm_loadu_si128(a), steps, take32));
        }
        if t0 + LANES == m {
            break;
        }
        t += LANES;
    }
}

/// `relax` for a step of any length: the candidates of the run first (into `cand`, the
/// position term into `near`), tap by tap, then the comparison.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn relax_any(
    a: usize,
    shape: &Taps,
    position: Option<&Taps>,
    weight: f64,
    run: &Run,
    out: Out,
    cand: &mut [f64],
    near: &mut [f64],
) {
    let m = out.prev.len();
    let part = |taps: &Taps, into: &mut [f64]| {
        into.fill(0.0);
        for r in 0..a {
            let (qx, qy) = (taps.qx[run.k + r], taps.qy[run.k + r]);
            let at = run.first + r * run.stride;
            let (tx, ty) = (&taps.tx[at..][..m], &taps.ty[at..][..m]);
            for ((c, &tx), &ty) in into.iter_mut().zip(tx).zip(ty) {
                let dx = qx - tx;
                let dy = qy - ty;
                *c += dx * dx + dy * dy;
            }
        }
    };
    let c = &mut cand[..m];
    part(shape, c);
    if let Some(p) = position {
        let e = &mut near[..m];
        part(p, e);
        for (c, &e) in c.iter_mut().zip(e.iter()) {
            *c += weight * e;
        }
    }
    keep_better(out, c);
}

#[cfg(test)]
mod tests;
