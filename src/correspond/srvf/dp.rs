//! Dynamic programming for the optimal warp gamma between two SRVFs sampled on the same uniform
//! grid: minimise sum_s |q1(t_s) - sqrt(gamma') q2(gamma(t_s))|^2 / n over piecewise-linear,
//! increasing gamma with gamma(0) = 0, gamma(1) = 1, whose pieces join grid nodes by steps from
//! the coprime neighbourhood {(a, b): 1 <= a, b <= N, gcd(a, b) = 1}.

use super::band::{band_rows, trace_band, BandProblem, DpOn};
use super::band_tables::{band_path, CostTables, Scratch};
use super::curve::{interp, Anchor};
use nalgebra::Vector2;

/// Two SRVFs to align, sampled alike: (q1, q2).
pub type CurvePair<'a> = (&'a [Vector2<f64>], &'a [Vector2<f64>]);

/// The coprime step set for neighbourhood size `n` (n = 1 gives only the diagonal).
pub fn coprime_steps(n: usize) -> Vec<(usize, usize)> {
    fn gcd(a: usize, b: usize) -> usize {
        if b == 0 {
            a
        } else {
            gcd(b, a % b)
        }
    }
    let mut s = Vec::new();
    for a in 1..=n.max(1) {
        for b in 1..=n.max(1) {
            if gcd(a, b) == 1 {
                s.push((a, b));
            }
        }
    }
    s
}

/// Cost of the straight piece from node (k, l) to node (i, j): the samples s = k..i-1 of q1
/// against q2 warped linearly with slope m = (j - l) / (i - k).
#[inline]
pub fn edge_cost(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    k: usize,
    l: usize,
    i: usize,
    j: usize,
) -> f64 {
    let m = (j - l) as f64 / (i - k) as f64;
    let sm = m.sqrt();
    let mut c = 0.0;
    for (t, q) in q1[k..i].iter().enumerate() {
        let y = l as f64 + t as f64 * m;
        c += (q - interp(q2, y) * sm).norm_squared();
    }
    c / q1.len() as f64
}

/// Result of one DP: the warp at every sample (gamma_s in [0, 1]), the warped q2 and its energy
/// ||q1 - q2_warped||^2 (mean over samples).
#[derive(Clone, Debug)]
pub struct Warp {
    /// The warp at A's samples, in B's sample units.
    pub gamma: Vec<f64>,
    /// B's SRVF warped onto A's samples.
    pub warped: Vec<Vector2<f64>>,
    /// The DP's energy (sum of squared SRVF differences).
    pub energy: f64,
    /// Grid nodes of the optimal path, from (0, 0) to (n-1, n-1).
    pub path: Vec<(usize, usize)>,
}

/// Optimal warp of q2 onto q1 (equal lengths, at least 2 samples) by DP over the coprime steps.
pub fn dp_warp(q1: &[Vector2<f64>], q2: &[Vector2<f64>], steps: &[(usize, usize)]) -> Warp {
    dp_warp_anchored(q1, q2, steps, None)
}

/// `dp_warp` with a position term (see `Anchor`); its energy includes the term.
pub fn dp_warp_anchored(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    anchor: Option<Anchor>,
) -> Warp {
    dp_warp_anchored_on(q1, q2, steps, anchor, DpOn::Host)
}

/// `dp_warp_anchored` with its DP run where `dp` says.
pub(crate) fn dp_warp_anchored_on(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    anchor: Option<Anchor>,
    dp: DpOn,
) -> Warp {
    let n = q1.len();
    dp_in_band(q1, q2, steps, &feasible_band(n, steps), anchor, dp)
}

/// Per row of an n x n grid, the columns a path from (0, 0) to (n-1, n-1) can pass through.
/// Every step (a, b) has a slope b / a between the set's shallowest and steepest, so a cell
/// (i, j) on such a path has i * shallowest <= j <= i * steepest, and the same measured back
/// from the end. A cell a path can use has all its predecessors that a path can use inside these
/// bounds too, so the DP over this band gives the full grid's costs and back-pointers on every
/// such cell, and the same optimal path (about a third fewer cells than the square).
pub(super) fn feasible_band(n: usize, steps: &[(usize, usize)]) -> Vec<(usize, usize)> {
    let last = n.saturating_sub(1);
    let full = vec![(1usize, last); n];
    // Steepest b_s / a_s and shallowest b_f / a_f, compared as fractions.
    let Some(&steep) = steps.iter().max_by(|x, y| (x.1 * y.0).cmp(&(y.1 * x.0))) else {
        return full;
    };
    let Some(&flat) = steps.iter().min_by(|x, y| (x.1 * y.0).cmp(&(y.1 * x.0))) else {
        return full;
    };
    if steep.0 == 0 || flat.0 == 0 {
        return full;
    }
    // floor(x * b / a) and ceil(x * b / a) for a step (a, b).
    let floor = |x: usize, (a, b): (usize, usize)| x * b / a;
    let ceil = |x: usize, (a, b): (usize, usize)| (x * b).div_ceil(a);
    (0..n)
        .map(|i| {
            let to_end = last - i;
            let lo = ceil(i, flat).max(last.saturating_sub(floor(to_end, steep)));
            let hi = floor(i, steep).min(last.saturating_sub(ceil(to_end, flat)));
            (lo.max(1), hi.min(last))
        })
        .collect()
}

/// DP restricted to the cells (i, j) with band[i].0 <= j <= band[i].1 (row 0 is the start).
/// Costs are kept only inside the band (row-major, one offset per row), so memory and time are
/// O(cells in the band); the per-step interpolation taps are precomputed, and the sum matches
/// `edge_cost` times n. The tables and the tap tables live in a per-thread scratch that the
/// next DP on the thread reuses (thousands of DPs run per reconstruction). With `DpOn::Device`
/// the tables are the device's (the host's DP where it cannot), traced back here.
pub(super) fn dp_in_band(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    band: &[(usize, usize)],
    anchor: Option<Anchor>,
    dp: DpOn,
) -> Warp {
    thread_local! {
        static SCRATCH: std::cell::RefCell<(CostTables, Scratch)> =
            std::cell::RefCell::default();
    }
    let path = |band: &[(usize, usize)]| {
        if let DpOn::Device(solver) = dp {
            let (lo, hi, _) = band_rows(band, q1.len());
            let problem = BandProblem {
                q1,
                q2,
                steps,
                lo: &lo,
                hi: &hi,
                anchor: anchor.filter(|a| a.weight > 0.0),
            };
            if let Some(back) = solver.back_pointers(&problem) {
                return trace_band(&back, &lo, &hi, steps);
            }
        }
        SCRATCH.with(|cell| {
            let (tables, scratch) = &mut *cell.borrow_mut();
            band_path(q1, q2, steps, band, anchor, tables, scratch)
        })
    };
    // A band that cuts every path (bands built from a path cannot) falls back to every cell a
    // path can use; a step set with no path at all (never a coprime set: it holds (1, 1)) to
    // the diagonal.
    let path = path(band)
        .or_else(|| path(&feasible_band(q1.len(), steps)))
        .unwrap_or_else(|| (0..q1.len()).map(|i| (i, i)).collect());
    finish_warp(q1, q2, path, anchor)
}

/// The warp along a DP's path, its energy with the position term.
pub(super) fn finish_warp(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    path: Vec<(usize, usize)>,
    anchor: Option<Anchor>,
) -> Warp {
    let n = q1.len();
    let mut w = warp_from_path(q1, q2, &path);
    if let Some(an) = anchor.filter(|a| a.weight > 0.0) {
        let scale = (n - 1).max(1) as f64;
        let samples: Vec<f64> = w.gamma.iter().map(|g| g * scale).collect();
        w.energy += an.energy(&samples);
    }
    w
}

/// Grids up to this size are solved exactly by the coarse-to-fine DP (`dp_many::warp_fast`).
pub const EXACT_DP_MAX: usize = 64;

/// The band of +-`halfwidth` cells around a node path given on a grid `factor` times coarser
/// (factor 1: the same grid), for a fine grid of n samples.
pub(super) fn band_around(
    path: &[(usize, usize)],
    factor: usize,
    n: usize,
    halfwidth: usize,
) -> Vec<(usize, usize)> {
    let fine = |c: usize| (factor * c).min(n - 1);
    let mut band = vec![(usize::MAX, 0usize); n];
    for w in path.windows(2) {
        let ((i0, j0), (i1, j1)) = ((fine(w[0].0), fine(w[0].1)), (fine(w[1].0), fine(w[1].1)));
        for (i, cell) in band.iter_mut().enumerate().take(i1 + 1).skip(i0) {
            let t = if i1 > i0 {
                (i - i0) as f64 / (i1 - i0) as f64
            } else {
                0.0
            };
            let j = j0 as f64 + t * (j1 as f64 - j0 as f64);
            let lo = (j.floor() as usize).saturating_sub(halfwidth);
            let hi = ((j.ceil() as usize) + halfwidth).min(n - 1);
            *cell = (cell.0.min(lo), cell.1.max(hi));
        }
    }
    band[n - 1].1 = n - 1;
    band
}

/// Follow back-pointers from (n-1, n-1) to (0, 0).
pub fn traceback(back: &[u32], n: usize, steps: &[(usize, usize)]) -> Vec<(usize, usize)> {
    let mut path = vec![(n - 1, n - 1)];
    let (mut i, mut j) = (n - 1, n - 1);
    while i > 0 && j > 0 {
        let s = back[i * n + j];
        if s == u32::MAX {
            break; // unreachable corner: cannot happen with the (1, 1) step present
        }
        let (a, b) = steps[s as usize];
        i -= a;
        j -= b;
        path.push((i, j));
    }
    path.reverse();
    path
}

/// Build gamma and the warped q2 from a node path, and the energy of the result.
pub fn warp_from_path(q1: &[Vector2<f64>], q2: &[Vector2<f64>], path: &[(usize, usize)]) -> Warp {
    let n = q1.len();
    let scale = (n - 1).max(1) as f64;
    let mut gamma = vec![1.0; n];
    let mut warped = vec![q2[n - 1]; n];
    for w in path.windows(2) {
        let ((k, l), (i, j)) = (w[0], w[1]);
        let m = (j - l) as f64 / (i - k) as f64;
        for s in k..i {
            let y = l as f64 + (s - k) as f64 * m;
            gamma[s] = y / scale;
            warped[s] = interp(q2, y) * m.sqrt();
        }
    }
    // The last sample takes the slope of the last piece.
    if let [.., (k, l), (i, j)] = path {
        let m = (j - l) as f64 / (i - k) as f64;
        warped[n - 1] = q2[n - 1] * m.sqrt();
    }
    let energy = super::curve::dist2(q1, &warped);
    Warp {
        gamma,
        warped,
        energy,
        path: path.to_vec(),
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    fn path_cost(q1: &[Vector2<f64>], q2: &[Vector2<f64>], p: &[(usize, usize)]) -> f64 {
        p.windows(2)
            .map(|w| edge_cost(q1, q2, w[0].0, w[0].1, w[1].0, w[1].1))
            .sum()
    }

    /// Every monotone path through the step set, by exhaustive recursion (tiny grids only).
    fn brute(q1: &[Vector2<f64>], q2: &[Vector2<f64>], steps: &[(usize, usize)]) -> f64 {
        brute_with(q1.len(), steps, &|k, l, i, j| edge_cost(q1, q2, k, l, i, j))
    }

    /// The cheapest monotone path from (0, 0) to (n-1, n-1) under `edge`, by exhaustive
    /// recursion.
    fn brute_with(
        n: usize,
        steps: &[(usize, usize)],
        edge: &dyn Fn(usize, usize, usize, usize) -> f64,
    ) -> f64 {
        fn go(
            n: usize,
            steps: &[(usize, usize)],
            edge: &dyn Fn(usize, usize, usize, usize) -> f64,
            at: (usize, usize),
            acc: f64,
        ) -> f64 {
            if at == (n - 1, n - 1) {
                return acc;
            }
            let mut best = f64::INFINITY;
            for &(a, b) in steps {
                let (i, j) = (at.0 + a, at.1 + b);
                if i < n && j < n {
                    best = best.min(go(n, steps, edge, (i, j), acc + edge(at.0, at.1, i, j)));
                }
            }
            best
        }
        go(n, steps, edge, (0, 0), 0.0)
    }

    /// The anchored cost of the piece (k, l) -> (i, j): the SRVF part and the position term of
    /// samples k..i-1, each over n.
    fn anchored_edge(q: CurvePair, an: &Anchor, (k, l, i, j): (usize, usize, usize, usize)) -> f64 {
        let m = (j - l) as f64 / (i - k) as f64;
        let pos: f64 = (k..i)
            .map(|t| (an.a[t] - interp(an.b, l as f64 + (t - k) as f64 * m)).norm_squared())
            .sum();
        edge_cost(q.0, q.1, k, l, i, j) + an.weight * pos / q.0.len() as f64
    }

    fn anchored_path_cost(q: CurvePair, an: &Anchor, p: &[(usize, usize)]) -> f64 {
        p.windows(2)
            .map(|w| anchored_edge(q, an, (w[0].0, w[0].1, w[1].0, w[1].1)))
            .sum()
    }

    #[test]
    fn anchored_dp_equals_brute_force_with_the_position_term() {
        let mut seed = 11u64;
        for n in [5usize, 7] {
            for nb in [2usize, 3] {
                let steps = coprime_steps(nb);
                let (q1, q2) = (random_q(n, &mut seed), random_q(n, &mut seed));
                let (a, b) = (random_q(n, &mut seed), random_q(n, &mut seed));
                let an = Anchor {
                    a: &a,
                    b: &b,
                    weight: 3.0,
                };
                let best = brute_with(n, &steps, &|k, l, i, j| {
                    anchored_edge((&q1, &q2), &an, (k, l, i, j))
                });
                let w = dp_warp_anchored(&q1, &q2, &steps, Some(an));
                let got = anchored_path_cost((&q1, &q2), &an, &w.path);
                assert!((got - best).abs() < 1e-12, "n {n} nb {nb}: {got} vs {best}");
                // The energy reported is the SRVF distance plus the position energy of the warp.
                let samples: Vec<f64> = w.gamma.iter().map(|g| g * (n - 1) as f64).collect();
                let e = super::super::curve::dist2(&q1, &w.warped) + an.energy(&samples);
                assert!((w.energy - e).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn the_anchored_check_rejects_the_shape_only_warp() {
        // Companion: where the position term matters, the warp that ignores it (plain dp_warp)
        // is not the anchored optimum, and the same comparison refuses it.
        let mut seed = 5u64;
        let n = 7;
        let steps = coprime_steps(3);
        let (q1, q2) = (random_q(n, &mut seed), random_q(n, &mut seed));
        let a: Vec<Vector2<f64>> = (0..n).map(|t| Vector2::new(t as f64, 0.0)).collect();
        let b: Vec<Vector2<f64>> = (0..n)
            .map(|t| Vector2::new((t * t) as f64 / 6.0, 0.0))
            .collect();
        let an = Anchor {
            a: &a,
            b: &b,
            weight: 3.0,
        };
        let best = brute_with(n, &steps, &|k, l, i, j| {
            anchored_edge((&q1, &q2), &an, (k, l, i, j))
        });
        let shape_only = dp_warp(&q1, &q2, &steps);
        let got = anchored_path_cost((&q1, &q2), &an, &shape_only.path);
        assert!(got > best + 1e-6, "{got} vs {best}");
        // With weight 0 the anchored DP is the plain one, path for path.
        let zero = Anchor { weight: 0.0, ..an };
        assert_eq!(
            dp_warp_anchored(&q1, &q2, &steps, Some(zero)).path,
            shape_only.path
        );
    }

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }

    pub(in crate::correspond::srvf) fn random_q(n: usize, seed: &mut u64) -> Vec<Vector2<f64>> {
        (0..n).map(|_| Vector2::new(lcg(seed), lcg(seed))).collect()
    }

    #[test]
    fn dp_equals_brute_force_on_tiny_grids() {
        let mut seed = 7u64;
        for n in [4usize, 6, 8] {
            for nb in [1usize, 2, 3] {
                let steps = coprime_steps(nb);
                let (q1, q2) = (random_q(n, &mut seed), random_q(n, &mut seed));
                let w = dp_warp(&q1, &q2, &steps);
                let b = brute(&q1, &q2, &steps);
                let p = path_cost(&q1, &q2, &w.path);
                assert!((p - b).abs() < 1e-12, "n {n} nb {nb}: dp {p} brute {b}");
                // The companion: a wrong path (the diagonal) is worse whenever DP found better.
                let diag: Vec<(usize, usize)> = (0..n).map(|i| (i, i)).collect();
                assert!(path_cost(&q1, &q2, &diag) >= b - 1e-12);
            }
        }
    }

    /// (q1, q2, anchor positions a and b) of a random problem.
    type Problem = (
        Vec<Vector2<f64>>,
        Vec<Vector2<f64>>,
        Vec<Vector2<f64>>,
        Vec<Vector2<f64>>,
    );

    fn problem(n: usize, seed: &mut u64) -> Problem {
        (
            random_q(n, seed),
            random_q(n, seed),
            random_q(n, seed),
            random_q(n, seed),
        )
    }

    fn same_warp(x: &Warp, y: &Warp) -> bool {
        x.path == y.path
            && x.energy.to_bits() == y.energy.to_bits()
            && x.gamma
                .iter()
                .zip(&y.gamma)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }

    #[test]
    fn the_feasible_band_gives_the_square_grids_warp_to_the_bit() {
        let mut seed = 21u64;
        let lopsided = vec![(1, 1), (1, 2), (2, 1), (1, 3), (2, 3)];
        for n in [5usize, 12, 49, 64] {
            for steps in [coprime_steps(2), coprime_steps(5), lopsided.clone()] {
                for anchored in [false, true] {
                    let (q1, q2, a, b) = problem(n, &mut seed);
                    let anchor = anchored.then_some(Anchor {
                        a: &a,
                        b: &b,
                        weight: 2.0,
                    });
                    let square =
                        dp_in_band(&q1, &q2, &steps, &vec![(1, n - 1); n], anchor, DpOn::Host);
                    let ours = dp_warp_anchored(&q1, &q2, &steps, anchor);
                    assert!(same_warp(&ours, &square), "n {n} steps {steps:?}");
                }
            }
        }
        // It is a real saving: a third of the square at the study's 49 samples.
        let band = feasible_band(49, &coprime_steps(5));
        let (_, _, offset) = band_rows(&band, 49);
        assert!(offset[49] < 48 * 48 * 7 / 10, "{} cells", offset[49]);
    }

    #[test]
    fn a_step_set_with_no_path_gives_the_diagonal_not_an_endless_fallback() {
        // Steps (2, 1) and (1, 2) cannot reach (2, 2) from (0, 0): no band holds a path.
        let mut seed = 8u64;
        let (q1, q2, _, _) = problem(3, &mut seed);
        let w = dp_warp(&q1, &q2, &[(2, 1), (1, 2)]);
        assert_eq!(w.path, vec![(0, 0), (1, 1), (2, 2)]);
        assert!(w.energy.is_finite());
    }

    #[test]
    fn a_band_that_cuts_the_optimal_path_is_told_apart() {
        // The same comparison, fed the DP over a band with one cell of the optimal path taken
        // out, must fail: the check sees a band that is too narrow.
        let mut seed = 4u64;
        let n = 40;
        let steps = coprime_steps(5);
        let (q1, q2, _, _) = problem(n, &mut seed);
        let square = dp_in_band(&q1, &q2, &steps, &vec![(1, n - 1); n], None, DpOn::Host);
        let (i, j) = square.path[square.path.len() / 2];
        let mut band = feasible_band(n, &steps);
        if j > band[i].0 {
            band[i].1 = j - 1;
        } else {
            band[i].0 = j + 1;
        }
        let cut = dp_in_band(&q1, &q2, &steps, &band, None, DpOn::Host);
        assert!(!same_warp(&cut, &square));
    }

    #[test]
    fn brute_force_check_rejects_a_suboptimal_answer() {
        // Feeding the comparison a deliberately worse path must fail it.
        let mut seed = 3u64;
        let n = 7;
        let steps = coprime_steps(3);
        let (q1, q2) = (random_q(n, &mut seed), random_q(n, &mut seed));
        let b = brute(&q1, &q2, &steps);
        let diag: Vec<(usize, usize)> = (0..n).map(|i| (i, i)).collect();
        let wrong = path_cost(&q1, &q2, &diag);
        assert!(
            (wrong - b).abs() > 1e-6,
            "the diagonal happened to be optimal; pick another seed"
        );
    }

    #[test]
    fn coarse_to_fine_dp_stays_within_one_percent_of_the_exact_dp() {
        let n = 201;
        for (f1, f2) in [(1.0, 1.3), (2.0, 2.5), (3.0, 2.2), (1.5, 4.0)] {
            let curve = |f: f64, ph: f64| -> Vec<Vector2<f64>> {
                (0..n)
                    .map(|i| {
                        let t = i as f64 / (n - 1) as f64;
                        Vector2::new((f * 6.0 * t + ph).cos(), (f * 4.0 * t).sin() + 0.3)
                    })
                    .collect()
            };
            let (q1, q2) = (curve(f1, 0.0), curve(f2, 0.4));
            let steps = coprime_steps(5);
            let exact = dp_warp(&q1, &q2, &steps);
            let fast = super::super::dp_many::warp_fast(&q1, &q2, &steps, 6, None, DpOn::Host);
            assert!(
                fast.energy <= exact.energy * 1.01 + 1e-9,
                "fast {} exact {}",
                fast.energy,
                exact.energy
            );
            assert!(fast.energy >= exact.energy - 1e-12);
            assert_eq!(fast.path.first(), Some(&(0, 0)));
            assert_eq!(fast.path.last(), Some(&(n - 1, n - 1)));
        }
    }

    #[test]
    fn warp_is_monotone_and_pinned() {
        let n = 30;
        let q1: Vec<Vector2<f64>> = (0..n)
            .map(|i| Vector2::new((i as f64 * 0.2).cos(), (i as f64 * 0.2).sin()))
            .collect();
        let q2: Vec<Vector2<f64>> = (0..n)
            .map(|i| Vector2::new((i as f64 * 0.25).cos(), (i as f64 * 0.15).sin()))
            .collect();
        let w = dp_warp(&q1, &q2, &coprime_steps(4));
        assert_eq!(w.gamma[0], 0.0);
        assert_eq!(w.gamma[n - 1], 1.0);
        assert!(w.gamma.windows(2).all(|g| g[1] >= g[0]));
        let diag: Vec<(usize, usize)> = (0..n).map(|i| (i, i)).collect();
        assert!(path_cost(&q1, &q2, &w.path) <= path_cost(&q1, &q2, &diag) + 1e-12);
    }
}
