//! A stray point in an annotation: one point far off a curve whose neighbours lie close to each
//! other, as a slip of the mouse leaves. The curve then runs out to it and back, a spike that
//! the arc-length resampling and the SRVF give as much weight as the rim itself.

use nalgebra::Point2;

/// A point is stray when it lies farther than this many times the curve's median spacing from
/// both its neighbours...
pub const STRAY_SPACINGS: f64 = 8.0;
/// ... and farther than this (pixels: a densely traced, noisy curve has spacings of a pixel or
/// two) ...
pub const STRAY_MIN_PX: f64 = 20.0;
/// ... while its neighbours lie closer to each other than this fraction of that distance (the
/// curve comes back to where it left). A corner of a sparsely clicked outline, or a notch as
/// wide as it is deep, has neighbours about as far apart as it is from them.
pub const STRAY_RETURN: f64 = 0.5;

/// The stray point found, and the distances that make it one (pixels).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StrayPoint {
    /// Its index in the points given.
    pub index: usize,
    /// Its distance to the nearer of its two neighbours.
    pub off_px: f64,
    /// How far apart its two neighbours are.
    pub neighbours_px: f64,
    /// The curve's median distance between consecutive points.
    pub spacing_px: f64,
}

/// The point of `p` (consecutive points distinct; `closed` joins the last to the first) that
/// lies farthest off while being stray (see `STRAY_SPACINGS`, `STRAY_MIN_PX`,
/// `STRAY_RETURN`); None when no point is. An open curve's end points have one neighbour and
/// are never called stray.
pub fn stray_point(p: &[Point2<f64>], closed: bool) -> Option<StrayPoint> {
    let n = p.len();
    if n < 4 {
        return None;
    }
    let segments = if closed { n } else { n - 1 };
    let mut spacing: Vec<f64> = (0..segments)
        .map(|i| (p[(i + 1) % n] - p[i]).norm())
        .collect();
    let mid = spacing.len() / 2;
    let (_, &mut m, _) = spacing.select_nth_unstable_by(mid, f64::total_cmp);
    let limit = (STRAY_SPACINGS * m).max(STRAY_MIN_PX);
    let inner = if closed { 0..n } else { 1..n - 1 };
    inner
        .filter_map(|i| {
            let (prev, next) = (p[(i + n - 1) % n], p[(i + 1) % n]);
            let off = (p[i] - prev).norm().min((p[i] - next).norm());
            let neighbours = (next - prev).norm();
            (off > limit && neighbours < STRAY_RETURN * off).then_some(StrayPoint {
                index: i,
                off_px: off,
                neighbours_px: neighbours,
                spacing_px: m,
            })
        })
        .max_by(|a, b| a.off_px.total_cmp(&b.off_px))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn circle(n: usize, r: f64) -> Vec<Point2<f64>> {
        (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / n as f64;
                Point2::new(1000.0 + r * t.cos(), 1000.0 + r * t.sin())
            })
            .collect()
    }

    /// One point of a dense outline (160 px radius, 7 px apart) pushed 100 px outwards is
    /// found, at its index, closed or open; the same outline without it, a polygon clicked
    /// every 20 px with 2 px of noise, and one with a notch 40 px deep and 60 px wide have none.
    #[test]
    fn a_point_far_off_with_its_neighbours_close_together_is_stray_and_a_notch_is_not() {
        let mut p = circle(144, 160.0);
        let push = (p[37] - Point2::new(1000.0, 1000.0)) * (100.0 / 160.0);
        p[37] += push;
        for closed in [true, false] {
            let s = stray_point(&p, closed).expect("the pushed point is stray");
            assert_eq!(s.index, 37);
            assert!((s.off_px - 100.0).abs() < 1.0, "{s:?}");
            assert!(
                s.neighbours_px < 15.0 && (s.spacing_px - 7.0).abs() < 0.1,
                "{s:?}"
            );
        }
        // Companions: none of these has a stray point.
        assert_eq!(stray_point(&circle(144, 160.0), true), None);
        let mut seed = 7u64;
        let mut noise = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 4.0
        };
        let polygon: Vec<Point2<f64>> = circle(50, 160.0)
            .into_iter()
            .map(|q| q + nalgebra::Vector2::new(noise(), noise()))
            .collect();
        assert_eq!(stray_point(&polygon, true), None);
        let mut notched = circle(144, 160.0);
        for (k, depth) in [
            (-4, 10.0),
            (-3, 20.0),
            (-2, 30.0),
            (-1, 40.0),
            (0, 40.0),
            (1, 40.0),
        ]
        .into_iter()
        .chain([(2, 40.0), (3, 30.0), (4, 20.0), (5, 10.0)])
        {
            let i = (72 + k) as usize;
            let q = notched[i];
            notched[i] = q - (q - Point2::new(1000.0, 1000.0)) * (depth / 160.0);
        }
        assert_eq!(stray_point(&notched, true), None);
    }

    /// A point that is only a little off, under the pixel floor, is not stray on a densely
    /// traced curve (1 px apart): noise, not a slip.
    #[test]
    fn a_small_excursion_on_a_dense_trace_is_not_stray_and_a_large_one_is() {
        let mut p = circle(1000, 160.0);
        let out = |q: Point2<f64>, by: f64| q + (q - Point2::new(1000.0, 1000.0)) * (by / 160.0);
        p[500] = out(p[500], 15.0);
        assert_eq!(stray_point(&p, true), None);
        p[500] = out(circle(1000, 160.0)[500], 25.0);
        assert_eq!(stray_point(&p, true).map(|s| s.index), Some(500));
    }
}
