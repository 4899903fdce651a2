//! An outline taken as the curve through its points. An annotator who clicks a rim puts each
//! point on it, and the straight steps between the clicks cut inside it: by about c^2 / 8r on a
//! rim of radius r clicked every c pixels (1.3 px for clicks 40 px apart on a rim 300 px across,
//! 5 px for clicks 80 px apart), so the outline the method meets is smaller than the rim, and
//! the cup with it. The curve through the clicks takes their place: each step is the blend of
//! two circular arcs, that of the circle through the point before and the step's ends and that
//! of the circle through the step's ends and the point after, weighed from the first to the
//! second along the step (circle blending, as in computer-aided geometric design). It passes
//! through every point, is exact on a circle however few the clicks, lies on the step where the
//! points run straight, and takes an arc that turns more than `MAX_ARC_TURN_DEG` from its chord
//! (a notch's corner, a click that doubles back) as straight on that side. A densely traced
//! outline (steps of 3 px or less) is its own curve.

use super::Curve;
use nalgebra::{Point2, Vector2};

/// The curve's points lie about this far apart (px); a step no longer is kept as it is.
pub const THROUGH_STEP_PX: f64 = 3.0;

/// The most points one step is given (a step of 12,000 px; a contour in pixels of an image
/// has none so long, and a host's curve in other units is not made to fill memory).
const MAX_STEP_POINTS: usize = 4096;

/// A turn of the arc from the chord (the tangent-chord angle) above this many degrees, where
/// the circle through three points is a corner's, not a rim's, is taken as none (a straight
/// step): six clicks round a circle turn 30 degrees.
pub const MAX_ARC_TURN_DEG: f64 = 60.0;

/// The tangent-chord angle, radians, of the arc from `a` to `b` on the circle through `a`, `b`
/// and `o` that leaves `o` out: the angle at `o` between `a` and `b` (the inscribed angle),
/// signed positive where the arc bulges to the left of `a` -> `b`. 0 where the three points
/// lie on a line, coincide, or turn more than `MAX_ARC_TURN_DEG`.
fn arc_turn(a: Point2<f64>, b: Point2<f64>, o: Point2<f64>) -> f64 {
    let (u, v, c) = (a - o, b - o, b - a);
    let angle = (u.x * v.y - u.y * v.x).abs().atan2(u.dot(&v));
    // The side of the chord `o` lies on; the arc bulges to the other.
    let side = c.x * (o.y - a.y) - c.y * (o.x - a.x);
    if !(angle.is_finite() && side.abs() > 1e-12) || angle > MAX_ARC_TURN_DEG.to_radians() {
        return 0.0;
    }
    -side.signum() * angle
}

/// The point at `t` (0 to 1) of the arc from `a` to `b` that leaves `a` turned `phi` radians
/// from the chord (`arc_turn`), as (along the chord, to its left) from `a`, in chord lengths.
fn arc_point(phi: f64, t: f64) -> (f64, f64) {
    if phi.abs() < 1e-12 {
        return (t, 0.0);
    }
    let psi = phi * (1.0 - 2.0 * t);
    let r = 0.5 / phi.sin();
    (0.5 - r * psi.sin(), r * (psi.cos() - phi.cos()))
}

impl Curve {
    /// A rim given as clicks on it, as the curve through them: every step longer than
    /// `THROUGH_STEP_PX` gets points on its blended arc (see the module) about that far apart
    /// between its ends, so that the curve's points lie evenly along it, as a traced line's do
    /// (the outlines' limb sphere is fitted to the points one by one: points only where the
    /// steps bend would weigh those stretches more); every given point is kept. An open curve's end steps take the one
    /// circle they have. A curve of fewer than three points is returned as it is.
    pub fn clicked(&self) -> Curve {
        let p = &self.points;
        let n = p.len();
        if n < 3 {
            return self.clone();
        }
        let steps = if self.closed { n } else { n - 1 };
        // A neighbour of a step: round a closed curve, none past an open one's ends.
        let at = |i: isize| -> Option<Point2<f64>> {
            if self.closed {
                Some(p[i.rem_euclid(n as isize) as usize])
            } else {
                usize::try_from(i).ok().and_then(|i| p.get(i).copied())
            }
        };
        let mut points = Vec::with_capacity(n);
        for i in 0..steps {
            let (a, b) = (p[i], p[(i + 1) % n]);
            points.push(a);
            let chord = b - a;
            let len = chord.norm();
            if !(len > THROUGH_STEP_PX) {
                continue;
            }
            // The arcs of the circles through the point before and the point after; an open
            // curve's end steps have one of them.
            let before = at(i as isize - 1).map(|o| arc_turn(a, b, o));
            let after = at(i as isize + 2).map(|o| arc_turn(a, b, o));
            let (p1, p2) = match (before, after) {
                (Some(x), Some(y)) => (x, y),
                (Some(x), None) => (x, x),
                (None, Some(y)) => (y, y),
                (None, None) => continue,
            };
            let m = ((len / THROUGH_STEP_PX).ceil() as usize).min(MAX_STEP_POINTS);
            let left = Vector2::new(-chord.y, chord.x);
            points.extend((1..m).map(|j| {
                let t = j as f64 / m as f64;
                let (x1, y1) = arc_point(p1, t);
                let (x2, y2) = arc_point(p2, t);
                let (x, y) = ((1.0 - t) * x1 + t * x2, (1.0 - t) * y1 + t * y2);
                a + chord * x + left * y
            }));
        }
        if !self.closed {
            points.push(p[n - 1]);
        }
        Curve {
            points,
            closed: self.closed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::distance_to_polyline;
    use std::f64::consts::TAU;

    /// `k` points on a circle of radius `r` about (500, 400), evenly spaced from angle `a0`.
    fn clicks(k: usize, r: f64, a0: f64) -> Vec<Point2<f64>> {
        (0..k)
            .map(|i| {
                let a = a0 + TAU * i as f64 / k as f64;
                Point2::new(500.0 + r * a.cos(), 400.0 + r * a.sin())
            })
            .collect()
    }

    /// How far the curve's points and the midpoints of its steps lie from the circle.
    fn off_circle(c: &Curve, r: f64) -> f64 {
        let o = Point2::new(500.0, 400.0);
        let n = c.points.len();
        let steps = if c.closed { n } else { n - 1 };
        (0..steps)
            .map(|i| nalgebra::center(&c.points[i], &c.points[(i + 1) % n]))
            .chain(c.points.iter().copied())
            .map(|p| ((p - o).norm() - r).abs())
            .fold(0.0, f64::max)
    }

    /// A rim 300 px across clicked 12 times: the straight steps cut 5.1 px inside it, the curve
    /// through the clicks is the circle (within the 0.01 px its own 3 px steps cut inside it) and passes through every click, in order.
    /// Companion: the clicks as given are rejected by the same bound.
    #[test]
    fn a_rim_clicked_far_apart_is_met_by_the_curve_through_its_clicks() {
        let pts = clicks(12, 150.0, 0.3);
        let given = Curve {
            points: pts.clone(),
            closed: true,
        };
        let through = given.clicked();
        assert!(
            off_circle(&through, 150.0) < 0.01,
            "{}",
            off_circle(&through, 150.0)
        );
        assert!(off_circle(&given, 150.0) > 5.0);
        let mut at = 0;
        for p in &pts {
            at += through.points[at..]
                .iter()
                .position(|q| q == p)
                .expect("every click kept");
        }
        // The curve's points lie evenly along it, about THROUGH_STEP_PX apart.
        let n = through.points.len();
        for i in 0..n {
            let d = (through.points[(i + 1) % n] - through.points[i]).norm();
            assert!(
                (0.8 * THROUGH_STEP_PX..=1.05 * THROUGH_STEP_PX).contains(&d),
                "{i}: {d}"
            );
        }
    }

    /// An arc of the rim (open), clicked 7 times over 200 degrees: the curve through it meets the
    /// circle (to 0.01 px), ends at the first and last click; companion: as given, over 4 px off.
    #[test]
    fn an_open_arc_clicked_far_apart_is_met_to_its_ends() {
        let pts: Vec<_> = (0..7)
            .map(|i| {
                let a = 0.2 + 200f64.to_radians() * i as f64 / 6.0;
                Point2::new(500.0 + 150.0 * a.cos(), 400.0 + 150.0 * a.sin())
            })
            .collect();
        let given = Curve {
            points: pts.clone(),
            closed: false,
        };
        let through = given.clicked();
        assert!(!through.closed);
        assert_eq!(through.points.first(), pts.first());
        assert_eq!(through.points.last(), pts.last());
        assert!(
            off_circle(&through, 150.0) < 0.01,
            "{}",
            off_circle(&through, 150.0)
        );
        assert!(off_circle(&given, 150.0) > 4.0);
    }

    /// A densely traced rim (steps under 3 px) is its own curve, and where clicks run straight
    /// (a square's sides, three clicks each) the points between them lie on the straight step:
    /// the curve bends only on the steps that end at a corner, by less than a sixth of a side.
    /// Companion: six clicks on a circle are the circle, well outside their hexagon.
    #[test]
    fn where_points_run_straight_the_curve_does() {
        let dense = Curve {
            points: clicks(330, 150.0, 0.0),
            closed: true,
        };
        assert_eq!(dense.clicked(), dense);
        let side = |a: [f64; 2], b: [f64; 2]| {
            (0..3).map(move |i| {
                let t = i as f64 / 3.0;
                Point2::new(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
            })
        };
        let c = [[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]];
        let square = Curve {
            points: (0..4).flat_map(|i| side(c[i], c[(i + 1) % 4])).collect(),
            closed: true,
        };
        let through = square.clicked();
        for k in 0..4 {
            let (s1, s2) = (square.points[3 * k + 1], square.points[3 * k + 2]);
            let i = through.points.iter().position(|p| *p == s1).unwrap();
            let j = through.points.iter().position(|p| *p == s2).unwrap();
            assert!(j > i + 1, "side {k}: points between its middle clicks");
            for p in &through.points[i..=j] {
                let off = distance_to_polyline(p, &[s1, s2], false);
                assert!(off < 1e-9, "side {k}'s middle step straight: {p:?} {off}");
            }
        }
        for p in &through.points {
            let to_square = distance_to_polyline(p, &square.points, true);
            assert!(to_square < 100.0 / 6.0, "{p:?} {to_square}");
        }
        // Six clicks on a circle (each arc turning 30 degrees) are that circle, 13.4 px outside
        // the hexagon's sides.
        let hexagon = Curve {
            points: clicks(6, 100.0, 0.2),
            closed: true,
        };
        let rounded = hexagon.clicked();
        let bulge = rounded
            .points
            .iter()
            .map(|p| distance_to_polyline(p, &hexagon.points, true))
            .fold(0.0, f64::max);
        assert!(bulge > 13.0, "{bulge}");
        assert!(off_circle(&rounded, 100.0) < 0.1);
        // A click that doubles back (the angle at it 157 degrees) leaves the step straight on
        // its side; one just off the line leaves it nearly straight.
        let (a, b) = (Point2::new(0.0, 0.0), Point2::new(10.0, 0.0));
        assert_eq!(arc_turn(a, b, Point2::new(5.0, -1.0)), 0.0);
        assert!(arc_turn(a, b, Point2::new(-10.0, -0.5)).abs() < 0.03);
        assert!(
            arc_turn(a, b, Point2::new(-10.0, -0.5)) > 0.0,
            "bulges away from it"
        );
    }

    /// Points clicked twice in a row leave the curve without a NaN; fewer than three points are
    /// returned as they are; a curve in other units does not fill memory.
    #[test]
    fn repeated_points_and_too_few_leave_the_curve() {
        let mut pts = clicks(8, 150.0, 0.0);
        pts.insert(3, pts[2]);
        let c = Curve {
            points: pts,
            closed: true,
        };
        let t = c.clicked();
        assert!(t.points.iter().all(|p| p.x.is_finite() && p.y.is_finite()));
        assert!(t.points.len() > c.points.len());
        let two = Curve {
            points: clicks(2, 150.0, 0.0),
            closed: false,
        };
        assert_eq!(two.clicked(), two);
        // A host's curve in other units: steps of 1e12 get at most MAX_STEP_POINTS points each;
        // a point that is not finite leaves its steps as they are.
        let huge = Curve {
            points: clicks(8, 1e12, 0.0),
            closed: true,
        };
        assert!(huge.clicked().points.len() <= 8 * MAX_STEP_POINTS);
        let mut nan = clicks(8, 150.0, 0.0);
        nan[4] = Point2::new(f64::NAN, 0.0);
        let t = Curve {
            points: nan,
            closed: true,
        }
        .clicked();
        assert_eq!(t.points.iter().filter(|p| p.x.is_nan()).count(), 1);
    }
}
