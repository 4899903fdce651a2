//! Partial matches: an open arc A (an annotation that leaves out the blurred walls) against the
//! best sub-arc of a closed curve B (the model's outline), start, length and direction searched
//! by rotation-only energies read from B's tangent field, then aligned by DP (`align`).

use super::align::{
    check, check_samples, rotate_and_warp, Alignment, AnchorFrame, SrvfError, SrvfParams,
};
use super::band::DpOn;
use super::curve::{best_rotation, dist2, srvf, Anchor};
use super::dp::coprime_steps;
use crate::geom::{polyline_length, resample_closed, resample_open, ClosedPolyline};
use nalgebra::{Point2, Vector2};

/// The open arc of closed curve B from arc length `start` over `len`, sampled at `t` points.
fn sub_arc(poly: &ClosedPolyline, start: f64, len: f64, t: usize) -> Vec<Point2<f64>> {
    (0..t)
        .map(|i| poly.at(start + len * i as f64 / (t - 1) as f64).0)
        .collect()
}

/// Unit tangents of the closed curve at `n` arc-length samples (the arc-length SRVF of any of its
/// sub-arcs, once normalised, is its unit tangent).
fn unit_tangents(b: &[Point2<f64>], n: usize) -> Vec<Vector2<f64>> {
    let (r, _) = resample_closed(b, n);
    (0..n)
        .map(|i| {
            let d = r[(i + 1) % n] - r[(i + n - 1) % n];
            let s = d.norm();
            if s > 1e-15 {
                d / s
            } else {
                Vector2::zeros()
            }
        })
        .collect()
}

/// Rotation-only energy 2 - 2 max_O <q1, O q2> (O within `prm.max_rotation`) of A's SRVF against
/// the sub-arc of B from fraction `start` over fraction `len`, read from B's tangent field.
fn subarc_rotation_energy(
    q1: &[Vector2<f64>],
    tang: &[Vector2<f64>],
    start: f64,
    len: f64,
    prm: &SrvfParams,
) -> f64 {
    let (n, t) = (tang.len(), q1.len());
    let (mut c, mut s) = (0.0, 0.0);
    for (i, a) in q1.iter().enumerate() {
        let x = (start + len * i as f64 / (t - 1) as f64) * n as f64;
        let k = x.floor();
        let u = x - k;
        let k = (k as i64).rem_euclid(n as i64) as usize;
        let v = tang[k] * (1.0 - u) + tang[(k + 1) % n] * u;
        c += a.dot(&v);
        s += v.x * a.y - v.y * a.x;
    }
    prm.best_bounded(c, s, t).0
}

/// Match the open arc A against the best sub-arc of the closed curve B, trying both directions of
/// A. Every start x length x direction is ranked by its rotation-only energy (read from B's
/// tangent field, no resampling); the six best distinct ones get a coarse DP alignment (at most
/// 48 samples), the best is polished by a coordinate search in start and length at that
/// resolution, and the winner is aligned once at the full sample count.
pub fn align_partial(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
) -> Result<Alignment, SrvfError> {
    align_partial_on(a, b, prm, DpOn::Host)
}

/// `align_partial` with its DPs run where `on` says.
pub(super) fn align_partial_on(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
    on: DpOn,
) -> Result<Alignment, SrvfError> {
    check("A", a)?;
    check("B", b)?;
    check_samples(prm.samples)?;
    let poly = ClosedPolyline::new(b);
    let ratio = (polyline_length(a, false) / poly.total).clamp(0.05, 1.0);
    let coarse = SrvfParams {
        samples: prm.samples.min(48),
        max_alternations: 2,
        ..prm.clone()
    };
    let steps = coprime_steps(prm.neighbourhood);
    let tang = unit_tangents(b, 1024);
    let starts = 96usize;
    // Sub-arc lengths (fractions of B): A's length ratio says little when the scales differ,
    // so a geometric ladder from 5 % to 95 % is ranked too, with the ratio's neighbours.
    let mut fracs: Vec<f64> = (0..32)
        .map(|k| 0.05 * (0.95f64 / 0.05).powf(k as f64 / 31.0))
        .collect();
    fracs.extend([0.85, 1.0, 1.15].iter().map(|f| (ratio * f).min(0.95)));
    let arc_q = |reversed: bool, t: usize| {
        let mut aa = a.to_vec();
        if reversed {
            aa.reverse();
        }
        let (ra, _) = resample_open(&aa, t);
        let q = srvf(&ra, false);
        (ra, q)
    };
    let frame = AnchorFrame::of(b);
    // A's positions in the anchor frame, by direction and sample count.
    let arc_pos = |reversed: bool, t: usize| frame.map(&arc_q(reversed, t).0);
    // (energy, reversed, start fraction, length fraction)
    let mut cands: Vec<(f64, bool, f64, f64)> = Vec::new();
    let rank_t = prm.samples.min(32);
    let coarse_q1 = [
        arc_q(false, coarse.samples).1,
        arc_q(true, coarse.samples).1,
    ];
    let rank_q1 = [arc_q(false, rank_t).1, arc_q(true, rank_t).1];
    let coarse_pa = [
        arc_pos(false, coarse.samples),
        arc_pos(true, coarse.samples),
    ];
    let rank_pa = [arc_pos(false, rank_t), arc_pos(true, rank_t)];
    for (d, q1) in rank_q1.iter().enumerate() {
        for k in 0..starts {
            let start = k as f64 / starts as f64;
            for &f in &fracs {
                cands.push((
                    subarc_rotation_energy(q1, &tang, start, f, prm),
                    d == 1,
                    start,
                    f,
                ));
            }
        }
    }
    cands.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut picked: Vec<(bool, f64, f64)> = Vec::new();
    for &(_, rev, start, len) in &cands {
        let close = picked.iter().any(|&(r2, s2, _)| {
            let d = (start - s2).rem_euclid(1.0);
            r2 == rev && d.min(1.0 - d) < 1.5 / starts as f64
        });
        if !close {
            picked.push((rev, start, len));
            if picked.len() == 8 {
                break;
            }
        }
    }
    let eval = |q1: &[Vector2<f64>],
                pa: &[Vector2<f64>],
                p: &SrvfParams,
                start: f64,
                len: f64,
                hint: Option<&[(usize, usize)]>| {
        let arc = sub_arc(&poly, start * poly.total, len * poly.total, q1.len());
        let q2 = srvf(&arc, false);
        let pb = frame.map(&arc);
        let anchor = Anchor {
            a: pa,
            b: &pb,
            weight: p.anchor,
        };
        rotate_and_warp(
            q1,
            &q2,
            best_rotation(q1, &q2),
            p,
            &steps,
            hint,
            Some(anchor),
            on,
        )
    };
    // The candidates are told apart by a DP at the ranking resolution; the winner is polished at
    // the (finer) coarse resolution.
    let rank_prm = SrvfParams {
        samples: rank_t,
        ..coarse.clone()
    };
    let mut best: Option<(f64, bool, f64, f64)> = None;
    for &(rev, start, len) in &picked {
        let d = usize::from(rev);
        let (_, w) = eval(&rank_q1[d], &rank_pa[d], &rank_prm, start, len, None);
        if best.as_ref().is_none_or(|b| w.energy < b.0) {
            best = Some((w.energy, rev, start, len));
        }
    }
    let (_, reversed, mut start, mut len) = best.expect("candidates are never empty");
    let q1c = &coarse_q1[usize::from(reversed)];
    let pac = &coarse_pa[usize::from(reversed)];
    let (_, w) = eval(q1c, pac, &coarse, start, len, None);
    let (mut energy, mut path) = (w.energy, w.path);
    // Pattern search: move while a move helps, else halve the steps (at most 24 evaluations).
    let (mut step_s, mut step_l) = (0.5 / starts as f64, 0.05 * len);
    let mut evals = 0;
    while evals < 24 && step_s > 0.02 / starts as f64 {
        let mut moved = false;
        for (ds, dl) in [(-step_s, 0.0), (step_s, 0.0), (0.0, -step_l), (0.0, step_l)] {
            let l2 = (len + dl).clamp(0.02, 0.99);
            // A small move of the sub-arc moves the warp path little: search near it.
            let (_, w) = eval(q1c, pac, &coarse, start + ds, l2, Some(&path));
            evals += 1;
            if w.energy < energy {
                (energy, start, len, path) = (w.energy, start + ds, l2, w.path);
                moved = true;
            }
        }
        if !moved {
            step_s *= 0.5;
            step_l *= 0.5;
        }
    }
    let t = prm.samples;
    let (ra, q1) = arc_q(reversed, t);
    let (theta, w) = eval(&q1, &frame.map(&ra), prm, start, len, None);
    let (start, len) = (start * poly.total, len * poly.total);
    let mut out = Alignment {
        distance: dist2(&q1, &w.warped).max(0.0).sqrt(),
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
