//! A polyline prepared for many point-distance queries: the same distances as
//! `distance_to_polyline`, to the bit, with the segments that cannot be nearer than the best found
//! so far skipped by a cheap bound.

use super::distance_to_polyline;
use nalgebra::{Point2, Vector2};

/// One segment: its start, direction, squared length (floored as `distance_to_polyline` floors
/// it), and the circle about its midpoint that holds it.
#[derive(Clone, Copy, Debug)]
struct Segment {
    a: Point2<f64>,
    ab: Vector2<f64>,
    len2: f64,
    mid: Point2<f64>,
    half: f64,
}

/// A polyline's segments, ready for `distance`.
#[derive(Clone, Debug)]
pub struct Segments {
    segs: Vec<Segment>,
    /// The polyline itself, for the cases the bound does not serve (fewer than two points, a
    /// non-finite query).
    points: Vec<Point2<f64>>,
    closed: bool,
}

/// Relative slack on the skipping bound, far above the rounding of the bound's few operations:
/// a segment is skipped only when it is certainly farther than the best one so far.
const SLACK: f64 = 1e-9;

impl Segments {
    /// The segments of `p` (its closing segment included when `closed`).
    pub fn new(p: &[Point2<f64>], closed: bool) -> Segments {
        let n = p.len();
        let count = match n {
            0 | 1 => 0,
            _ if closed => n,
            _ => n - 1,
        };
        let segs = (0..count)
            .map(|i| {
                let (a, b) = (p[i], p[(i + 1) % n]);
                let ab = b - a;
                Segment {
                    a,
                    ab,
                    len2: ab.norm_squared().max(f64::MIN_POSITIVE),
                    mid: a + ab * 0.5,
                    half: 0.5 * ab.norm(),
                }
            })
            .collect();
        Segments {
            segs,
            points: p.to_vec(),
            closed,
        }
    }

    /// Distance from `q` to the polyline, equal to `distance_to_polyline(q, p, closed)`.
    /// `hint` is the segment to try first (the nearest one of the previous query, when queries
    /// run along a curve); it is updated to this query's nearest segment.
    pub fn distance(&self, q: &Point2<f64>, hint: &mut usize) -> f64 {
        if self.segs.is_empty() || !(q.x.is_finite() && q.y.is_finite()) {
            // No segments, or no bound holds for such a point: the plain scan.
            return distance_to_polyline(q, &self.points, self.closed);
        }
        let exact = |s: &Segment| {
            let t = ((q - s.a).dot(&s.ab) / s.len2).clamp(0.0, 1.0);
            (q - (s.a + t * s.ab)).norm()
        };
        let start = (*hint).min(self.segs.len() - 1);
        let mut best = exact(&self.segs[start]);
        let mut arg = start;
        for (i, s) in self.segs.iter().enumerate() {
            if i == start {
                continue;
            }
            let reach = (best + s.half) * (1.0 + SLACK);
            if (q - s.mid).norm_squared() > reach * reach {
                continue;
            }
            let d = exact(s);
            if d < best {
                best = d;
                arg = i;
            }
        }
        *hint = arg;
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    fn ragged(n: usize, seed: &mut u64) -> Vec<Point2<f64>> {
        (0..n)
            .map(|k| {
                let t = k as f64 / n as f64 * std::f64::consts::TAU;
                let r = 100.0 + 30.0 * lcg(seed);
                Point2::new(r * t.cos(), 0.6 * r * t.sin())
            })
            .collect()
    }

    #[test]
    fn distances_equal_the_plain_scan_to_the_bit() {
        let mut seed = 11;
        for closed in [true, false] {
            for n in [1, 2, 3, 36, 72, 250] {
                let p = ragged(n, &mut seed);
                let segs = Segments::new(&p, closed);
                let mut hint = 0;
                for _ in 0..400 {
                    let q = Point2::new(
                        300.0 * lcg(&mut seed) - 150.0,
                        200.0 * lcg(&mut seed) - 100.0,
                    );
                    let want = distance_to_polyline(&q, &p, closed);
                    let got = segs.distance(&q, &mut hint);
                    assert_eq!(
                        got.to_bits(),
                        want.to_bits(),
                        "n {n} closed {closed} q {q:?}"
                    );
                }
            }
        }
        let none = Segments::new(&[], true);
        assert_eq!(none.distance(&Point2::origin(), &mut 0), f64::INFINITY);
    }

    #[test]
    fn the_bit_check_rejects_a_distance_that_skips_a_nearer_segment() {
        // The same comparison, fed the distance to the polyline without its nearest segment,
        // must fail: the check is not blind to a bound that skips too much.
        let mut seed = 5;
        let p = ragged(72, &mut seed);
        let q = Point2::new(20.0, -10.0);
        let segs = Segments::new(&p, true);
        let mut hint = 0;
        let got = segs.distance(&q, &mut hint);
        let second = (0..p.len())
            .filter(|&i| i != hint)
            .map(|i| distance_to_polyline(&q, &[p[i], p[(i + 1) % p.len()]], false))
            .fold(f64::INFINITY, f64::min);
        assert_eq!(got.to_bits(), distance_to_polyline(&q, &p, true).to_bits());
        assert_ne!(second.to_bits(), got.to_bits());
    }
}
