//! Elastic alignment of curve B onto curve A: the rotation O in SO(2), the start point (seed) for
//! closed curves, the sub-arc for partial matches, and the warp gamma that minimise
//! ||q_A - O q_B(gamma) sqrt(gamma')||^2, alternating rotation and DP until the energy stops
//! falling.

use super::curve::{best_rotation, dist2, rotate, srvf};
use super::dp::{coprime_steps, dp_warp, dp_warp_fast, Warp};
use crate::contours::{polyline_length, resample_closed, resample_open, ClosedPolyline};
use nalgebra::{Point2, Vector2};

/// How the two curves are matched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CurveKind {
    /// Both closed: rotation, seed and warp.
    Closed,
    /// Both open with corresponding end points: rotation and warp.
    Open,
    /// A is an open arc matched against a sub-arc of the closed curve B (either direction).
    Partial,
}

/// Parameters of an alignment, with their defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct SrvfParams {
    /// Arc-length samples T per curve (default 200).
    pub samples: usize,
    /// Coprime step neighbourhood size of the DP (default 5: 19 step directions).
    pub neighbourhood: usize,
    /// Closed curves: how many of the best seeds (ranked by the rotation-only energy, which is
    /// exact for all seeds at once) are refined with full DP (default 6).
    pub seed_candidates: usize,
    /// Rotation/DP alternations at most (default 3); stops earlier when the energy falls by less
    /// than `rel_tol` (default 1e-4) of itself.
    pub max_alternations: usize,
    pub rel_tol: f64,
    /// Coarse-to-fine DP band half-width in cells (default 6); 0 solves every DP on the full grid.
    pub band: usize,
}

impl Default for SrvfParams {
    fn default() -> Self {
        SrvfParams {
            samples: 200,
            neighbourhood: 5,
            seed_candidates: 6,
            max_alternations: 3,
            rel_tol: 1e-4,
            band: 6,
        }
    }
}

/// Why two curves cannot be aligned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SrvfError {
    #[error("curve {curve} has {count} points; at least 3 are needed")]
    TooFewPoints { curve: &'static str, count: usize },
    #[error("curve {curve} has zero length (all points coincide)")]
    ZeroLength { curve: &'static str },
    #[error("curve {curve} has a non-finite coordinate at point {index}")]
    NonFinite { curve: &'static str, index: usize },
    #[error("samples must be at least 8 (got {0})")]
    TooFewSamples(usize),
}

/// The result: distance, rotation, seed and, per arc-length sample of A, where it lands on B.
#[derive(Clone, Debug)]
pub struct Alignment {
    /// ||q_A - O q_B(gamma) sqrt(gamma')|| with unit-norm SRVFs (0 = same shape; at most 2).
    pub distance: f64,
    /// Rotation applied to B, radians (counter-clockwise in x-right, y-up axes).
    pub rotation: f64,
    /// Closed: index of B's start sample; partial: start of the sub-arc in B's samples.
    pub seed: usize,
    /// The warp at A's samples, in [0, 1] of B's (shifted or sub-arc) parameter.
    pub gamma: Vec<f64>,
    /// A's arc-length samples.
    pub a_points: Vec<Point2<f64>>,
    /// For each A sample, the arc length along B (from B's first point, in B's own units).
    pub b_arclength: Vec<f64>,
    /// For each A sample, the matched point on B and its fractional vertex index in B.
    pub b_points: Vec<Point2<f64>>,
    pub b_index: Vec<f64>,
    /// Partial matches only: whether A was reversed to run the same way as B.
    pub reversed: bool,
}

fn check(curve: &'static str, p: &[Point2<f64>]) -> Result<(), SrvfError> {
    if let Some(index) = p.iter().position(|q| !q.x.is_finite() || !q.y.is_finite()) {
        return Err(SrvfError::NonFinite { curve, index });
    }
    if p.len() < 3 {
        return Err(SrvfError::TooFewPoints {
            curve,
            count: p.len(),
        });
    }
    if polyline_length(p, false) <= 1e-12 {
        return Err(SrvfError::ZeroLength { curve });
    }
    Ok(())
}

/// Optimal rotation + warp with alternation, starting from rotation `theta`.
fn rotate_and_warp(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    theta: f64,
    prm: &SrvfParams,
    steps: &[(usize, usize)],
) -> (f64, Warp) {
    let mut theta = theta;
    let dp = |q: &[Vector2<f64>]| {
        if prm.band == 0 {
            dp_warp(q1, q, steps)
        } else {
            dp_warp_fast(q1, q, steps, prm.band)
        }
    };
    let mut w = dp(&rotate(q2, theta));
    let mut energy = w.energy;
    for _ in 1..prm.max_alternations.max(1) {
        let d = best_rotation(q1, &w.warped);
        let next_theta = theta + d;
        let w2 = dp(&rotate(q2, next_theta));
        if w2.energy < energy * (1.0 - prm.rel_tol) {
            theta = next_theta;
            energy = w2.energy;
            w = w2;
        } else {
            // Keep the rotation refinement alone if it helps without a new warp.
            let rotated = rotate(&w.warped, d);
            let e = dist2(q1, &rotated);
            if e < energy {
                theta = next_theta;
                w.warped = rotated;
                w.energy = e;
            }
            break;
        }
    }
    (theta, w)
}

/// Rotation-only energy of every cyclic shift of q2 against q1 (exact, O(T^2)).
fn shift_energies(q1: &[Vector2<f64>], q2: &[Vector2<f64>]) -> Vec<(f64, f64)> {
    let t = q1.len();
    (0..t)
        .map(|s| {
            let (mut c, mut sn) = (0.0, 0.0);
            for i in 0..t {
                let (a, b) = (q1[i], q2[(i + s) % t]);
                c += a.dot(&b);
                sn += b.x * a.y - b.y * a.x;
            }
            // Unit-norm SRVFs: ||q1 - O q2||^2 = 2 - 2 <q1, O q2>.
            let best = (c * c + sn * sn).sqrt() / t as f64;
            (2.0 - 2.0 * best, sn.atan2(c))
        })
        .collect()
}

fn closed_grid(q: &[Vector2<f64>], shift: usize) -> Vec<Vector2<f64>> {
    let t = q.len();
    (0..=t).map(|i| q[(i + shift) % t]).collect()
}

/// Align closed curve B onto closed curve A. With `exhaustive`, every seed is refined (the test
/// oracle); otherwise the `seed_candidates` best by rotation-only energy.
pub fn align_closed(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
    exhaustive: bool,
) -> Result<Alignment, SrvfError> {
    check("A", a)?;
    check("B", b)?;
    if prm.samples < 8 {
        return Err(SrvfError::TooFewSamples(prm.samples));
    }
    let t = prm.samples;
    let (ra, _) = resample_closed(a, t);
    let (rb, _) = resample_closed(b, t);
    let q1 = srvf(&ra, true);
    let q2 = srvf(&rb, true);
    let steps = coprime_steps(prm.neighbourhood);
    let energies = shift_energies(&q1, &q2);
    let mut order: Vec<usize> = (0..t).collect();
    order.sort_by(|&x, &y| energies[x].0.total_cmp(&energies[y].0));
    if !exhaustive {
        order = pick_distinct_seeds(&order, t, prm.seed_candidates.max(1));
    }
    let q1g = closed_grid(&q1, 0);
    let mut best: Option<(f64, usize, f64, Warp)> = None;
    let refine = |s: usize, best: &mut Option<(f64, usize, f64, Warp)>| {
        let (theta, w) = rotate_and_warp(&q1g, &closed_grid(&q2, s), energies[s].1, prm, &steps);
        if best.as_ref().map_or(true, |b| w.energy < b.0) {
            *best = Some((w.energy, s, theta, w));
        }
    };
    if exhaustive {
        let exact = SrvfParams {
            band: 0,
            ..prm.clone()
        };
        let refine = |s: usize, best: &mut Option<(f64, usize, f64, Warp)>| {
            let (theta, w) =
                rotate_and_warp(&q1g, &closed_grid(&q2, s), energies[s].1, &exact, &steps);
            if best.as_ref().map_or(true, |b| w.energy < b.0) {
                *best = Some((w.energy, s, theta, w));
            }
        };
        for s in order {
            refine(s, &mut best);
        }
    } else {
        // Coarse to fine: rank the candidate seeds by a DP at <= 48 samples, then refine the two
        // best (and their neighbouring full-resolution seeds) at the full sample count.
        let tc = t.min(48);
        let coarse_prm = SrvfParams {
            max_alternations: 2,
            ..prm.clone()
        };
        let (ca, _) = resample_closed(&ra, tc);
        let cq1 = closed_grid(&srvf(&ca, true), 0);
        let mut ranked: Vec<(f64, usize)> = order
            .iter()
            .map(|&s| {
                let (cb, _) = resample_closed(&rotate_list(&rb, s), tc);
                let cq2 = closed_grid(&srvf(&cb, true), 0);
                let (_, w) = rotate_and_warp(&cq1, &cq2, energies[s].1, &coarse_prm, &steps);
                (w.energy, s)
            })
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        for &(_, s) in ranked.iter().take(2) {
            refine(s, &mut best);
        }
        // The candidates are kept apart, so walk the seed one sample at a time while it helps.
        for dir in [1usize, t - 1] {
            loop {
                let current = best.as_ref().map(|b| (b.0, b.1)).expect("refined above");
                let s = (current.1 + dir) % t;
                refine(s, &mut best);
                if best.as_ref().map(|b| b.1) != Some(s) {
                    break;
                }
            }
        }
    }
    let (energy, seed, theta, w) = best.expect("at least one seed is tried");
    let poly = ClosedPolyline::new(b);
    let mut b_arclength = Vec::with_capacity(t);
    let (mut b_points, mut b_index) = (Vec::with_capacity(t), Vec::with_capacity(t));
    for g in &w.gamma[..t] {
        let s = (seed as f64 + g * t as f64) / t as f64 * poly.total;
        let (p, idx) = poly.at(s);
        b_arclength.push(s.rem_euclid(poly.total));
        b_points.push(p);
        b_index.push(idx);
    }
    Ok(Alignment {
        distance: energy.max(0.0).sqrt(),
        rotation: theta,
        seed,
        gamma: w.gamma[..t].to_vec(),
        a_points: ra,
        b_arclength,
        b_points,
        b_index,
        reversed: false,
    })
}

/// The points rotated so that index `s` comes first.
fn rotate_list(p: &[Point2<f64>], s: usize) -> Vec<Point2<f64>> {
    p[s..].iter().chain(&p[..s]).cloned().collect()
}

/// The best-ranked seeds, skipping ones within T/50 samples of a seed already taken.
fn pick_distinct_seeds(order: &[usize], t: usize, k: usize) -> Vec<usize> {
    let gap = (t / 50).max(1);
    let mut out: Vec<usize> = Vec::new();
    for &s in order {
        if out.iter().all(|&o| {
            let d = (s as isize - o as isize).unsigned_abs();
            d.min(t - d) > gap
        }) {
            out.push(s);
            if out.len() == k {
                break;
            }
        }
    }
    out
}

/// Align open curve B onto open curve A (ends correspond).
pub fn align_open(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
) -> Result<Alignment, SrvfError> {
    check("A", a)?;
    check("B", b)?;
    if prm.samples < 8 {
        return Err(SrvfError::TooFewSamples(prm.samples));
    }
    let t = prm.samples;
    let (ra, _) = resample_open(a, t);
    let (rb, _) = resample_open(b, t);
    let q1 = srvf(&ra, false);
    let q2 = srvf(&rb, false);
    let steps = coprime_steps(prm.neighbourhood);
    let (theta, w) = rotate_and_warp(&q1, &q2, best_rotation(&q1, &q2), prm, &steps);
    let total = polyline_length(b, false);
    let mut out = Alignment {
        distance: w.energy.max(0.0).sqrt(),
        rotation: theta,
        seed: 0,
        gamma: w.gamma.clone(),
        a_points: ra,
        b_arclength: w.gamma.iter().map(|g| g * total).collect(),
        b_points: Vec::new(),
        b_index: Vec::new(),
        reversed: false,
    };
    let cum = open_positions(b, &out.b_arclength);
    (out.b_points, out.b_index) = cum;
    Ok(out)
}

/// Points and fractional indices on an open polyline at the given arc lengths.
fn open_positions(b: &[Point2<f64>], arclength: &[f64]) -> (Vec<Point2<f64>>, Vec<f64>) {
    // An open polyline is a closed one whose closing segment is never reached.
    let poly = ClosedPolyline::new(b);
    let open_total = polyline_length(b, false);
    arclength
        .iter()
        .map(|&s| poly.at(s.clamp(0.0, open_total)))
        .unzip()
}

/// The open arc of closed curve B from arc length `start` over `len`, sampled at `t` points.
fn sub_arc(poly: &ClosedPolyline, start: f64, len: f64, t: usize) -> Vec<Point2<f64>> {
    (0..t)
        .map(|i| poly.at(start + len * i as f64 / (t - 1) as f64).0)
        .collect()
}

/// Match the open arc A against the best sub-arc of the closed curve B, trying both directions of
/// A. A coarse search over start and length (at most 64 samples) picks candidates that are then
/// refined at the full sample count.
pub fn align_partial(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
) -> Result<Alignment, SrvfError> {
    check("A", a)?;
    check("B", b)?;
    if prm.samples < 8 {
        return Err(SrvfError::TooFewSamples(prm.samples));
    }
    let poly = ClosedPolyline::new(b);
    let ratio = (polyline_length(a, false) / poly.total).clamp(0.05, 1.0);
    let coarse = SrvfParams {
        samples: prm.samples.min(64),
        max_alternations: 2,
        ..prm.clone()
    };
    let steps_c = coprime_steps(coarse.neighbourhood.min(4));
    let starts = 48usize;
    let fracs: Vec<f64> = [0.7, 0.85, 1.0, 1.15, 1.35]
        .iter()
        .map(|f| (ratio * f).min(0.98))
        .collect();
    // (energy, reversed, start, len)
    let mut cands: Vec<(f64, bool, f64, f64)> = Vec::new();
    for reversed in [false, true] {
        let mut aa = a.to_vec();
        if reversed {
            aa.reverse();
        }
        let (ra, _) = resample_open(&aa, coarse.samples);
        let q1 = srvf(&ra, false);
        for k in 0..starts {
            let start = poly.total * k as f64 / starts as f64;
            for &f in &fracs {
                let len = f * poly.total;
                let q2 = srvf(&sub_arc(&poly, start, len, coarse.samples), false);
                let (_, w) = rotate_and_warp(&q1, &q2, best_rotation(&q1, &q2), &coarse, &steps_c);
                cands.push((w.energy, reversed, start, len));
            }
        }
    }
    cands.sort_by(|x, y| x.0.total_cmp(&y.0));
    // Refine the three best with a local search in start and length at full resolution.
    let t = prm.samples;
    let steps = coprime_steps(prm.neighbourhood);
    let mut best: Option<(f64, bool, f64, f64, f64, Warp, Vec<Point2<f64>>)> = None;
    for &(_, reversed, start0, len0) in cands.iter().take(3) {
        let mut aa = a.to_vec();
        if reversed {
            aa.reverse();
        }
        let (ra, _) = resample_open(&aa, t);
        let q1 = srvf(&ra, false);
        let (mut start, mut len) = (start0, len0);
        let mut step_s = 0.5 * poly.total / starts as f64;
        let mut step_l = 0.07 * len0;
        let eval = |start: f64, len: f64| {
            let q2 = srvf(&sub_arc(&poly, start, len, t), false);
            rotate_and_warp(&q1, &q2, best_rotation(&q1, &q2), prm, &steps)
        };
        let (mut theta, mut w) = eval(start, len);
        for _ in 0..3 {
            for (ds, dl) in [(-step_s, 0.0), (step_s, 0.0), (0.0, -step_l), (0.0, step_l)] {
                let l2 = (len + dl).clamp(0.02 * poly.total, 0.99 * poly.total);
                let (th, w2) = eval(start + ds, l2);
                if w2.energy < w.energy {
                    (theta, w, start, len) = (th, w2, start + ds, l2);
                }
            }
            step_s *= 0.5;
            step_l *= 0.5;
        }
        if best.as_ref().map_or(true, |b| w.energy < b.0) {
            best = Some((w.energy, reversed, start, len, theta, w, ra));
        }
    }
    let (energy, reversed, start, len, theta, w, ra) = best.expect("candidates are never empty");
    let mut out = Alignment {
        distance: energy.max(0.0).sqrt(),
        rotation: theta,
        seed: ((start.rem_euclid(poly.total) / poly.total) * t as f64).round() as usize % t,
        gamma: w.gamma.clone(),
        a_points: ra,
        b_arclength: w
            .gamma
            .iter()
            .map(|g| (start + g * len).rem_euclid(poly.total))
            .collect(),
        b_points: Vec::new(),
        b_index: Vec::new(),
        reversed,
    };
    (out.b_points, out.b_index) = out.b_arclength.iter().map(|&s| poly.at(s)).unzip();
    if reversed {
        // Report in A's own order.
        out.a_points.reverse();
        out.b_arclength.reverse();
        out.b_points.reverse();
        out.b_index.reverse();
        out.gamma.reverse();
    }
    Ok(out)
}

/// Align with the given kind.
pub fn align(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    kind: CurveKind,
    prm: &SrvfParams,
) -> Result<Alignment, SrvfError> {
    match kind {
        CurveKind::Closed => align_closed(a, b, prm, false),
        CurveKind::Open => align_open(a, b, prm),
        CurveKind::Partial => align_partial(a, b, prm),
    }
}
