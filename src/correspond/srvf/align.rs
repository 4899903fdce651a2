//! Elastic alignment of curve B onto curve A: the rotation O in SO(2), the start point (seed) for
//! closed curves, the sub-arc for partial matches, and the warp gamma that minimise
//! ||q_A - O q_B(gamma) sqrt(gamma')||^2, alternating rotation and DP until the energy stops
//! falling.

use super::band::DpOn;
use super::curve::{best_rotation, dist2, srvf, Anchor};
use super::dp::{coprime_steps, CurvePair, Warp};
use super::dp_many::{rotate_and_warp_many, Candidate};
use crate::geom::{polyline_length, resample_closed, resample_open, ClosedPolyline};
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
    /// See `max_alternations`.
    pub rel_tol: f64,
    /// Coarse-to-fine DP band half-width in cells (default 6); 0 solves every DP on the full grid.
    pub band: usize,
    /// Largest rotation O may make, radians (default None: any, the elastic shape distance).
    /// Curves drawn in one frame, as a view's model contour and its annotated rim are, turn
    /// against each other only as far as the start's pose is off; an unbounded rotation lets a
    /// nearly round or elliptical outline match itself turned by up to 180 degrees, and every
    /// correspondence then pulls its vertex across the outline (see `CorrespondParams`).
    pub max_rotation: Option<f64>,
    /// Weight of the position term (default 0: the elastic shape distance alone). Curves drawn
    /// in one frame also tell where each point is: with a weight w > 0 the warp and seed also
    /// pay w |a(t) - b(gamma(t))|^2 per sample, positions in units of B's RMS radius about its
    /// centroid, so that of two warps that match the shapes about as well the one pairing
    /// nearby points wins (a dent in A is then met by the part of B beside it, not by a part
    /// of similar shape further round). `distance` stays the shape distance alone.
    pub anchor: f64,
}

impl SrvfParams {
    /// With `max_rotation`, `theta` wrapped to (-pi, pi] and held within it; without, `theta`
    /// as it is.
    pub fn bounded(&self, theta: f64) -> f64 {
        let pi = std::f64::consts::PI;
        let t = theta - 2.0 * pi * ((theta + pi) / (2.0 * pi)).floor();
        let t = if t <= -pi { t + 2.0 * pi } else { t };
        match self.max_rotation {
            Some(m) => t.clamp(-m.abs(), m.abs()),
            None => theta,
        }
    }

    /// The rotation maximising c cos(theta) + s sin(theta) (the inner product of q1 with q2
    /// turned by theta, summed as c and s) within `max_rotation`, and the energy
    /// 2 - 2 (c cos + s sin) / t of unit-norm SRVFs at it.
    pub(super) fn best_bounded(&self, c: f64, s: f64, t: usize) -> (f64, f64) {
        if self.max_rotation.is_none() {
            return (2.0 - 2.0 * (c * c + s * s).sqrt() / t as f64, s.atan2(c));
        }
        let theta = self.bounded(s.atan2(c));
        let inner = c * theta.cos() + s * theta.sin();
        (2.0 - 2.0 * inner / t as f64, theta)
    }
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
            max_rotation: None,
            anchor: 0.0,
        }
    }
}

/// Fewest arc-length samples per curve an alignment takes.
pub const MIN_SAMPLES: usize = 8;
/// Most samples per curve: the closed-curve seed search grows with the square of the count
/// (20,000 samples take about 1.3 s on one core; 10^8 would not finish).
pub const MAX_SAMPLES: usize = 50_000;

pub(super) fn check_samples(n: usize) -> Result<(), SrvfError> {
    if (MIN_SAMPLES..=MAX_SAMPLES).contains(&n) {
        Ok(())
    } else {
        Err(SrvfError::SampleCount(n))
    }
}

/// Why two curves cannot be aligned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SrvfError {
    /// A curve with fewer than 3 points.
    #[error("curve {curve} has {count} points; at least 3 are needed")]
    TooFewPoints {
        /// Which curve ("a" or "b").
        curve: &'static str,
        /// Its points.
        count: usize,
    },
    /// A curve whose points all coincide, or lie within 1e-12 units of each other.
    #[error(
        "curve {curve} has zero length: its points coincide or lie within 1e-12 units of each other \
         (rescale the coordinates)"
    )]
    ZeroLength {
        /// Which curve.
        curve: &'static str,
    },
    /// A curve with a NaN or infinite coordinate.
    #[error("curve {curve} has a non-finite coordinate at point {index}")]
    NonFinite {
        /// Which curve.
        curve: &'static str,
        /// The first such point.
        index: usize,
    },
    /// A curve whose length overflows f64.
    #[error(
        "curve {curve} is too large to measure (its length overflows; rescale the coordinates)"
    )]
    Overflow {
        /// Which curve.
        curve: &'static str,
    },
    /// A sample count outside MIN_SAMPLES..=MAX_SAMPLES.
    #[error("samples must be {MIN_SAMPLES} to {MAX_SAMPLES} (got {0})")]
    SampleCount(usize),
    /// A model contour whose vertex ids and points differ in number (its fields are public;
    /// `model_contour` makes them one for one).
    #[error("the model contour has {ids} vertex ids for {points} points; it needs one for each")]
    ModelIds {
        /// Its vertex ids.
        ids: usize,
        /// Its points.
        points: usize,
    },
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
    /// For each A sample, its matched point's fractional vertex index in B.
    pub b_index: Vec<f64>,
    /// Partial matches only: whether A was reversed to run the same way as B.
    pub reversed: bool,
}

pub(super) fn check(curve: &'static str, p: &[Point2<f64>]) -> Result<(), SrvfError> {
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
    if !polyline_length(p, true).is_finite() {
        return Err(SrvfError::Overflow { curve });
    }
    Ok(())
}

/// Optimal rotation + warp with alternation, starting from rotation `theta`. The first DP runs
/// coarse to fine (or in a band around `hint`, the path of a neighbouring problem); each later
/// one in a band around the previous path, since a small rotation change moves the path little.
/// The rotation and warp of q2 onto q1 from `theta` (`dp_many::rotate_and_warp_many` of one
/// candidate).
#[allow(clippy::too_many_arguments)]
pub(super) fn rotate_and_warp(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    theta: f64,
    prm: &SrvfParams,
    steps: &[(usize, usize)],
    hint: Option<&[(usize, usize)]>,
    anchor: Option<Anchor>,
    on: DpOn,
) -> (f64, Warp) {
    let cand = Candidate {
        q2,
        theta,
        anchor,
        hint,
    };
    rotate_and_warp_many(q1, std::slice::from_ref(&cand), prm, steps, on)
        .pop()
        .expect("one candidate gives one alignment")
}

/// Rotation-only energy of every cyclic shift of q2 against q1 and its rotation, within
/// `prm.max_rotation` (exact, O(T^2)); with positions (A's and B's samples in the anchor frame),
/// plus the position term of pairing A's sample i with B's i + s.
fn shift_energies(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    prm: &SrvfParams,
    positions: Option<CurvePair>,
) -> Vec<(f64, f64)> {
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
            let (mut e, theta) = prm.best_bounded(c, sn, t);
            if let Some((pa, pb)) = positions {
                let d: f64 = (0..t)
                    .map(|i| (pa[i] - pb[(i + s) % t]).norm_squared())
                    .sum();
                e += prm.anchor * d / t as f64;
            }
            (e, theta)
        })
        .collect()
}

/// Where the position term measures: about B's centroid, in units of B's RMS radius about it.
#[derive(Clone, Copy)]
pub(super) struct AnchorFrame {
    origin: Point2<f64>,
    unit: f64,
}

impl AnchorFrame {
    pub(super) fn of(b: &[Point2<f64>]) -> AnchorFrame {
        let n = b.len().max(1) as f64;
        let origin = Point2::from(b.iter().map(|p| p.coords).sum::<Vector2<f64>>() / n);
        let rms = (b.iter().map(|p| (p - origin).norm_squared()).sum::<f64>() / n).sqrt();
        AnchorFrame {
            origin,
            unit: if rms > 0.0 { rms } else { 1.0 },
        }
    }

    pub(super) fn map(&self, p: &[Point2<f64>]) -> Vec<Vector2<f64>> {
        p.iter().map(|q| (q - self.origin) / self.unit).collect()
    }
}

fn closed_grid(q: &[Vector2<f64>], shift: usize) -> Vec<Vector2<f64>> {
    let t = q.len();
    (0..=t).map(|i| q[(i + shift) % t]).collect()
}

/// Both curves checked, resampled to `prm.samples` points and turned into SRVFs, with the DP's
/// step set: what closed and open alignment start from.
struct Resampled {
    t: usize,
    ra: Vec<Point2<f64>>,
    rb: Vec<Point2<f64>>,
    q1: Vec<Vector2<f64>>,
    q2: Vec<Vector2<f64>>,
    steps: Vec<(usize, usize)>,
}

impl Resampled {
    fn new(
        a: &[Point2<f64>],
        b: &[Point2<f64>],
        prm: &SrvfParams,
        closed: bool,
    ) -> Result<Resampled, SrvfError> {
        check("A", a)?;
        check("B", b)?;
        check_samples(prm.samples)?;
        let t = prm.samples;
        let resample = if closed {
            resample_closed
        } else {
            resample_open
        };
        let (ra, _) = resample(a, t);
        let (rb, _) = resample(b, t);
        let q1 = srvf(&ra, closed);
        let q2 = srvf(&rb, closed);
        Ok(Resampled {
            t,
            ra,
            rb,
            q1,
            q2,
            steps: coprime_steps(prm.neighbourhood),
        })
    }
}

/// Align closed curve B onto closed curve A. With `exhaustive`, every seed is refined (the test
/// oracle); otherwise the `seed_candidates` best by rotation-only energy.
pub fn align_closed(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
    exhaustive: bool,
) -> Result<Alignment, SrvfError> {
    align_closed_on(a, b, prm, exhaustive, DpOn::Host)
}

/// `align_closed` with its DPs run where `on` says.
pub(super) fn align_closed_on(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
    exhaustive: bool,
    on: DpOn,
) -> Result<Alignment, SrvfError> {
    let Resampled {
        t,
        ra,
        rb,
        q1,
        q2,
        steps,
    } = Resampled::new(a, b, prm, true)?;
    let anchored = prm.anchor > 0.0;
    let frame = AnchorFrame::of(&rb);
    let (pa, pb) = (frame.map(&ra), frame.map(&rb));
    let energies = shift_energies(&q1, &q2, prm, anchored.then_some((&pa[..], &pb[..])));
    let mut order: Vec<usize> = (0..t).collect();
    order.sort_by(|&x, &y| energies[x].0.total_cmp(&energies[y].0));
    if !exhaustive {
        order = pick_distinct_seeds(&order, t, prm.seed_candidates.max(1));
    }
    let search = SeedSearch {
        t,
        q1g: closed_grid(&q1, 0),
        pag: closed_grid(&pa, 0),
        q2,
        pb,
        energies,
        steps,
        on,
    };
    let mut best: Option<BestSeed> = None;
    if exhaustive {
        let exact = SrvfParams {
            band: 0,
            ..prm.clone()
        };
        for s in order {
            search.refine(s, &mut best, false, &exact);
        }
    } else {
        // Coarse to fine: rank the candidate seeds by a DP at <= 48 samples, then refine the two
        // best (and their neighbouring full-resolution seeds) at the full sample count. With
        // two candidates or fewer every one is refined, and the ranking is not needed: the
        // refinements do not depend on their order (only a tie of two seeds' energies to the
        // bit would keep the other one).
        let ranked: Vec<usize> = if order.len() <= REFINED_SEEDS {
            order
        } else {
            search.coarse_rank(&order, &ra, &rb, &frame, prm)
        };
        search.refine_first(&ranked, &mut best, prm);
        search.walk(&mut best, prm);
    }
    let (_, seed, theta, w) = best.expect("at least one seed is tried");
    // The shape distance alone (the position term only chose among warps).
    let energy = dist2(&search.q1g, &w.warped);
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

/// The best seed so far: its energy, the seed, its rotation and its warp.
type BestSeed = (f64, usize, f64, Warp);

/// The closed alignment's seed search: A's SRVF and positions on the closed grid, B's SRVF and
/// positions (to be started at a seed), each seed's rotation-only energy and rotation.
struct SeedSearch<'o> {
    t: usize,
    q1g: Vec<Vector2<f64>>,
    pag: Vec<Vector2<f64>>,
    q2: Vec<Vector2<f64>>,
    pb: Vec<Vector2<f64>>,
    energies: Vec<(f64, f64)>,
    steps: Vec<(usize, usize)>,
    on: DpOn<'o>,
}

impl SeedSearch<'_> {
    /// Seed `s` refined with a full DP under `p`, kept in `best` when it beats it; `near`:
    /// search a band around the best path so far, since a neighbouring seed shifts the optimal
    /// path by one cell.
    fn refine(&self, s: usize, best: &mut Option<BestSeed>, near: bool, p: &SrvfParams) {
        let hint = if near {
            best.as_ref().map(|b| b.3.path.clone())
        } else {
            None
        };
        let pbg = closed_grid(&self.pb, s);
        let (theta, w) = rotate_and_warp(
            &self.q1g,
            &closed_grid(&self.q2, s),
            self.energies[s].1,
            p,
            &self.steps,
            hint.as_deref(),
            Some(Anchor {
                a: &self.pag,
                b: &pbg,
                weight: p.anchor,
            }),
            self.on,
        );
        if best.as_ref().is_none_or(|b| w.energy < b.0) {
            *best = Some((w.energy, s, theta, w));
        }
    }

    /// The seeds `order` ranked by a DP of the curves (`ra`, `rb`, in B's anchor `frame`)
    /// resampled to at most 48 points: every candidate's coarse curves, then their alignments
    /// in step (one request a round on a device).
    fn coarse_rank(
        &self,
        order: &[usize],
        ra: &[Point2<f64>],
        rb: &[Point2<f64>],
        frame: &AnchorFrame,
        prm: &SrvfParams,
    ) -> Vec<usize> {
        let tc = self.t.min(48);
        let coarse_prm = SrvfParams {
            max_alternations: 2,
            ..prm.clone()
        };
        let (ca, _) = resample_closed(ra, tc);
        let cq1 = closed_grid(&srvf(&ca, true), 0);
        let cpa = closed_grid(&frame.map(&ca), 0);
        let coarse: Vec<SeedGrids> = order
            .iter()
            .map(|&s| {
                let (cb, _) = resample_closed(&rotate_list(rb, s), tc);
                (
                    closed_grid(&srvf(&cb, true), 0),
                    closed_grid(&frame.map(&cb), 0),
                )
            })
            .collect();
        let cands = seed_candidates(order, &coarse, &self.energies, &cpa, prm.anchor);
        let aligned = rotate_and_warp_many(&cq1, &cands, &coarse_prm, &self.steps, self.on);
        let mut ranked: Vec<(f64, usize)> = aligned
            .iter()
            .zip(order)
            .map(|((_, w), &s)| (w.energy, s))
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        ranked.into_iter().map(|(_, s)| s).collect()
    }

    /// The best `REFINED_SEEDS` of `ranked` refined at full resolution in step, then kept in
    /// rank order as one at a time would.
    fn refine_first(&self, ranked: &[usize], best: &mut Option<BestSeed>, prm: &SrvfParams) {
        let first: Vec<usize> = ranked.iter().take(REFINED_SEEDS).copied().collect();
        let grids: Vec<SeedGrids> = first
            .iter()
            .map(|&s| (closed_grid(&self.q2, s), closed_grid(&self.pb, s)))
            .collect();
        let cands = seed_candidates(&first, &grids, &self.energies, &self.pag, prm.anchor);
        let refined = rotate_and_warp_many(&self.q1g, &cands, prm, &self.steps, self.on);
        for (&s, (theta, w)) in first.iter().zip(refined) {
            if best.as_ref().is_none_or(|b| w.energy < b.0) {
                *best = Some((w.energy, s, theta, w));
            }
        }
    }

    /// The candidates are kept apart, so walk the best seed one sample at a time each way
    /// while it helps.
    fn walk(&self, best: &mut Option<BestSeed>, prm: &SrvfParams) {
        let t = self.t;
        for dir in [1usize, t - 1] {
            while let Some(current) = best.as_ref().map(|b| b.1) {
                let s = (current + dir) % t;
                self.refine(s, best, true, prm);
                if best.as_ref().map(|b| b.1) != Some(s) {
                    break;
                }
            }
        }
    }
}

/// A seed's grids: B's SRVF and B's positions, started at the seed.
type SeedGrids = (Vec<Vector2<f64>>, Vec<Vector2<f64>>);

/// The alignment candidates of `seeds` (their grids in `grids`, in the same order): each from
/// its seed's rotation in `energies`, with the position term of A's positions `pa`.
fn seed_candidates<'a>(
    seeds: &[usize],
    grids: &'a [SeedGrids],
    energies: &[(f64, f64)],
    pa: &'a [Vector2<f64>],
    weight: f64,
) -> Vec<Candidate<'a>> {
    seeds
        .iter()
        .zip(grids)
        .map(|(&s, (q2, pb))| Candidate {
            q2,
            theta: energies[s].1,
            anchor: Some(Anchor {
                a: pa,
                b: pb,
                weight,
            }),
            hint: None,
        })
        .collect()
}

/// Closed curves: seeds refined at the full sample count from the coarse ranking.
const REFINED_SEEDS: usize = 2;

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
    align_open_on(a, b, prm, DpOn::Host)
}

/// `align_open` with its DPs run where `on` says.
pub(super) fn align_open_on(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    prm: &SrvfParams,
    on: DpOn,
) -> Result<Alignment, SrvfError> {
    let Resampled {
        ra,
        rb,
        q1,
        q2,
        steps,
        ..
    } = Resampled::new(a, b, prm, false)?;
    let frame = AnchorFrame::of(&rb);
    let (pa, pb) = (frame.map(&ra), frame.map(&rb));
    let anchor = Anchor {
        a: &pa,
        b: &pb,
        weight: prm.anchor,
    };
    let (theta, w) = rotate_and_warp(
        &q1,
        &q2,
        best_rotation(&q1, &q2),
        prm,
        &steps,
        None,
        Some(anchor),
        on,
    );
    let total = polyline_length(b, false);
    let mut out = Alignment {
        distance: dist2(&q1, &w.warped).max(0.0).sqrt(),
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
