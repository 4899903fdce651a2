//! A polyline prepared for many point-distance queries: the same distances as
//! `distance_to_polyline`, to the bit. The segments are kept as columns (start, direction,
//! squared length), so that a query measures several segments at a time.

use super::distance_to_polyline;
use nalgebra::Point2;

/// A polyline's segments, ready for `distance`: segment i runs from `(ax[i], ay[i])` along
/// `(bx[i], by[i])`; `len2[i]` is its squared length, floored as `distance_to_polyline` floors it.
#[derive(Clone, Debug)]
pub struct Segments {
    ax: Vec<f64>,
    ay: Vec<f64>,
    bx: Vec<f64>,
    by: Vec<f64>,
    len2: Vec<f64>,
    /// The polyline itself, for the cases the columns do not serve (fewer than two points, a
    /// non-finite query).
    points: Vec<Point2<f64>>,
    closed: bool,
}

/// Segments measured together (one pass of the inner loop).
const LANES: usize = 8;

impl Segments {
    /// The segments of `p` (its closing segment included when `closed`).
    pub fn new(p: &[Point2<f64>], closed: bool) -> Segments {
        let n = p.len();
        let count = match n {
            0 | 1 => 0,
            _ if closed => n,
            _ => n - 1,
        };
        let mut out = Segments {
            ax: Vec::with_capacity(count),
            ay: Vec::with_capacity(count),
            bx: Vec::with_capacity(count),
            by: Vec::with_capacity(count),
            len2: Vec::with_capacity(count),
            points: p.to_vec(),
            closed,
        };
        for i in 0..count {
            let (a, b) = (p[i], p[(i + 1) % n]);
            let ab = b - a;
            out.ax.push(a.x);
            out.ay.push(a.y);
            out.bx.push(ab.x);
            out.by.push(ab.y);
            out.len2.push(ab.norm_squared().max(f64::MIN_POSITIVE));
        }
        out
    }

    /// Distance from `q` to the polyline, equal to `distance_to_polyline(q, p, closed)`: each
    /// segment's squared distance is computed with the same operations in the same order, and
    /// the square root of their least is the least of their square roots.
    pub fn distance(&self, q: &Point2<f64>) -> f64 {
        if self.ax.is_empty() || !(q.x.is_finite() && q.y.is_finite()) {
            return distance_to_polyline(q, &self.points, self.closed);
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.nearest_avx2(q.x, q.y) }.sqrt();
        }
        self.nearest(q.x, q.y).sqrt()
    }

    /// `nearest` compiled with AVX2 (call only where the CPU has it).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn nearest_avx2(&self, qx: f64, qy: f64) -> f64 {
        self.nearest(qx, qy)
    }

    /// The least squared distance from (qx, qy) to a segment (NaN distances are passed over,
    /// as `f64::min` passes them).
    #[inline(always)]
    fn nearest(&self, qx: f64, qy: f64) -> f64 {
        let n = self.ax.len();
        let mut best = f64::INFINITY;
        let mut d2 = [0.0; LANES];
        let mut i = 0;
        while i < n {
            let m = (n - i).min(LANES);
            let (ax, ay) = (&self.ax[i..i + m], &self.ay[i..i + m]);
            let (bx, by, l2) = (&self.bx[i..i + m], &self.by[i..i + m], &self.len2[i..i + m]);
            for k in 0..m {
                // As distance_to_polyline: t = ((q - a) . ab / |ab|^2) in [0, 1], then
                // |q - (a + t ab)|^2 (x term first).
                let t = (((qx - ax[k]) * bx[k] + (qy - ay[k]) * by[k]) / l2[k]).clamp(0.0, 1.0);
                let (dx, dy) = (qx - (ax[k] + t * bx[k]), qy - (ay[k] + t * by[k]));
                d2[k] = dx * dx + dy * dy;
            }
            for &d in &d2[..m] {
                if d < best {
                    best = d;
                }
            }
            i += m;
        }
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
                for _ in 0..400 {
                    let q = Point2::new(
                        300.0 * lcg(&mut seed) - 150.0,
                        200.0 * lcg(&mut seed) - 100.0,
                    );
                    let want = distance_to_polyline(&q, &p, closed);
                    let got = segs.distance(&q);
                    assert_eq!(
                        got.to_bits(),
                        want.to_bits(),
                        "n {n} closed {closed} q {q:?}"
                    );
                }
            }
        }
        let none = Segments::new(&[], true);
        assert_eq!(none.distance(&Point2::origin()), f64::INFINITY);
    }

    #[test]
    fn the_bit_check_rejects_a_distance_that_skips_a_nearer_segment() {
        // The same comparison, fed the distance to the polyline without its nearest segment,
        // must fail: the check is not blind to a bound that skips too much.
        let mut seed = 5;
        let p = ragged(72, &mut seed);
        let q = Point2::new(20.0, -10.0);
        let segs = Segments::new(&p, true);
        let got = segs.distance(&q);
        let one = |i: usize| distance_to_polyline(&q, &[p[i], p[(i + 1) % p.len()]], false);
        let nearest = (0..p.len())
            .min_by(|&i, &j| one(i).total_cmp(&one(j)))
            .expect("72 segments");
        let second = (0..p.len())
            .filter(|&i| i != nearest)
            .map(one)
            .fold(f64::INFINITY, f64::min);
        assert_eq!(got.to_bits(), distance_to_polyline(&q, &p, true).to_bits());
        assert_ne!(second.to_bits(), got.to_bits());
    }
}
