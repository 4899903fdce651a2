//! Planar polylines: length, orientation and arc-length resampling.

use nalgebra::Point2;

/// An observed or model curve in pixels; `closed` joins the last point to the first.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// The points, in order, pixels.
    pub points: Vec<Point2<f64>>,
    /// Whether the last point joins the first.
    pub closed: bool,
}

impl Curve {
    /// The same curve entered at a point and run in a direction fixed by its shape, so that
    /// where an annotator began clicking, which way round, or where a triangulation began
    /// tracing cannot change a result. It runs the way that gives it a positive `signed_area`
    /// (an open curve closed by its chord), the way model contours run; a closed curve then
    /// starts at its leftmost vertex (the topmost-in-y of equally left ones), an open one at the
    /// end that direction makes its first.
    pub fn entered(&self) -> Curve {
        let mut points = self.points.clone();
        if signed_area(&points) < 0.0 {
            points.reverse();
        }
        if self.closed {
            let k = fixed_start(&points);
            points.rotate_left(k);
        }
        Curve {
            points,
            closed: self.closed,
        }
    }
}

#[cfg(test)]
impl Curve {
    /// The same outline as another annotator might have given it: a closed one started `k`
    /// points on (modulo its length), and traced the other way round when `reverse`.
    pub(crate) fn retraced(&self, k: usize, reverse: bool) -> Curve {
        let mut c = self.clone();
        if c.closed && !c.points.is_empty() {
            let n = c.points.len();
            c.points.rotate_left(k % n);
        }
        if reverse {
            c.points.reverse();
        }
        c
    }
}

/// Where a closed polyline is entered by its shape alone: the index of its leftmost point (the
/// topmost-in-y of equally left ones; 0 for none).
pub fn fixed_start(points: &[Point2<f64>]) -> usize {
    (0..points.len())
        .min_by(|&i, &j| {
            let (p, q) = (points[i], points[j]);
            p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y))
        })
        .unwrap_or(0)
}

/// Length of the polyline (including the closing segment when `closed`).
pub fn polyline_length(p: &[Point2<f64>], closed: bool) -> f64 {
    let mut l: f64 = p.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    if closed && p.len() > 1 {
        l += (p[0] - p[p.len() - 1]).norm();
    }
    l
}

/// Shoelace signed area (positive when the points run counter-clockwise in x-right, y-up axes).
pub fn signed_area(p: &[Point2<f64>]) -> f64 {
    let n = p.len();
    (0..n)
        .map(|i| p[i].x * p[(i + 1) % n].y - p[(i + 1) % n].x * p[i].y)
        .sum::<f64>()
        * 0.5
}

/// Distance from `q` to the polyline `p` (its closing segment included when `closed`); infinite
/// for an empty polyline.
pub fn distance_to_polyline(q: &Point2<f64>, p: &[Point2<f64>], closed: bool) -> f64 {
    let n = p.len();
    if n == 1 {
        return (q - p[0]).norm();
    }
    let segments = if closed { n } else { n.saturating_sub(1) };
    (0..segments)
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % n]);
            let ab = b - a;
            let t = ((q - a).dot(&ab) / ab.norm_squared().max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
            (q - (a + t * ab)).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Cumulative arc length at each vertex, plus the total (closing segment included when closed).
fn cumulative(p: &[Point2<f64>], closed: bool) -> Vec<f64> {
    let mut s = vec![0.0; p.len() + usize::from(closed)];
    for i in 1..s.len() {
        s[i] = s[i - 1] + (p[i % p.len()] - p[i - 1]).norm();
    }
    s
}

fn sample(p: &[Point2<f64>], s: &[f64], target: f64) -> (Point2<f64>, f64) {
    // Index of the segment holding `target`, and the fractional position along it.
    let k = match s.binary_search_by(|x| x.partial_cmp(&target).unwrap_or(std::cmp::Ordering::Less))
    {
        Ok(k) => k.min(s.len() - 2),
        Err(k) => k.saturating_sub(1).min(s.len() - 2),
    };
    let len = s[k + 1] - s[k];
    let u = if len > 0.0 {
        ((target - s[k]) / len).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let a = p[k % p.len()];
    let b = p[(k + 1) % p.len()];
    (a + (b - a) * u, k as f64 + u)
}

/// A closed polyline with its arc-length table, for sampling at arbitrary arc-length positions.
#[derive(Clone, Debug)]
pub struct ClosedPolyline<'a> {
    points: &'a [Point2<f64>],
    cum: Vec<f64>,
    /// Total length, closing segment included.
    pub total: f64,
}

impl<'a> ClosedPolyline<'a> {
    /// Arc-length parametrisation of the closed polyline through `points`.
    pub fn new(points: &'a [Point2<f64>]) -> Self {
        let cum = cumulative(points, true);
        let total = cum[cum.len() - 1];
        ClosedPolyline { points, cum, total }
    }

    /// The point at arc length `s` (taken modulo the total) and its fractional vertex index.
    pub fn at(&self, s: f64) -> (Point2<f64>, f64) {
        let s = if self.total > 0.0 {
            s.rem_euclid(self.total)
        } else {
            0.0
        };
        sample(self.points, &self.cum, s)
    }
}

/// Resample a closed polyline to `t` points evenly spaced in arc length, starting at point 0.
/// Also returns each sample's position as a fractional vertex index into `p`.
pub fn resample_closed(p: &[Point2<f64>], t: usize) -> (Vec<Point2<f64>>, Vec<f64>) {
    if let Some(few) = too_few(p, t) {
        return few;
    }
    let s = cumulative(p, true);
    let total = s[s.len() - 1];
    (0..t)
        .map(|i| sample(p, &s, total * i as f64 / t as f64))
        .unzip()
}

/// Resample an open polyline to `t` points evenly spaced in arc length, both ends included.
pub fn resample_open(p: &[Point2<f64>], t: usize) -> (Vec<Point2<f64>>, Vec<f64>) {
    if let Some(few) = too_few(p, t) {
        return few;
    }
    let s = cumulative(p, false);
    let total = s[s.len() - 1];
    (0..t)
        .map(|i| sample(p, &s, total * i as f64 / (t - 1).max(1) as f64))
        .unzip()
}

/// A polyline of fewer than two points has no length to sample along: none (no points) or `t`
/// copies of its one point, each at parameter 0.
fn too_few(p: &[Point2<f64>], t: usize) -> Option<(Vec<Point2<f64>>, Vec<f64>)> {
    match p {
        [] => Some((Vec::new(), Vec::new())),
        [one] => Some((vec![*one; t], vec![0.0; t])),
        _ => None,
    }
}

/// How many times the closed polyline `p` goes round the point `about` (counter-clockwise
/// positive): the sum of the turns of `p[i] - about` from point to point, over 2 pi, rounded.
/// 0 when a point of `p` is `about` itself or `p` has fewer than 3 points.
pub fn winding_number(p: &[Point2<f64>], about: Point2<f64>) -> i64 {
    let n = p.len();
    if n < 3 || p.iter().any(|q| (q - about).norm() == 0.0) {
        return 0;
    }
    let turn: f64 = (0..n)
        .map(|i| {
            let (a, b) = (p[i] - about, p[(i + 1) % n] - about);
            (a.x * b.y - a.y * b.x).atan2(a.dot(&b))
        })
        .sum();
    (turn / std::f64::consts::TAU).round() as i64
}

/// Area of the convex hull of `p` (Andrew's monotone chain); 0 for fewer than 3 points or
/// points on one line. Beside `signed_area` it tells how much of its hull a closed outline
/// encloses: most of it for a rim, little for points on a line or an outline that crosses
/// itself (its loops' areas cancel).
pub fn convex_hull_area(p: &[Point2<f64>]) -> f64 {
    let mut pts: Vec<Point2<f64>> = p.to_vec();
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        return 0.0;
    }
    let cross = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| {
        (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
    };
    // Lower hull left to right, then upper hull right to left, each turning left only.
    let mut hull: Vec<Point2<f64>> = Vec::with_capacity(2 * pts.len());
    for pass in [&pts[..], &pts.iter().rev().copied().collect::<Vec<_>>()[..]] {
        let floor = hull.len();
        for q in pass {
            while hull.len() >= floor + 2
                && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(*q);
        }
        hull.pop(); // the pass's last point starts the next one
    }
    signed_area(&hull).abs()
}

/// How many times a closed outline goes round its points' centroid, either way: a rim once, two
/// passes of an annotation joined twice; 0 for no points.
pub fn turns_round_centroid(pts: &[Point2<f64>]) -> i64 {
    if pts.is_empty() {
        return 0;
    }
    let centre = pts.iter().map(|p| p.coords).sum::<nalgebra::Vector2<f64>>() / pts.len() as f64;
    winding_number(pts, Point2::from(centre)).abs()
}

/// The area a closed outline encloses and its convex hull's, px^2: nearly equal for a rim, the
/// first far smaller for points on a line or an outline that crosses itself.
pub fn hull_fill(pts: &[Point2<f64>]) -> (f64, f64) {
    (signed_area(pts).abs(), convex_hull_area(pts))
}

/// The widest extent of the points `p`: the largest of their widths across 72 directions 2.5
/// degrees apart (the diameter of their convex hull to within 0.1 %), in one pass per direction;
/// 0 for fewer than two points.
pub fn widest_extent(p: &[Point2<f64>]) -> f64 {
    if p.len() < 2 {
        return 0.0;
    }
    (0..72)
        .map(|k| {
            let (s, c) = (k as f64 * std::f64::consts::PI / 72.0).sin_cos();
            let (lo, hi) = p
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                    let x = c * q.x + s * q.y;
                    (lo.min(x), hi.max(x))
                });
            hi - lo
        })
        .fold(0.0, f64::max)
}

/// The longest segment of the closed polygon `p`: (i, its length, the next longest's), the
/// segment running from point i to point i + 1 (the last to the first for the last i); None for
/// fewer than three points.
pub fn longest_segment(p: &[Point2<f64>]) -> Option<(usize, f64, f64)> {
    let m = p.len();
    if m < 3 {
        return None;
    }
    let (mut at, mut first, mut second) = (0, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for i in 0..m {
        let d = (p[(i + 1) % m] - p[i]).norm();
        if d > first {
            (at, first, second) = (i, d, first);
        } else if d > second {
            second = d;
        }
    }
    Some((at, first, second))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A polyline of fewer than two points resamples to nothing or to copies of its point (it
    /// panicked); companion: two points resample along their segment.
    #[test]
    fn a_polyline_of_one_point_or_none_resamples_without_a_panic() {
        let a = Point2::new(3.0, 4.0);
        assert_eq!(resample_closed(&[], 5), (Vec::new(), Vec::new()));
        assert_eq!(resample_open(&[], 5), (Vec::new(), Vec::new()));
        assert_eq!(resample_closed(&[a], 3), (vec![a; 3], vec![0.0; 3]));
        assert_eq!(resample_open(&[a], 3), (vec![a; 3], vec![0.0; 3]));
        let b = Point2::new(5.0, 4.0);
        let (pts, _) = resample_open(&[a, b], 3);
        assert_eq!(pts, vec![a, Point2::new(4.0, 4.0), b]);
    }

    /// A closed curve entered anywhere, either way round, comes out the same: run the positive
    /// way from its leftmost point; an open one keeps its points and ends, run the positive
    /// way. Companions: a curve with its leftmost point moved right starts elsewhere; an open
    /// arc is not turned round to another start.
    #[test]
    fn a_curve_is_entered_the_same_wherever_and_whichever_way_it_started() {
        let pts: Vec<Point2<f64>> = (0..12)
            .map(|k| {
                let t = k as f64 * std::f64::consts::TAU / 12.0 + 0.1;
                Point2::new(10.0 * t.cos() + (k % 3) as f64, 6.0 * t.sin())
            })
            .collect();
        assert!(signed_area(&pts) > 0.0);
        let curve = |points: Vec<Point2<f64>>, closed| Curve { points, closed };
        let fixed = curve(pts.clone(), true).entered();
        let left = pts.iter().map(|p| p.x).fold(f64::INFINITY, f64::min);
        assert_eq!(fixed.points[0].x, left);
        assert!(signed_area(&fixed.points) > 0.0);
        let closed = curve(pts.clone(), true);
        for k in 0..pts.len() {
            assert_eq!(closed.retraced(k, false).entered(), fixed);
            assert_eq!(closed.retraced(k, true).entered(), fixed);
            let turned = closed.retraced(k, false).points;
            assert_eq!(curve(turned.clone(), false).entered().points, turned);
        }
        // An open arc either way round comes out the positive way, from the same end.
        let arc = curve(pts[2..9].to_vec(), false);
        assert_eq!(arc.retraced(0, true).entered(), arc);
        assert_eq!(arc.entered(), arc);
        let mut moved = pts.clone();
        let k = fixed_start(&pts);
        moved[k].x += 5.0;
        assert_ne!(fixed_start(&moved), k);
    }

    /// A square's sides are all longest alike; a 60 % arc closed by its chord has the chord
    /// longest, many times the arc's steps; the companion: a whole circle has no segment longer
    /// than the rest.
    #[test]
    fn the_longest_segment_of_an_arc_closed_by_its_chord_is_the_chord() {
        let square =
            [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)].map(|(x, y)| Point2::new(x, y));
        let (_, a, b) = longest_segment(&square).unwrap();
        assert_eq!((a, b), (1.0, 1.0));
        let arc: Vec<Point2<f64>> = (0..60)
            .map(|k| {
                let t = std::f64::consts::TAU * 0.6 * k as f64 / 59.0;
                Point2::new(100.0 * t.cos(), 100.0 * t.sin())
            })
            .collect();
        let (i, chord, step) = longest_segment(&arc).unwrap();
        assert_eq!(i, 59, "the closing segment");
        assert!((chord - 2.0 * 100.0 * (0.4 * std::f64::consts::PI).sin()).abs() < 1e-9);
        assert!(chord > 20.0 * step, "{chord} {step}");
        // Companion: the whole circle has no such segment.
        let circle: Vec<Point2<f64>> = (0..60)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / 60.0;
                Point2::new(100.0 * t.cos(), 100.0 * t.sin())
            })
            .collect();
        let (_, a, b) = longest_segment(&circle).unwrap();
        assert!(a < 1.001 * b);
        assert_eq!(longest_segment(&square[..2]), None);
    }

    /// A circle winds once round its centre (either way), the same circle traced twice winds
    /// twice, and a point outside it not at all.
    #[test]
    fn winding_counts_the_turns_round_a_point() {
        let c = Point2::new(5.0, -3.0);
        let circle: Vec<Point2<f64>> = (0..40)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 40.0;
                c + nalgebra::Vector2::new(10.0 * t.cos(), 10.0 * t.sin())
            })
            .collect();
        assert_eq!(winding_number(&circle, c), 1);
        let reversed: Vec<_> = circle.iter().rev().copied().collect();
        assert_eq!(winding_number(&reversed, c), -1);
        let twice: Vec<_> = circle.iter().chain(&circle).copied().collect();
        assert_eq!(winding_number(&twice, c), 2);
        assert_eq!(
            winding_number(&circle, c + nalgebra::Vector2::new(30.0, 0.0)),
            0
        );
    }

    #[test]
    fn square_resampling_and_area() {
        let sq = [
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(1.0, 1.0),
            Point2::new(0.0, 1.0),
        ];
        assert_eq!(signed_area(&sq), 1.0);
        assert_eq!(polyline_length(&sq, true), 4.0);
        let (r, idx) = resample_closed(&sq, 8);
        assert_eq!(r.len(), 8);
        assert!((r[1] - Point2::new(0.5, 0.0)).norm() < 1e-12);
        assert!((r[7] - Point2::new(0.0, 0.5)).norm() < 1e-12);
        assert!((idx[7] - 3.5).abs() < 1e-12);
        let (o, _) = resample_open(&sq, 4);
        assert!((o[3] - Point2::new(0.0, 1.0)).norm() < 1e-12);
        assert!((o[1] - Point2::new(1.0, 0.0)).norm() < 1e-12);
    }

    /// The hull of an L shape bridges its inner corner; inner points and repeats change nothing.
    /// Companions: points on one line, and fewer than three, have no hull area.
    #[test]
    fn convex_hull_area_bridges_concavities_and_is_zero_on_a_line() {
        let l = [
            (0.0, 0.0),
            (10.0, 0.0),
            (10.0, 5.0),
            (5.0, 5.0),
            (5.0, 10.0),
            (0.0, 10.0),
            (2.0, 3.0),
            (10.0, 0.0),
        ]
        .map(|(x, y)| Point2::new(x, y));
        assert!((convex_hull_area(&l) - 87.5).abs() < 1e-12);
        assert!((signed_area(&l[..6]) - 75.0).abs() < 1e-12);
        let line: Vec<Point2<f64>> = (0..20)
            .map(|i| Point2::new(i as f64, 2.0 * i as f64))
            .collect();
        assert_eq!(convex_hull_area(&line), 0.0);
        assert_eq!(convex_hull_area(&l[..2]), 0.0);
    }

    /// A rim traced once goes once round its centroid, either way, and encloses nearly all of
    /// its hull. Companions: the same rim traced twice goes twice round; a figure eight (two
    /// loops that cancel) encloses almost none of its hull; no points, no turns.
    #[test]
    fn a_rim_goes_once_round_and_fills_its_hull() {
        let rim = |turns: f64, n: usize| -> Vec<Point2<f64>> {
            (0..n)
                .map(|i| {
                    let t = turns * std::f64::consts::TAU * i as f64 / n as f64;
                    Point2::new(200.0 + 40.0 * t.cos(), 150.0 + 30.0 * t.sin())
                })
                .collect()
        };
        let once = rim(1.0, 90);
        assert_eq!(turns_round_centroid(&once), 1);
        let backwards: Vec<Point2<f64>> = once.iter().rev().copied().collect();
        assert_eq!(turns_round_centroid(&backwards), 1);
        let (inside, hull) = hull_fill(&once);
        assert!(inside > 0.99 * hull && inside <= hull, "{inside} of {hull}");
        assert_eq!(turns_round_centroid(&rim(2.0, 180)), 2);
        let eight: Vec<Point2<f64>> = (0..120)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 120.0;
                Point2::new(40.0 * t.sin(), 20.0 * (2.0 * t).sin())
            })
            .collect();
        let (inside, hull) = hull_fill(&eight);
        assert!(hull > 1000.0 && inside < 0.01 * hull, "{inside} of {hull}");
        assert_eq!(turns_round_centroid(&[]), 0);
    }

    /// A circle's widest extent is its diameter, a rectangle's its diagonal (within 0.1 %).
    /// Companion: the width along one axis alone would miss the diagonal by far.
    #[test]
    fn widest_extent_is_the_diameter_of_the_hull() {
        let circle: Vec<Point2<f64>> = (0..100)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 100.0;
                Point2::new(3.0 + 20.0 * t.cos(), -1.0 + 20.0 * t.sin())
            })
            .collect();
        assert!((widest_extent(&circle) - 40.0).abs() < 0.04);
        let rect =
            [(0.0, 0.0), (30.0, 0.0), (30.0, 40.0), (0.0, 40.0)].map(|(x, y)| Point2::new(x, y));
        assert!((widest_extent(&rect) - 50.0).abs() < 0.05);
        assert!((widest_extent(&rect) - 40.0).abs() > 5.0);
        assert_eq!(widest_extent(&rect[..1]), 0.0);
    }
}
