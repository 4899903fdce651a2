//! The cup's orientation from the rim: the acetabular rim is a circle on the cup sphere, and
//! where an outline runs inside the sphere's projected limb it is that circle's projection. The
//! outlines are sampled evenly along their length (so a rim clicked point by point and the same
//! rim traced densely weigh alike), and the circle (its axis and its height along the axis) is
//! fitted to the samples inside the limb in every view at once, robustly (the best 70 % of the
//! samples: bridged notches and drift fall out), by a grid over the axis then a shrinking
//! pattern search. Inclination and anteversion follow
//! Murray's radiographic definitions in the case's body frame (x lateral, y anterior, z
//! superior; the lateral side is whichever way the cup opens).

use crate::geom::{
    par_map, polyline_length, resample_closed, resample_open, Curve, Segments, Sphere,
};
use crate::views::Camera;
use nalgebra::{Point2, Point3, Unit, Vector3};

/// Outline points closer to the projected sphere centre than this share of its projected radius
/// are taken for the rim (the rest run along the limb); also the share by which SRVF's pairs the
/// rim makes are told (`pipeline::RimPairs`).
pub const RIM_WITHIN: f64 = 0.93;
/// Share of the rim points (the closest to the circle) the fit is scored on.
const KEEP: f64 = 0.7;
/// Samples of the projected circle.
const CIRCLE_SAMPLES: usize = 72;
/// Spacing of the outline samples, as an angle of the sphere's projected limb (radians): the
/// same samples at any image resolution.
const SAMPLE_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// The grid's quick look scores every this many samples.
const COARSE_EVERY: usize = 3;
/// Closest spacing of the samples, pixels, and most samples an outline gives (a sphere too
/// small or an outline too long for any image is not sampled without end).
const MIN_SPACING_PX: f64 = 0.5;
const MAX_SAMPLES: usize = 20_000;
/// Fewest rim samples (40 degrees of the limb in all), over at least two views.
const MIN_POINTS: usize = 20;

/// The rim circle fitted to the outlines, and the cup's orientation from it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RimFit {
    /// The opening axis (unit, from the sphere centre out through the rim).
    pub axis: [f64; 3],
    /// The rim circle's centre along the axis from the sphere centre, mm (negative: the rim is
    /// short of a hemisphere).
    pub offset_mm: f64,
    /// Radiographic inclination, degrees (Murray): the axis against the longitudinal axis, in
    /// the coronal plane.
    pub inclination_deg: f64,
    /// Radiographic anteversion, degrees (Murray): the axis against the coronal plane.
    pub anteversion_deg: f64,
    /// RMS distance of the kept rim points to the projected circle, pixels.
    pub rms_px: f64,
    /// Rim samples used (all views; one every 2 degrees of the sphere's projected limb).
    pub points: usize,
}

/// Why no orientation came out.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RimError {
    /// Too few outline points inside the limb to trace a rim.
    #[error("cup orientation: {points} outline samples (one every 2 degrees of the sphere's limb) run inside the limb in {views} views; the rim needs {MIN_POINTS} in at least two")]
    TooFewPoints {
        /// Samples found.
        points: usize,
        /// Views with any.
        views: usize,
    },
    /// The sphere is unusable (not finite, not in front of the views).
    #[error("cup orientation: the sphere (centre {center:?}, radius {radius}) does not project into every view")]
    Sphere {
        /// Its centre.
        center: [f64; 3],
        /// Its radius.
        radius: f64,
    },
}

/// Radiographic anteversion and inclination (degrees) of an opening axis.
pub fn radiographic_angles(axis: &Vector3<f64>) -> (f64, f64) {
    let n = axis.normalize();
    (
        n.y.clamp(-1.0, 1.0).asin().to_degrees(),
        n.x.abs().atan2(-n.z).to_degrees(),
    )
}

/// The axis of anteversion `a` and inclination `i` (degrees; a negative `i` opens towards -x).
fn axis_of(a: f64, i: f64) -> Vector3<f64> {
    let (a, i) = (a.to_radians(), i.to_radians());
    Vector3::new(a.cos() * i.sin(), a.sin(), -a.cos() * i.cos())
}

/// Fit the rim circle on `sphere` to the outlines' rim points.
pub fn rim_orientation(
    cams: &[Camera],
    observed: &[Vec<Curve>],
    sphere: &Sphere,
) -> Result<RimFit, RimError> {
    let c = sphere.center_point();
    let r = sphere.radius;
    let bad_sphere = || RimError::Sphere {
        center: sphere.center,
        radius: r,
    };
    if !(r.is_finite() && r > 0.0) {
        return Err(bad_sphere());
    }
    let mut rim: Vec<Vec<Point2<f64>>> = Vec::with_capacity(cams.len());
    for (cam, curves) in cams.iter().zip(observed) {
        let cp = cam.project(&c).map_err(|_| bad_sphere())?;
        let rpx = r * cam.pixels_per_mm_at(&c);
        rim.push(
            curves
                .iter()
                .flat_map(|cv| even_samples(cv, SAMPLE_RAD * rpx))
                .filter(|p| (*p - cp).norm() < RIM_WITHIN * rpx)
                .collect(),
        );
    }
    let points: usize = rim.iter().map(Vec::len).sum();
    let views = rim.iter().filter(|v| !v.is_empty()).count();
    if points < MIN_POINTS || views < 2 {
        return Err(RimError::TooFewPoints { points, views });
    }
    let fit = RimCost {
        cams,
        rim,
        c,
        r,
        coarse_turn: circle_turn(36),
        fine_turn: circle_turn(CIRCLE_SAMPLES),
    };
    let best = fit.pattern_search(fit.grid_best(points), points);
    let n = Unit::new_normalize(axis_of(best.1, best.2));
    let (anteversion_deg, inclination_deg) = radiographic_angles(&n);
    Ok(RimFit {
        axis: [n.x, n.y, n.z],
        offset_mm: best.3,
        inclination_deg,
        anteversion_deg,
        rms_px: best.0.sqrt(),
        points,
    })
}

/// A circle's (cos, sin) at `samples` angles evenly round it.
fn circle_turn(samples: usize) -> Vec<(f64, f64)> {
    (0..samples)
        .map(|k| {
            let t = k as f64 * std::f64::consts::TAU / samples as f64;
            (t.cos(), t.sin())
        })
        .collect()
}

/// A rim circle's fit: (mean squared distance of the kept rim points, px^2; anteversion and
/// inclination of its axis, degrees; its height above the sphere's centre, mm).
type RimCandidate = (f64, f64, f64, f64);

/// The rim points of each view (`rim`) against circles on the sphere (centre `c`, radius `r`).
struct RimCost<'a> {
    cams: &'a [Camera],
    rim: Vec<Vec<Point2<f64>>>,
    c: Point3<f64>,
    r: f64,
    /// The circle's (cos, sin) at its samples' angles, the same every evaluation: 36 for the
    /// grid's quick look, `CIRCLE_SAMPLES` in full.
    coarse_turn: Vec<(f64, f64)>,
    fine_turn: Vec<(f64, f64)>,
}

impl RimCost<'_> {
    /// The mean squared distance of the best `KEEP` share of the rim points to the circle of
    /// axis `n` at height `h`; `coarse`: every `COARSE_EVERY`th point against the 36-point
    /// circle. `d2` is the caller's buffer.
    fn cost(&self, n: &Vector3<f64>, h: f64, coarse: bool, d2: &mut Vec<f64>) -> f64 {
        let trig = if coarse {
            &self.coarse_turn
        } else {
            &self.fine_turn
        };
        let u = n
            .cross(&if n.x.abs() < 0.9 {
                Vector3::x()
            } else {
                Vector3::y()
            })
            .normalize();
        let v = n.cross(&u);
        let rr = (self.r * self.r - h * h).max(0.0).sqrt();
        let cc: Point3<f64> = self.c + n * h;
        d2.clear();
        for (cam, pts) in self.cams.iter().zip(&self.rim) {
            if pts.is_empty() {
                continue;
            }
            let circle: Vec<Point2<f64>> = trig
                .iter()
                .filter_map(|&(c, s)| cam.project(&(cc + (u * c + v * s) * rr)).ok())
                .collect();
            if circle.len() < 3 {
                return f64::INFINITY;
            }
            let segs = Segments::new(&circle, true);
            let every = if coarse { COARSE_EVERY } else { 1 };
            d2.extend(pts.iter().step_by(every).map(|p| segs.distance(p).powi(2)));
        }
        d2.sort_by(f64::total_cmp);
        let k = ((d2.len() as f64 * KEEP) as usize).max(1);
        d2[..k].iter().sum::<f64>() / k as f64
    }

    /// The grid over the opening axis (it always points inferiorly) and the rim's height. The
    /// grid's rows (one anteversion each) are scored side by side; its best is the first lowest
    /// in row order, as one pass over the grid would keep it. `points`: the rim points (the
    /// buffers' size).
    fn grid_best(&self, points: usize) -> RimCandidate {
        let r = self.r;
        let rows: Vec<i32> = (-40..=70).step_by(6).collect();
        let row_best = par_map(&rows, |_, &a| {
            let mut d2 = Vec::with_capacity(points);
            let mut best = (f64::INFINITY, 0.0, 0.0, 0.0);
            for i in (-84..=84).step_by(6) {
                for hk in [-0.3, -0.15, 0.0, 0.15] {
                    let e = self.cost(&axis_of(a as f64, i as f64), hk * r, true, &mut d2);
                    if e < best.0 {
                        best = (e, a as f64, i as f64, hk * r);
                    }
                }
            }
            best
        });
        let mut best = (f64::INFINITY, 0.0, 0.0, 0.0);
        for b in row_best {
            if b.0 < best.0 {
                best = b;
            }
        }
        best
    }

    /// From the grid's `best`, scored in full, a pattern search that halves its step when no
    /// move helps.
    fn pattern_search(&self, mut best: RimCandidate, points: usize) -> RimCandidate {
        let mut d2 = Vec::with_capacity(points);
        best.0 = self.cost(&axis_of(best.1, best.2), best.3, false, &mut d2);
        let mut step = 3.0;
        while step > 0.1 {
            let (e0, a0, i0, h0) = best;
            for (da, di, dh) in [
                (step, 0.0, 0.0),
                (-step, 0.0, 0.0),
                (0.0, step, 0.0),
                (0.0, -step, 0.0),
                (0.0, 0.0, 0.1 * step),
                (0.0, 0.0, -0.1 * step),
            ] {
                let e = self.cost(&axis_of(a0 + da, i0 + di), h0 + dh, false, &mut d2);
                if e < best.0 {
                    best = (e, a0 + da, i0 + di, h0 + dh);
                }
            }
            if best.0 >= e0 {
                step *= 0.5;
            }
        }
        best
    }
}

/// `curve` sampled every `spacing` pixels along its length (its closing segment included when
/// closed, from the point its shape fixes: `Curve::entered`, so that where it was started
/// changes nothing; an open one's ends kept); its points as they are if the spacing is not
/// positive.
fn even_samples(curve: &Curve, spacing: f64) -> Vec<Point2<f64>> {
    let curve = &curve.entered();
    let length = polyline_length(&curve.points, curve.closed);
    if !(spacing > 0.0 && length.is_finite()) || curve.points.len() < 2 {
        return curve.points.clone();
    }
    let n = ((length / spacing.max(MIN_SPACING_PX)).ceil() as usize).min(MAX_SAMPLES);
    if curve.closed {
        resample_closed(&curve.points, n.max(3)).0
    } else {
        resample_open(&curve.points, n.max(1) + 1).0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{phantom, phantom_case, radiographic_axis, PhantomParams};

    /// The rim fit on the level-3 outlines (seed `seed`) of the phantom turned to 35 degrees of
    /// anteversion (15 more than its design): the tests' wrong answer.
    fn turned_phantom_fit(seed: u64) -> RimFit {
        let turned = phantom(&PhantomParams {
            anteversion_deg: 35.0,
            ..Default::default()
        })
        .mesh;
        let sim = crate::sim::simulate_case(
            &turned,
            &crate::sim::XrayGeometry::default(),
            2.0,
            &crate::sim::NoiseLevel::level(3).unwrap(),
            seed,
        )
        .unwrap();
        rim_orientation(&sim.cameras, &sim.observed, &sim.truth_sphere).unwrap()
    }

    #[test]
    fn angles_invert_the_radiographic_axis() {
        for (a, i) in [(20.0, 45.0), (-5.0, 30.0), (35.0, 60.0)] {
            let (a2, i2) = radiographic_angles(&radiographic_axis(a, i));
            assert!((a2 - a).abs() < 1e-9 && (i2 - i).abs() < 1e-9, "{a2} {i2}");
        }
    }

    #[test]
    fn the_phantom_rim_gives_its_orientation_and_a_turned_one_does_not() {
        let truth = phantom(&PhantomParams::default()).placement;
        let (ta, ti) = radiographic_angles(&truth.axis);
        let (_, sim) = phantom_case(3, 2).unwrap();
        let fit = rim_orientation(&sim.cameras, &sim.observed, &sim.truth_sphere).unwrap();
        let err = |f: &RimFit| {
            (
                (f.anteversion_deg - ta).abs(),
                (f.inclination_deg - ti).abs(),
            )
        };
        let (ea, ei) = err(&fit);
        assert!(ea < 4.0 && ei < 4.0, "{fit:?}");
        // The companion: the same outlines of a phantom turned 15 degrees in anteversion are
        // told apart from the truth's angles by the same check.
        let fit2 = turned_phantom_fit(2);
        let (ea2, _) = err(&fit2);
        assert!(ea2 >= 4.0, "{fit2:?}");
    }

    /// Every outline's first half traced 20 times as densely (the same polyline, more points)
    /// gives the rim the same orientation: the fit weighs the outlines by length, not by how
    /// many points an annotator clicked. Companion: the same comparison with a phantom turned
    /// 15 degrees in anteversion is told apart.
    #[test]
    fn a_rim_traced_unevenly_gives_the_same_orientation() {
        let (_, sim) = phantom_case(3, 4).unwrap();
        let uneven: Vec<Vec<Curve>> = sim
            .observed
            .iter()
            .map(|curves| {
                curves
                    .iter()
                    .map(|c| {
                        let n = c.points.len();
                        let mut points = Vec::new();
                        for (i, p) in c.points.iter().enumerate() {
                            points.push(*p);
                            if i < n / 2 && i + 1 < n {
                                let q = c.points[i + 1];
                                points.extend((1..20).map(|k| p + (q - p) * (k as f64 / 20.0)));
                            }
                        }
                        Curve {
                            points,
                            closed: c.closed,
                        }
                    })
                    .collect()
            })
            .collect();
        let a = rim_orientation(&sim.cameras, &sim.observed, &sim.truth_sphere).unwrap();
        let b = rim_orientation(&sim.cameras, &uneven, &sim.truth_sphere).unwrap();
        let apart = |x: &RimFit, y: &RimFit| {
            (x.anteversion_deg - y.anteversion_deg)
                .abs()
                .max((x.inclination_deg - y.inclination_deg).abs())
        };
        assert!(apart(&a, &b) < 0.5, "{a:?} {b:?}");
        let c = turned_phantom_fit(4);
        assert!(apart(&a, &c) >= 4.0, "{a:?} {c:?}");
    }

    /// Where each closed rim was started, and which way round it runs, changes nothing, to the
    /// bit (the samples start where the rim's shape says); companion: one point moved 3 px
    /// changes the fit.
    #[test]
    fn where_a_rim_was_started_does_not_change_the_orientation() {
        let (_, sim) = phantom_case(3, 4).unwrap();
        let restarted: Vec<Vec<Curve>> = sim
            .observed
            .iter()
            .enumerate()
            .map(|(v, curves)| {
                curves
                    .iter()
                    .map(|c| c.retraced(c.points.len() / 3 + 5 * v, v == 1))
                    .collect()
            })
            .collect();
        let a = rim_orientation(&sim.cameras, &sim.observed, &sim.truth_sphere).unwrap();
        let b = rim_orientation(&sim.cameras, &restarted, &sim.truth_sphere).unwrap();
        assert_eq!(a, b);
        let mut moved = sim.observed.clone();
        moved[0][0].points[7].y += 3.0;
        let c = rim_orientation(&sim.cameras, &moved, &sim.truth_sphere).unwrap();
        assert_ne!(a, c);
    }

    /// A sphere far too small or an outline far too long is sampled at a bounded count.
    #[test]
    fn the_samples_are_bounded() {
        let square = |side: f64| Curve {
            points: vec![
                Point2::new(0.0, 0.0),
                Point2::new(side, 0.0),
                Point2::new(side, side),
                Point2::new(0.0, side),
            ],
            closed: true,
        };
        assert_eq!(even_samples(&square(10.0), 1e-12).len(), 80);
        assert_eq!(even_samples(&square(1e30), 1.0).len(), MAX_SAMPLES);
        // Companion: a spacing the bounds leave alone gives its own count.
        assert_eq!(even_samples(&square(10.0), 2.0).len(), 20);
    }

    #[test]
    fn a_sphere_off_every_outline_is_refused() {
        let (_, sim) = phantom_case(1, 1).unwrap();
        let mut far = sim.truth_sphere;
        // Three radii to the side (lateral): every outline lies outside its projected limb.
        far.center[0] += 3.0 * far.radius;
        let e = rim_orientation(&sim.cameras, &sim.observed, &far).unwrap_err();
        assert!(matches!(e, RimError::TooFewPoints { .. }), "{e}");
    }
}
