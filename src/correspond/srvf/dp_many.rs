//! Several independent DPs at once (the seed candidates of one alignment): each level of the
//! coarse-to-fine DP, and each rotation/warp alternation, for all of them in one request, so an
//! engine that takes batches (the GPU, through `BandSolver::back_pointers_many`) gets them
//! together. On the host every job runs exactly as it would alone (`dp::dp_in_band`), so the
//! results are the same to the bit as one job at a time.

use super::band::{band_rows, trace_band, BandProblem, DpOn};
use super::curve::{best_rotation, dist2, rotate, Anchor};
use super::dp::{band_around, dp_in_band, feasible_band, finish_warp};
use super::dp::{Warp, EXACT_DP_MAX};
use super::SrvfParams;
use nalgebra::Vector2;

/// One DP: q2 warped onto q1 over `band`, with the position term of `anchor`.
struct Job<'a> {
    q1: &'a [Vector2<f64>],
    q2: &'a [Vector2<f64>],
    band: Vec<(usize, usize)>,
    anchor: Option<Anchor<'a>>,
}

/// `dp::dp_in_band` of every job; on a device, all of them in one request.
fn in_band(jobs: &[Job], steps: &[(usize, usize)], dp: DpOn) -> Vec<Warp> {
    let alone =
        |j: &Job, band: &[(usize, usize)]| dp_in_band(j.q1, j.q2, steps, band, j.anchor, dp);
    let DpOn::Device(solver) = dp else {
        return jobs.iter().map(|j| alone(j, &j.band)).collect();
    };
    if jobs.is_empty() {
        return Vec::new();
    }
    let rows: Vec<(Vec<usize>, Vec<usize>)> = jobs
        .iter()
        .map(|j| {
            let (lo, hi, _) = band_rows(&j.band, j.q1.len());
            (lo, hi)
        })
        .collect();
    let problems: Vec<BandProblem> = jobs
        .iter()
        .zip(&rows)
        .map(|(j, (lo, hi))| BandProblem {
            q1: j.q1,
            q2: j.q2,
            steps,
            lo,
            hi,
            anchor: j.anchor.filter(|a| a.weight > 0.0),
        })
        .collect();
    match solver.back_pointers_many(&problems) {
        Some(backs) if backs.len() == jobs.len() => jobs
            .iter()
            .zip(&rows)
            .zip(&backs)
            .map(
                |((j, (lo, hi)), back)| match trace_band(back, lo, hi, steps) {
                    Some(path) => finish_warp(j.q1, j.q2, path, j.anchor),
                    // As `dp_in_band` does when the band cuts every path.
                    None => alone(j, &feasible_band(j.q1.len(), steps)),
                },
            )
            .collect(),
        _ => jobs
            .iter()
            .map(|j| dp_in_band(j.q1, j.q2, steps, &j.band, j.anchor, DpOn::Host))
            .collect(),
    }
}

/// One warp problem of a level: the curves and the position term.
#[derive(Clone, Copy)]
struct Pair<'a> {
    q1: &'a [Vector2<f64>],
    q2: &'a [Vector2<f64>],
    anchor: Option<Anchor<'a>>,
}

/// `dp::dp_warp_anchored_on` of every pair.
fn anchored(pairs: &[Pair], steps: &[(usize, usize)], dp: DpOn) -> Vec<Warp> {
    let jobs: Vec<Job> = pairs
        .iter()
        .map(|p| Job {
            q1: p.q1,
            q2: p.q2,
            band: feasible_band(p.q1.len(), steps),
            anchor: p.anchor,
        })
        .collect();
    in_band(&jobs, steps, dp)
}

/// Coarse-to-fine DP of one pair: solve on every other sample (recursively), then the full
/// grid only in a band of +-`halfwidth` cells around the coarse path. O(n * band) instead of
/// O(n^2); the exact `dp::dp_warp` is its test oracle.
#[cfg(test)]
pub(super) fn warp_fast(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    halfwidth: usize,
    anchor: Option<Anchor>,
    dp: DpOn,
) -> Warp {
    let pair = Pair { q1, q2, anchor };
    fast(&[pair], steps, halfwidth, dp)
        .pop()
        .expect("one pair gives one warp")
}

/// `warp_fast` of every pair, level by level (pairs of different sample counts one by one).
fn fast(pairs: &[Pair], steps: &[(usize, usize)], halfwidth: usize, dp: DpOn) -> Vec<Warp> {
    let Some(n) = pairs.first().map(|p| p.q1.len()) else {
        return Vec::new();
    };
    if pairs.iter().any(|p| p.q1.len() != n) {
        return pairs
            .iter()
            .flat_map(|p| fast(std::slice::from_ref(p), steps, halfwidth, dp))
            .collect();
    }
    if n <= EXACT_DP_MAX {
        return anchored(pairs, steps, dp);
    }
    let m = n.div_ceil(2) + usize::from(n.is_multiple_of(2));
    let fine = |c: usize| (2 * c).min(n - 1);
    let every_other =
        |q: &[Vector2<f64>]| -> Vec<Vector2<f64>> { (0..m).map(|c| q[fine(c)]).collect() };
    // (c1, c2, and the position term's coarse curves) per pair.
    type Coarse = (
        Vec<Vector2<f64>>,
        Vec<Vector2<f64>>,
        Option<(Vec<Vector2<f64>>, Vec<Vector2<f64>>, f64)>,
    );
    let coarse: Vec<Coarse> = pairs
        .iter()
        .map(|p| {
            (
                every_other(p.q1),
                every_other(p.q2),
                p.anchor
                    .map(|a| (every_other(a.a), every_other(a.b), a.weight)),
            )
        })
        .collect();
    let coarse_pairs: Vec<Pair> = coarse
        .iter()
        .map(|(c1, c2, pos)| Pair {
            q1: c1,
            q2: c2,
            anchor: pos.as_ref().map(|(a, b, weight)| Anchor {
                a,
                b,
                weight: *weight,
            }),
        })
        .collect();
    let paths = fast(&coarse_pairs, steps, halfwidth, dp);
    let jobs: Vec<Job> = pairs
        .iter()
        .zip(&paths)
        .map(|(p, c)| Job {
            q1: p.q1,
            q2: p.q2,
            band: band_around(&c.path, 2, n, halfwidth),
            anchor: p.anchor,
        })
        .collect();
    in_band(&jobs, steps, dp)
}

/// The DP of every pair in a band of +-`halfwidth` cells about its own hint (a path of a nearby
/// problem on the same grid: the previous rotation's, a neighbouring seed's); short curves and
/// missing hints over the whole feasible band.
fn near(
    pairs: &[Pair],
    hints: &[&[(usize, usize)]],
    steps: &[(usize, usize)],
    halfwidth: usize,
    dp: DpOn,
) -> Vec<Warp> {
    let jobs: Vec<Job> = pairs
        .iter()
        .zip(hints)
        .map(|(p, hint)| {
            let n = p.q1.len();
            let band = if n <= 24 || hint.len() < 2 {
                feasible_band(n, steps)
            } else {
                band_around(hint, 1, n, halfwidth)
            };
            Job {
                q1: p.q1,
                q2: p.q2,
                band,
                anchor: p.anchor,
            }
        })
        .collect();
    in_band(&jobs, steps, dp)
}

/// One candidate of `rotate_and_warp_many`: its q2, its starting rotation, its position term,
/// and a path of a nearby problem to search about first (a neighbouring seed's), if any.
pub(super) struct Candidate<'a> {
    pub(super) q2: &'a [Vector2<f64>],
    pub(super) theta: f64,
    pub(super) anchor: Option<Anchor<'a>>,
    pub(super) hint: Option<&'a [(usize, usize)]>,
}

/// The rotation O and the warp of every candidate against the same q1, alternating rotation
/// and DP until the energy stops falling (at most `prm.max_alternations` DPs; the rotation
/// bounded by `prm.max_rotation`): the first DP in a band about the candidate's hint, or
/// coarse-to-fine without one, later ones about the previous path. The candidates' rounds go in
/// step, each round's DPs one request; each candidate's rotations, warps and energies are those
/// it would get alone.
pub(super) fn rotate_and_warp_many(
    q1: &[Vector2<f64>],
    cands: &[Candidate],
    prm: &SrvfParams,
    steps: &[(usize, usize)],
    on: DpOn,
) -> Vec<(f64, Warp)> {
    let anchors: Vec<Option<Anchor>> = cands
        .iter()
        .map(|c| c.anchor.filter(|a| a.weight > 0.0))
        .collect();
    // The DPs of candidates `idx` (their turned q2 in `qs`), each about its hint if it has one.
    let solve = |qs: &[Vec<Vector2<f64>>], idx: &[usize], hints: &[Option<&[(usize, usize)]>]| {
        let pairs: Vec<Pair> = qs
            .iter()
            .zip(idx)
            .map(|(q, &k)| Pair {
                q1,
                q2: q,
                anchor: anchors[k],
            })
            .collect();
        if prm.band == 0 {
            return anchored(&pairs, steps, on);
        }
        let (with, without): (Vec<usize>, Vec<usize>) =
            (0..pairs.len()).partition(|&i| hints[i].is_some());
        let pick = |set: &[usize]| -> Vec<Pair> { set.iter().map(|&i| pairs[i]).collect() };
        let hinted: Vec<&[(usize, usize)]> = with.iter().filter_map(|&i| hints[i]).collect();
        let mut out: Vec<Option<Warp>> = (0..pairs.len()).map(|_| None).collect();
        let solved = near(&pick(&with), &hinted, steps, prm.band, on)
            .into_iter()
            .zip(&with)
            .chain(
                fast(&pick(&without), steps, prm.band, on)
                    .into_iter()
                    .zip(&without),
            );
        for (w, &i) in solved {
            out[i] = Some(w);
        }
        out.into_iter().flatten().collect::<Vec<Warp>>()
    };
    let mut theta: Vec<f64> = cands.iter().map(|c| prm.bounded(c.theta)).collect();
    let all: Vec<usize> = (0..cands.len()).collect();
    let first: Vec<Vec<Vector2<f64>>> = cands
        .iter()
        .zip(&theta)
        .map(|(c, &t)| rotate(c.q2, t))
        .collect();
    let first_hints: Vec<Option<&[(usize, usize)]>> = cands.iter().map(|c| c.hint).collect();
    let mut w = solve(&first, &all, &first_hints);
    let mut energy: Vec<f64> = w.iter().map(|w| w.energy).collect();
    let mut active = all;
    for _ in 1..prm.max_alternations.max(1) {
        if active.is_empty() {
            break;
        }
        // (next theta, the turn d) of every candidate still alternating.
        let turns: Vec<(f64, f64)> = active
            .iter()
            .map(|&k| {
                let free = best_rotation(q1, &w[k].warped);
                let next = prm.bounded(theta[k] + free);
                let d = if prm.max_rotation.is_some() {
                    next - theta[k]
                } else {
                    free
                };
                (next, d)
            })
            .collect();
        let turned: Vec<Vec<Vector2<f64>>> = active
            .iter()
            .zip(&turns)
            .map(|(&k, &(next, _))| rotate(cands[k].q2, next))
            .collect();
        let hints: Vec<Option<&[(usize, usize)]>> =
            active.iter().map(|&k| Some(&w[k].path[..])).collect();
        let w2 = solve(&turned, &active, &hints);
        let mut still = Vec::new();
        for ((&k, &(next, d)), w2) in active.iter().zip(&turns).zip(w2) {
            if w2.energy < energy[k] * (1.0 - prm.rel_tol) {
                theta[k] = next;
                energy[k] = w2.energy;
                w[k] = w2;
                still.push(k);
            } else {
                // Keep the rotation refinement alone if it helps without a new warp (the
                // position term does not depend on the rotation).
                let rotated = rotate(&w[k].warped, d);
                let e = dist2(q1, &rotated) + (w[k].energy - dist2(q1, &w[k].warped));
                if e < energy[k] {
                    theta[k] = next;
                    w[k].warped = rotated;
                    w[k].energy = e;
                }
            }
        }
        active = still;
    }
    theta.into_iter().zip(w).collect()
}
