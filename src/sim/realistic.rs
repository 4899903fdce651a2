//! The realistic protocol: what separates a simulated case from a patient's X-rays, drawn per
//! run. The X-rays are made with views that are not quite where the reconstruction is told they
//! are (pose errors about the object, a magnification error), the annotator leaves out the arc
//! of the outline where the walls cross the femoral head and blur (the paper's real cases were
//! annotated so), and the traced line wanders smoothly (a Gaussian process along the outline) on
//! top of the click-to-click jitter. The reconstruction gets the nominal views and these outlines.

use super::simulate::{gaussian, observed_alpha, perturb, NoiseLevel, SimCase, SimError, SimSetup};
use crate::contours::model_contour;
use crate::geom::{Curve, Mesh};
use crate::template::Placement;
use crate::views::Camera;
use nalgebra::{Point2, Vector2};
use rand::SeedableRng;
use rand_distr::Distribution;

/// How a simulated case is made: ideal (the nominal views, the whole outline, independent
/// Gaussian noise per point) or realistic (`RealisticErrors`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum Protocol {
    /// Nominal views, closed outlines, `StudyConfig::noise_px` per point.
    Ideal,
    /// The errors of a patient's X-rays (`StudyConfig::noise_px` is not used).
    Realistic(RealisticErrors),
}

impl Protocol {
    /// The protocol's name, as `--protocol` takes it.
    pub fn name(&self) -> &'static str {
        match self {
            Protocol::Ideal => "ideal",
            Protocol::Realistic(_) => "realistic",
        }
    }
}

/// The realistic protocol's error sizes (defaults: issue 17's).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RealisticErrors {
    /// Per-view pose error: rotation SD per axis about the object's centre, degrees (default 1).
    /// The first view defines the frame and is exact, as the AP view does in practice.
    pub pose_deg: f64,
    /// Per-view pose error: translation SD per axis, mm at the object (default 2).
    pub pose_mm: f64,
    /// Per-view magnification error, relative SD (default 0.02): the view's true focal length
    /// is the nominal one times 1 + N(0, SD).
    pub magnification: f64,
    /// Share of each outline's length left out, one arc centred where the template's opening
    /// axis points in the image (the walls over the femoral head; default 0.25; 0 keeps the
    /// outline closed).
    pub left_out: f64,
    /// Smooth annotation drift: SD of a Gaussian process along the outline, px, per image axis
    /// (default 2) ...
    pub drift_px: f64,
    /// ... with this correlation length along the outline, px (default 20).
    pub drift_length_px: f64,
    /// Independent jitter per point, px (default 1).
    pub jitter_px: f64,
    /// Distance between the annotator's clicks along the outline, px: the kept outline is
    /// replaced by points this far apart (a polygon, as a rim clicked point by point), before
    /// the drift and jitter; the method gets them as clicks (the curve through them,
    /// `Curve::clicked`, as from a case file's `"clicked": true`) unless `raster_px` reads them
    /// off a mask. 0 (the default) keeps the outline's own points, a few px apart, as a traced
    /// line.
    pub click_px: f64,
    /// The annotation as a segmentation mask's boundary gives it: the traced line (after the
    /// drift and jitter) read off a grid of this pitch, px, as the chain of cells it passes
    /// through, each cell's centre once, consecutive ones 8-neighbours (a staircase; 1: the
    /// image's own pixels, 4: a mask made at a quarter of the resolution). 0 (the default)
    /// keeps the traced points.
    pub raster_px: f64,
}

impl Default for RealisticErrors {
    fn default() -> Self {
        RealisticErrors {
            pose_deg: 1.0,
            pose_mm: 2.0,
            magnification: 0.02,
            left_out: 0.25,
            drift_px: 2.0,
            drift_length_px: 20.0,
            jitter_px: 1.0,
            click_px: 0.0,
            raster_px: 0.0,
        }
    }
}

/// Largest pose error SDs the protocol takes, degrees and mm: beyond them a view is another
/// view, not an error of one.
pub const MAX_POSE_DEG: f64 = 30.0;
/// See `MAX_POSE_DEG`.
pub const MAX_POSE_MM: f64 = 100.0;
/// Largest annotation drift or jitter SD, px: an outline is a few hundred px across.
pub const MAX_NOISE_PX: f64 = 100.0;

impl RealisticErrors {
    /// Every error but the point jitter set to zero: the nominal poses and scale, whole
    /// outlines, no drift, `jitter_px` of jitter (0 gives the ideal outline itself).
    pub fn jitter_only(jitter_px: f64) -> Self {
        RealisticErrors {
            pose_deg: 0.0,
            pose_mm: 0.0,
            magnification: 0.0,
            left_out: 0.0,
            drift_px: 0.0,
            jitter_px,
            ..RealisticErrors::default()
        }
    }

    /// The first setting no draw can be made with: SDs that are not finite and >= 0, or beyond
    /// what could still be one view's error (`MAX_POSE_DEG`, `MAX_POSE_MM`, `MAX_NOISE_PX`: a
    /// pose SD of 1e300 degrees ran every run into "cannot be projected" without naming the
    /// setting), a magnification SD of 0.2 or more (a focal length could turn negative), a
    /// left-out share outside [0, 0.6], a correlation length that is not finite and > 0.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |field, value: f64, expected| {
            Err(SimError::Setting {
                field,
                value: crate::io::shown(&value.to_string()),
                expected,
            })
        };
        for (field, v, max, expected) in [
            (
                "realistic pose_deg",
                self.pose_deg,
                MAX_POSE_DEG,
                "an SD of 0 to 30 degrees",
            ),
            (
                "realistic pose_mm",
                self.pose_mm,
                MAX_POSE_MM,
                "an SD of 0 to 100 mm",
            ),
            (
                "realistic drift_px",
                self.drift_px,
                MAX_NOISE_PX,
                "an SD of 0 to 100 px",
            ),
            (
                "realistic jitter_px",
                self.jitter_px,
                MAX_NOISE_PX,
                "an SD of 0 to 100 px",
            ),
        ] {
            if !(v.is_finite() && (0.0..=max).contains(&v)) {
                return bad(field, v, expected);
            }
        }
        if !(self.magnification.is_finite() && (0.0..0.2).contains(&self.magnification)) {
            return bad(
                "realistic magnification",
                self.magnification,
                "a relative SD in [0, 0.2)",
            );
        }
        if !(self.left_out.is_finite() && (0.0..=0.6).contains(&self.left_out)) {
            return bad("realistic left_out", self.left_out, "a share in [0, 0.6]");
        }
        if !(self.click_px.is_finite() && self.click_px >= 0.0) {
            return bad(
                "realistic click_px",
                self.click_px,
                "a finite distance >= 0 (0: the outline's own points)",
            );
        }
        if !(self.raster_px.is_finite() && (0.0..=MAX_NOISE_PX).contains(&self.raster_px)) {
            return bad(
                "realistic raster_px",
                self.raster_px,
                "a grid pitch of 0 to 100 px (0: the traced points)",
            );
        }
        if !(self.drift_length_px.is_finite() && self.drift_length_px > 0.0) {
            return bad(
                "realistic drift_length_px",
                self.drift_length_px,
                "a finite length > 0",
            );
        }
        Ok(())
    }
}

/// Fewest outline points an annotation keeps after its arc is left out.
const MIN_KEPT_POINTS: usize = 8;

impl SimSetup {
    /// One realistic run of `truth` (the mesh this set-up was made from): true views drawn about
    /// the nominal ones, the truth's outlines in them, an arc left out, drift and jitter added,
    /// the start perturbed by `level`; all draws from ChaCha8(seed). The case carries the
    /// nominal views.
    pub fn realistic_case(
        &self,
        truth: &Mesh,
        errors: &RealisticErrors,
        level: &NoiseLevel,
        seed: u64,
    ) -> Result<SimCase, SimError> {
        let (given, init) = self.realistic_annotations(truth, errors, level, seed)?;
        let clicks = given
            .iter()
            .map(|view| {
                if handed_on_as_clicks(errors) {
                    view.iter().flat_map(|c| c.points.iter().copied()).collect()
                } else {
                    Vec::new()
                }
            })
            .collect();
        let observed = given
            .into_iter()
            .map(|view| view.into_iter().map(|c| handed_on(c, errors)).collect())
            .collect();
        Ok(SimCase {
            clicks,
            ..self.case_of(observed, init, seed)
        })
    }

    /// The draws of `realistic_case`: each view's annotation as the annotator gave it (with
    /// `click_px`, the clicks themselves, before the curve through them that the case carries),
    /// and the perturbed start.
    pub fn realistic_annotations(
        &self,
        truth: &Mesh,
        errors: &RealisticErrors,
        level: &NoiseLevel,
        seed: u64,
    ) -> Result<(Vec<Vec<Curve>>, Placement), SimError> {
        errors.validate()?;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let init = perturb(&self.placement, level, &mut rng)?;
        let rot = gaussian("realistic pose_deg", errors.pose_deg.to_radians())?;
        let shift = gaussian("realistic pose_mm", errors.pose_mm)?;
        let mag = gaussian("realistic magnification", errors.magnification)?;
        let mut observed = Vec::with_capacity(self.cameras.len());
        for (view, nominal) in self.cameras.iter().enumerate() {
            let mut x = [0.0; 6];
            if view > 0 {
                for v in x[..3].iter_mut() {
                    *v = rot.sample(&mut rng);
                }
                for v in x[3..].iter_mut() {
                    *v = shift.sample(&mut rng);
                }
            }
            let mut cam = crate::solve::corrected_camera(nominal, &self.placement.center, &x);
            let m = 1.0 + mag.sample(&mut rng);
            cam.k.fx *= m;
            cam.k.fy *= m;
            let outline = model_contour(
                truth,
                &cam,
                Some(observed_alpha(truth, &cam, &self.placement)),
            )
            .map_err(|source| SimError::Contour { view, source })?;
            let curve =
                annotate(&outline.points, &cam, self, errors, &mut rng).map_err(|count| {
                    SimError::Annotation {
                        view,
                        count,
                        outline: outline.points.len(),
                        left_out: errors.left_out,
                        click_px: errors.click_px,
                        raster_px: errors.raster_px,
                        min: MIN_KEPT_POINTS,
                    }
                })?;
            observed.push(vec![curve]);
        }
        Ok((observed, init))
    }
}

/// An annotation as the method gets it: clicks (`click_px`, not read off a mask) as the curve
/// through them (`Curve::clicked`), as a case file's `"clicked": true` gives them; a traced line
/// or a mask's boundary as it is.
fn handed_on(curve: Curve, e: &RealisticErrors) -> Curve {
    if handed_on_as_clicks(e) {
        curve.clicked()
    } else {
        curve
    }
}

/// Whether the annotations under `e` reach the method as clicks (see `handed_on`).
fn handed_on_as_clicks(e: &RealisticErrors) -> bool {
    e.click_px > 0.0 && e.raster_px == 0.0
}

/// An annotator's trace of the closed outline `pts` seen by `cam`: the left-out arc removed,
/// then the drift and the jitter added; or, where fewer than `MIN_KEPT_POINTS` are left, how
/// many are.
fn annotate(
    pts: &[Point2<f64>],
    cam: &Camera,
    setup: &SimSetup,
    e: &RealisticErrors,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Result<Curve, usize> {
    let (kept, closed) = leave_out_arc(pts, cam, setup, e.left_out);
    let kept = if e.click_px > 0.0 {
        clicked(&kept, closed, e.click_px)
    } else {
        kept
    };
    if kept.len() < MIN_KEPT_POINTS {
        return Err(kept.len());
    }
    let s = arc_positions(&kept);
    let total = s.last().copied().unwrap_or(0.0)
        + if closed {
            (kept[0] - kept[kept.len() - 1]).norm()
        } else {
            0.0
        };
    let drift_x = smooth_process(&s, total, closed, e.drift_px, e.drift_length_px, rng);
    let drift_y = smooth_process(&s, total, closed, e.drift_px, e.drift_length_px, rng);
    let jitter = rand_distr::Normal::new(0.0, e.jitter_px).expect("validated SD");
    let points: Vec<Point2<f64>> = kept
        .iter()
        .enumerate()
        .map(|(i, p)| {
            p + Vector2::new(
                drift_x[i] + jitter.sample(rng),
                drift_y[i] + jitter.sample(rng),
            )
        })
        .collect();
    let points = if e.raster_px > 0.0 {
        pixel_chain(&points, closed, e.raster_px)
    } else {
        points
    };
    if points.len() < MIN_KEPT_POINTS {
        return Err(points.len());
    }
    Ok(Curve { points, closed })
}

/// The traced line `pts` as the boundary of a mask on a grid of pitch `pitch` px (cell centres
/// on whole multiples of it) gives it: the cells the line passes through, in order along it,
/// each as its centre; a step straight back into the cell just left drops the cell it came from
/// (the line wandered along a cell border), and a closed line's last cells that repeat its
/// first are dropped. The line is read every quarter cell, so consecutive cells are
/// 8-neighbours: a staircase.
fn pixel_chain(pts: &[Point2<f64>], closed: bool, pitch: f64) -> Vec<Point2<f64>> {
    let cell = |p: Point2<f64>| ((p.x / pitch).round() as i64, (p.y / pitch).round() as i64);
    let mut chain: Vec<(i64, i64)> = Vec::with_capacity(pts.len());
    let mut push = |c: (i64, i64)| {
        let n = chain.len();
        if chain.last() == Some(&c) {
            return; // still in the same cell
        }
        if n >= 2 && chain[n - 2] == c {
            chain.pop(); // straight back: the cell just left was a wander along the border
        } else {
            chain.push(c);
        }
    };
    let n = pts.len();
    if let Some(&first) = pts.first() {
        push(cell(first));
    }
    let segments = if closed { n } else { n.saturating_sub(1) };
    for i in 0..segments {
        let (a, b) = (pts[i], pts[(i + 1) % n]);
        let samples = ((b - a).norm() / (0.25 * pitch)).ceil().max(1.0) as usize;
        for k in 1..=samples {
            push(cell(a + (b - a) * (k as f64 / samples as f64)));
        }
    }
    if closed {
        while chain.len() > 1 && chain.last() == chain.first() {
            chain.pop();
        }
    }
    chain
        .into_iter()
        .map(|(x, y)| Point2::new(x as f64 * pitch, y as f64 * pitch))
        .collect()
}

/// The outline `pts` as an annotator clicks it: points evenly spaced along its arc length,
/// about `step` px apart (a closed outline from its first point round; an open one from end
/// to end, both ends kept).
fn clicked(pts: &[Point2<f64>], closed: bool, step: f64) -> Vec<Point2<f64>> {
    let total = crate::geom::polyline_length(pts, closed);
    let gaps = (total / step).round().max(1.0) as usize;
    if closed {
        crate::geom::resample_closed(pts, gaps).0
    } else {
        crate::geom::resample_open(pts, gaps + 1).0
    }
}

/// `pts` without the arc of `share` of its length centred on the point farthest along the
/// image direction of the truth's opening axis; the rest as an open curve that starts just
/// after the gap (or the whole closed outline when `share` is 0).
fn leave_out_arc(
    pts: &[Point2<f64>],
    cam: &Camera,
    setup: &SimSetup,
    share: f64,
) -> (Vec<Point2<f64>>, bool) {
    let n = pts.len();
    if share <= 0.0 || n < 3 {
        return (pts.to_vec(), true);
    }
    let c = setup.placement.center;
    let tip = c + setup.placement.axis.into_inner() * setup.placement.radius;
    let dir = match (cam.project(&c), cam.project(&tip)) {
        (Ok(a), Ok(b)) if (b - a).norm() > 1e-9 => (b - a).normalize(),
        // The axis points along the ray: no side faces the head more than another.
        _ => Vector2::new(0.0, 1.0),
    };
    let mid = (0..n)
        .max_by(|&i, &j| dir.dot(&pts[i].coords).total_cmp(&dir.dot(&pts[j].coords)))
        .unwrap_or(0);
    let seg = |i: usize| (pts[(i + 1) % n] - pts[i]).norm();
    let total: f64 = (0..n).map(seg).sum();
    let half = 0.5 * share * total;
    // Walk out from `mid` both ways until half the left-out length is covered on each side.
    let (mut fwd, mut len) = (0, 0.0);
    while len < half && fwd < n {
        len += seg((mid + fwd) % n);
        fwd += 1;
    }
    let (mut back, mut len) = (0, 0.0);
    while len < half && back < n {
        back += 1;
        len += seg((mid + n - back) % n);
    }
    let dropped = (fwd + back + 1).min(n);
    let start = (mid + fwd + 1) % n;
    let kept = (0..n - dropped).map(|k| pts[(start + k) % n]).collect();
    (kept, false)
}

/// Arc length at each point of `pts` from the first.
fn arc_positions(pts: &[Point2<f64>]) -> Vec<f64> {
    let mut s = Vec::with_capacity(pts.len());
    let mut acc = 0.0;
    for (i, p) in pts.iter().enumerate() {
        if i > 0 {
            acc += (p - pts[i - 1]).norm();
        }
        s.push(acc);
    }
    s
}

/// A Gaussian process with SD `sd` and squared-exponential correlation of length `length` along
/// the curve, sampled at arc positions `s` (periodic over `total` when `closed`): white noise
/// on a grid of `length`/4 spacing, smoothed by a Gaussian kernel of width `length`/sqrt 2 (the
/// convolution's covariance has length `length`), read at each position by its grid
/// neighbours, and scaled to SD `sd`.
fn smooth_process(
    s: &[f64],
    total: f64,
    closed: bool,
    sd: f64,
    length: f64,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Vec<f64> {
    if sd == 0.0 || s.is_empty() {
        return vec![0.0; s.len()];
    }
    let h = length / 4.0;
    let width = length / std::f64::consts::SQRT_2;
    let reach = (3.0 * width / h).ceil() as i64;
    // Grid over the curve (and `reach` beyond each end of an open one).
    let cells = ((total / h).ceil() as i64).max(1);
    let (lo, hi) = if closed {
        (0, cells)
    } else {
        (-reach, cells + reach + 1)
    };
    let white: Vec<f64> = (lo..hi)
        .map(|_| rand_distr::StandardNormal.sample(rng))
        .collect();
    let kernel: Vec<f64> = (-reach..=reach)
        .map(|k| (-0.5 * (k as f64 * h / width).powi(2)).exp())
        .collect();
    let norm = kernel.iter().map(|k| k * k).sum::<f64>().sqrt();
    let at_cell = |c: i64| -> f64 {
        (-reach..=reach)
            .map(|k| {
                let j = if closed {
                    (c + k).rem_euclid(cells)
                } else {
                    (c + k).clamp(lo, hi - 1)
                };
                kernel[(k + reach) as usize] * white[(j - lo) as usize]
            })
            .sum::<f64>()
            / norm
    };
    s.iter()
        .map(|&x| {
            let f = x / h;
            let c = f.floor() as i64;
            let t = f - c as f64;
            sd * ((1.0 - t) * at_cell(c) + t * at_cell(c + 1))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{phantom, PhantomParams, XrayGeometry};

    fn setup() -> (Mesh, SimSetup) {
        let truth = phantom(&PhantomParams::default()).mesh;
        let s = SimSetup::new(&truth, &XrayGeometry::default()).unwrap();
        (truth, s)
    }

    #[test]
    fn the_drift_has_the_sd_and_correlation_length_asked_for() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let s: Vec<f64> = (0..400).map(|i| i as f64 * 2.0).collect();
        let (mut v0, mut c10, mut c40, mut n) = (0.0, 0.0, 0.0, 0.0);
        for _ in 0..200 {
            let d = smooth_process(&s, 800.0, true, 2.0, 20.0, &mut rng);
            for i in 0..s.len() {
                v0 += d[i] * d[i];
                c10 += d[i] * d[(i + 5) % s.len()];
                c40 += d[i] * d[(i + 20) % s.len()];
                n += 1.0;
            }
        }
        let sd = (v0 / n).sqrt();
        let (r10, r40) = (c10 / v0, c40 / v0);
        assert!((sd - 2.0).abs() < 0.15, "sd {sd}");
        // Squared-exponential of length 20: exp(-1/8) = 0.88 at 10 px, exp(-2) = 0.14 at 40.
        assert!((r10 - 0.88).abs() < 0.06, "10 px: {r10}");
        assert!((r40 - 0.135).abs() < 0.08, "40 px: {r40}");
        // Companion: white jitter's correlation at 10 px is near zero, which the test refuses.
        let white: Vec<f64> = (0..400)
            .map(|_| rand_distr::StandardNormal.sample(&mut rng))
            .collect();
        let w10: f64 = (0..400)
            .map(|i| white[i] * white[(i + 5) % 400])
            .sum::<f64>()
            / white.iter().map(|x| x * x).sum::<f64>();
        assert!(
            (w10 - 0.88).abs() >= 0.06,
            "white noise passed as drift: {w10}"
        );
    }

    #[test]
    fn a_realistic_case_leaves_out_an_arc_and_moves_the_outline_by_the_errors() {
        let (truth, s) = setup();
        let level = NoiseLevel::level(1).unwrap();
        let e = RealisticErrors::default();
        let case = s.realistic_case(&truth, &e, &level, 11).unwrap();
        assert_eq!(
            case.cameras, s.cameras,
            "the reconstruction gets the nominal views"
        );
        for (v, curves) in case.observed.iter().enumerate() {
            let c = &curves[0];
            assert!(!c.closed);
            let full = crate::geom::polyline_length(&s.outlines[v], true);
            let kept = crate::geom::polyline_length(&c.points, false);
            assert!(
                (0.6..0.8).contains(&(kept / full)),
                "view {v}: kept {kept:.0} of {full:.0} px"
            );
        }
        // Same seed, same case; another seed, another.
        let again = s.realistic_case(&truth, &e, &level, 11).unwrap();
        assert_eq!(case.observed[1][0].points, again.observed[1][0].points);
        let other = s.realistic_case(&truth, &e, &level, 12).unwrap();
        assert_ne!(case.observed[1][0].points, other.observed[1][0].points);
        // No errors and nothing left out: the ideal outline, closed and exact.
        let none = RealisticErrors::jitter_only(0.0);
        let exact = s.realistic_case(&truth, &none, &level, 11).unwrap();
        for v in 0..s.cameras.len() {
            assert!(exact.observed[v][0].closed);
            assert_eq!(exact.observed[v][0].points, s.outlines[v]);
        }
        // A 5 % magnification error is seen: the outline grows about the principal point.
        let big = RealisticErrors {
            magnification: 0.05,
            ..none.clone()
        };
        let grown = (0..20)
            .map(|seed| {
                let c = s.realistic_case(&truth, &big, &level, seed).unwrap();
                let l = crate::geom::polyline_length(&c.observed[0][0].points, true);
                (l / crate::geom::polyline_length(&s.outlines[0], true) - 1.0).abs()
            })
            .fold(0.0, f64::max);
        assert!(grown > 0.03, "magnification not applied: {grown}");
    }

    /// Clicks 20 px apart: each annotation is a polygon of about its length / 20 points, 20 px
    /// apart give or take the drift and jitter, over the same arc, and the method gets the curve
    /// through them; the default keeps the outline's own points, a few px apart, and hands them
    /// on as they are (the companions: clicks not applied are told apart, and a traced line is
    /// not taken for clicks).
    #[test]
    fn clicks_make_the_annotation_a_polygon_of_points_that_far_apart() {
        let (truth, s) = setup();
        let level = NoiseLevel::level(1).unwrap();
        let dense = RealisticErrors::default();
        let clicks = RealisticErrors {
            click_px: 20.0,
            ..dense.clone()
        };
        let spacing = |c: &Curve| {
            let mut d: Vec<f64> = c.points.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        };
        let a = s.realistic_case(&truth, &dense, &level, 5).unwrap();
        let (given, _) = s.realistic_annotations(&truth, &clicks, &level, 5).unwrap();
        let handed = s.realistic_case(&truth, &clicks, &level, 5).unwrap();
        let (traced, _) = s.realistic_annotations(&truth, &dense, &level, 5).unwrap();
        for v in 0..s.cameras.len() {
            let (da, db) = (&a.observed[v][0], &given[v][0]);
            assert_eq!(handed.observed[v][0], db.clicked());
            // The case keeps the clicks for the overlays; a traced line has none.
            assert_eq!(handed.clicks[v], db.points);
            assert!(a.clicks[v].is_empty());
            assert!(handed.observed[v][0].points.len() > db.points.len());
            assert_eq!(*da, traced[v][0]);
            assert!(!db.closed);
            let length = crate::geom::polyline_length(&db.points, false);
            assert!(
                (17.0..23.0).contains(&spacing(db)),
                "view {v}: {}",
                spacing(db)
            );
            assert!(
                (db.points.len() as f64 - length / 20.0 - 1.0).abs() < 0.15 * length / 20.0,
                "view {v}: {} points over {length:.0} px",
                db.points.len()
            );
            assert!(
                spacing(da) < 10.0,
                "view {v}: the default's {}",
                spacing(da)
            );
            let kept = crate::geom::polyline_length(&da.points, false);
            assert!((length / kept - 1.0).abs() < 0.1, "{length} against {kept}");
        }
        // Companion: a negative or infinite distance is refused, naming the setting.
        for bad in [-1.0, f64::INFINITY] {
            let e = RealisticErrors {
                click_px: bad,
                ..dense.clone()
            };
            let err = s
                .realistic_case(&truth, &e, &level, 5)
                .unwrap_err()
                .to_string();
            assert!(err.contains("click_px"), "{err}");
        }
        // Clicks farther apart than the outline is long leave too few points: refused as the
        // annotation's, with the count and the setting, not as the truth's outline.
        let sparse = RealisticErrors {
            click_px: 1e9,
            ..dense.clone()
        };
        let err = s.realistic_case(&truth, &sparse, &level, 5).unwrap_err();
        assert!(
            matches!(err, SimError::Annotation { view: 0, count, click_px, .. }
                if count < MIN_KEPT_POINTS && click_px == 1e9),
            "{err}"
        );
        let err = err.to_string();
        assert!(
            err.contains("simulated annotation in view 0") && err.contains("click_px 1000000000"),
            "{err}"
        );
    }

    /// A mask's boundary: with `raster_px` every annotation point is the centre of a grid cell,
    /// consecutive points (round the closed outline) are 8-neighbours, every point lies within
    /// half a cell's diagonal of the outline and every outline point within a cell of the
    /// chain. The companions: without it the points are off the grid; a pitch below 0, above
    /// 100 px or not finite is refused naming the setting.
    #[test]
    fn a_mask_boundary_is_a_staircase_of_grid_cells_along_the_outline() {
        let (truth, s) = setup();
        let level = NoiseLevel::level(1).unwrap();
        let exact = RealisticErrors::jitter_only(0.0);
        let on_grid = |p: &Point2<f64>, pitch: f64| {
            (p.x / pitch).fract() == 0.0 && (p.y / pitch).fract() == 0.0
        };
        for pitch in [1.0, 4.0] {
            let e = RealisticErrors {
                raster_px: pitch,
                ..exact.clone()
            };
            let case = s.realistic_case(&truth, &e, &level, 5).unwrap();
            for v in 0..s.cameras.len() {
                let c = &case.observed[v][0];
                assert!(c.closed);
                let n = c.points.len();
                let outline = &s.outlines[v];
                let length = crate::geom::polyline_length(outline, true);
                assert!(
                    n as f64 > 0.7 * length / pitch,
                    "view {v}: {n} cells over {length:.0} px"
                );
                for (i, p) in c.points.iter().enumerate() {
                    assert!(on_grid(p, pitch), "view {v}: {p:?}");
                    let d = (c.points[(i + 1) % n] - p) / pitch;
                    assert!(
                        d.x.abs() <= 1.0 && d.y.abs() <= 1.0 && d.norm() > 0.0,
                        "view {v}: step {d:?} at {i}"
                    );
                }
                let far = |from: &[Point2<f64>], to: &[Point2<f64>]| {
                    let segs = crate::geom::Segments::new(to, true);
                    from.iter().map(|p| segs.distance(p)).fold(0.0, f64::max)
                };
                assert!(far(&c.points, outline) <= 0.5 * std::f64::consts::SQRT_2 * pitch + 1e-9);
                assert!(far(outline, &c.points) <= pitch);
            }
        }
        // Companion: the traced points, off the grid.
        let traced = s.realistic_case(&truth, &exact, &level, 5).unwrap();
        let off = traced.observed[0][0]
            .points
            .iter()
            .filter(|p| !on_grid(p, 1.0))
            .count();
        assert!(off > traced.observed[0][0].points.len() / 2, "{off}");
        for bad in [-1.0, 101.0, f64::NAN] {
            let e = RealisticErrors {
                raster_px: bad,
                ..exact.clone()
            };
            let err = s
                .realistic_case(&truth, &e, &level, 5)
                .unwrap_err()
                .to_string();
            assert!(err.contains("raster_px"), "{err}");
        }
    }

    #[test]
    fn realistic_settings_no_draw_can_be_made_with_are_refused() {
        let (truth, s) = setup();
        let level = NoiseLevel::level(1).unwrap();
        let ok = RealisticErrors::default();
        for bad in [
            RealisticErrors {
                pose_deg: f64::NAN,
                ..ok.clone()
            },
            RealisticErrors {
                jitter_px: -1.0,
                ..ok.clone()
            },
            RealisticErrors {
                magnification: 0.5,
                ..ok.clone()
            },
            RealisticErrors {
                left_out: 0.9,
                ..ok.clone()
            },
            RealisticErrors {
                drift_length_px: 0.0,
                ..ok.clone()
            },
            // Finite but beyond any one view's error: named, not run into unprojectable views.
            RealisticErrors {
                pose_deg: 1e300,
                ..ok.clone()
            },
            RealisticErrors {
                pose_mm: 101.0,
                ..ok.clone()
            },
            RealisticErrors {
                drift_px: 1e9,
                ..ok.clone()
            },
        ] {
            assert!(matches!(
                s.realistic_case(&truth, &bad, &level, 1),
                Err(SimError::Setting { .. })
            ));
        }
        let e = RealisticErrors {
            pose_deg: 1e300,
            ..ok.clone()
        };
        let msg = e.validate().unwrap_err().to_string();
        assert!(
            msg.contains("pose_deg = 1e300") && msg.contains("0 to 30 degrees"),
            "{msg}"
        );
        assert!(s.realistic_case(&truth, &ok, &level, 1).is_ok());
        // Companion: the largest errors taken still make a case.
        let edge = RealisticErrors {
            pose_deg: MAX_POSE_DEG,
            pose_mm: MAX_POSE_MM,
            ..ok.clone()
        };
        assert!(edge.validate().is_ok());
    }
}
