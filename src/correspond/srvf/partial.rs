//! Partial matches: an open arc A (an annotation that leaves out the blurred walls) against the
//! best sub-arc of a closed curve B (the model's outline), start, length and direction searched
//! by rotation-only energies read from B's tangent field, then aligned by DP (`align`).

use super::align::{
    check, check_samples, rotate_and_warp, Alignment, AnchorFrame, SrvfError, SrvfParams,
};
use super::band::DpOn;
use super::curve::{best_rotation, dist2, srvf, Anchor};
use super::dp::{coprime_steps, Warp};
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
/// tangent field, no resampling); the eight best of distinct starts get a DP alignment at the
/// ranking resolution (at most 32 samples), the best is polished by a coordinate search in start
/// and length at a coarse one (at most 48), and the winner is aligned once at the full sample
/// count.
pub fn align_partial(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
) -> Result<Alignment, SrvfError> {
    align_partial_on(a, b, prm, DpOn::Host)
}

/// Starts of B's sub-arcs ranked per direction of A (fractions of B, evenly spaced).
const STARTS: usize = 96;

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
    let search = SubArcSearch {
        a,
        poly: ClosedPolyline::new(b),
        frame: AnchorFrame::of(b),
        steps: coprime_steps(prm.neighbourhood),
        on,
    };
    let coarse = SrvfParams {
        samples: prm.samples.min(48),
        max_alternations: 2,
        ..prm.clone()
    };
    // The candidates are told apart by a DP at the ranking resolution; the winner is polished at
    // the (finer) coarse resolution.
    let rank_prm = SrvfParams {
        samples: prm.samples.min(32),
        ..coarse.clone()
    };
    // A's SRVF and anchor-frame positions at the ranking resolution, by direction: made once for
    // the ranking and its DPs.
    let rank = [false, true].map(|rev| search.arc_and_pos(rev, rank_prm.samples));
    let picked = search.candidates(b, prm, &rank);
    let (reversed, start, len) = search.best_of(&picked, &rank, &rank_prm);
    let (start, len) = search.polish(reversed, start, len, &coarse);
    let t = prm.samples;
    let (ra, q1) = search.arc_q(reversed, t);
    let (theta, w) = search.eval(&q1, &search.frame.map(&ra), prm, start, len, None);
    let poly = &search.poly;
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

/// A at some sample count: its SRVF and its positions in B's anchor frame.
type ArcAt = (Vec<Vector2<f64>>, Vec<Vector2<f64>>);

/// The open arc `a` against the sub-arcs of the closed curve B (`poly`), each sub-arc given by
/// its direction, start and length as fractions of B.
struct SubArcSearch<'a> {
    a: &'a [Point2<f64>],
    poly: ClosedPolyline<'a>,
    /// B's anchor frame (where A's and the sub-arcs' positions are compared).
    frame: AnchorFrame,
    steps: Vec<(usize, usize)>,
    on: DpOn<'a>,
}

impl SubArcSearch<'_> {
    /// A (reversed or not) resampled at `t` points, and its SRVF.
    fn arc_q(&self, reversed: bool, t: usize) -> (Vec<Point2<f64>>, Vec<Vector2<f64>>) {
        let mut aa = self.a.to_vec();
        if reversed {
            aa.reverse();
        }
        let (ra, _) = resample_open(&aa, t);
        let q = srvf(&ra, false);
        (ra, q)
    }

    /// A's SRVF and its positions in the anchor frame, by direction and sample count.
    fn arc_and_pos(&self, reversed: bool, t: usize) -> ArcAt {
        let (ra, q) = self.arc_q(reversed, t);
        (q, self.frame.map(&ra))
    }

    /// The rotation and warp of A (SRVF `q1`, anchor-frame positions `pa`) onto the sub-arc
    /// from `start` over `len`, under `p`; `hint`: a warp path to search near.
    fn eval(
        &self,
        q1: &[Vector2<f64>],
        pa: &[Vector2<f64>],
        p: &SrvfParams,
        start: f64,
        len: f64,
        hint: Option<&[(usize, usize)]>,
    ) -> (f64, Warp) {
        let poly = &self.poly;
        let arc = sub_arc(poly, start * poly.total, len * poly.total, q1.len());
        let q2 = srvf(&arc, false);
        let pb = self.frame.map(&arc);
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
            &self.steps,
            hint,
            Some(anchor),
            self.on,
        )
    }

    /// Every start x length x direction ranked by its rotation-only energy (A's SRVF at the
    /// ranking resolution, `rank`, against B's tangent field, no resampling); the eight best of
    /// distinct starts (direction, start, length).
    fn candidates(
        &self,
        b: &[Point2<f64>],
        prm: &SrvfParams,
        rank: &[ArcAt; 2],
    ) -> Vec<(bool, f64, f64)> {
        let ratio = (polyline_length(self.a, false) / self.poly.total).clamp(0.05, 1.0);
        let tang = unit_tangents(b, 1024);
        // Sub-arc lengths (fractions of B): A's length ratio says little when the scales
        // differ, so a geometric ladder from 5 % to 95 % is ranked too, with the ratio's
        // neighbours.
        let mut fracs: Vec<f64> = (0..32)
            .map(|k| 0.05 * (0.95f64 / 0.05).powf(k as f64 / 31.0))
            .collect();
        fracs.extend([0.85, 1.0, 1.15].iter().map(|f| (ratio * f).min(0.95)));
        // (energy, reversed, start fraction, length fraction)
        let mut cands: Vec<(f64, bool, f64, f64)> = Vec::new();
        for reversed in [false, true] {
            let q1 = &rank[usize::from(reversed)].0;
            for k in 0..STARTS {
                let start = k as f64 / STARTS as f64;
                for &f in &fracs {
                    cands.push((
                        subarc_rotation_energy(q1, &tang, start, f, prm),
                        reversed,
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
                r2 == rev && d.min(1.0 - d) < 1.5 / STARTS as f64
            });
            if !close {
                picked.push((rev, start, len));
                if picked.len() == 8 {
                    break;
                }
            }
        }
        picked
    }

    /// The candidate whose DP alignment under `rank_prm` has the least energy (the first of
    /// equals); the candidates are never empty (every start and length is ranked).
    fn best_of(
        &self,
        picked: &[(bool, f64, f64)],
        rank: &[ArcAt; 2],
        rank_prm: &SrvfParams,
    ) -> (bool, f64, f64) {
        let mut best: Option<(f64, bool, f64, f64)> = None;
        for &(rev, start, len) in picked {
            let (q1, pa) = &rank[usize::from(rev)];
            let (_, w) = self.eval(q1, pa, rank_prm, start, len, None);
            if best.as_ref().is_none_or(|b| w.energy < b.0) {
                best = Some((w.energy, rev, start, len));
            }
        }
        best.map_or(picked[0], |(_, rev, start, len)| (rev, start, len))
    }

    /// The sub-arc's start and length polished under `coarse` by a pattern search: move while
    /// a move helps, else halve the steps (at most 24 evaluations).
    fn polish(&self, reversed: bool, start: f64, len: f64, coarse: &SrvfParams) -> (f64, f64) {
        let t = coarse.samples;
        let (q1c, pac) = self.arc_and_pos(reversed, t);
        let (_, w) = self.eval(&q1c, &pac, coarse, start, len, None);
        let (mut energy, mut path) = (w.energy, w.path);
        let (mut start, mut len) = (start, len);
        let (mut step_s, mut step_l) = (0.5 / STARTS as f64, 0.05 * len);
        let mut evals = 0;
        while evals < 24 && step_s > 0.02 / STARTS as f64 {
            let mut moved = false;
            for (ds, dl) in [(-step_s, 0.0), (step_s, 0.0), (0.0, -step_l), (0.0, step_l)] {
                let l2 = (len + dl).clamp(0.02, 0.99);
                // A small move of the sub-arc moves the warp path little: search near it.
                let (_, w) = self.eval(&q1c, &pac, coarse, start + ds, l2, Some(&path));
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
        (start, len)
    }
}
