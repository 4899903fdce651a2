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
        let as_clicks = handed_on_as_clicks(errors);
        let clicks = given
            .iter()
            .map(|view| {
                if as_clicks {
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
mod tests;
