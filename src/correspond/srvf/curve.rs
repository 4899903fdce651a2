//! Square-root velocity functions of sampled curves: q = b' / sqrt(|b'|), scaled to unit L2 norm
//! (norm = mean over samples, so <q, q> = 1); a sampled curve read between its samples; and the
//! position term that pairs two curves' samples drawn in one frame.

use nalgebra::{Point2, Vector2};

/// SRVF of `b` sampled at n points on t in [0, 1]. Closed curves use periodic central
/// differences (the sample after the last is the first); open ones one-sided at the ends.
pub fn srvf(b: &[Point2<f64>], closed: bool) -> Vec<Vector2<f64>> {
    let n = b.len();
    if n < 2 {
        return vec![Vector2::zeros(); n];
    }
    let dt = if closed {
        1.0 / n as f64
    } else {
        1.0 / (n - 1) as f64
    };
    let mut q: Vec<Vector2<f64>> = (0..n)
        .map(|i| {
            let d = if closed {
                (b[(i + 1) % n] - b[(i + n - 1) % n]) / (2.0 * dt)
            } else if i == 0 {
                (b[1] - b[0]) / dt
            } else if i == n - 1 {
                (b[n - 1] - b[n - 2]) / dt
            } else {
                (b[i + 1] - b[i - 1]) / (2.0 * dt)
            };
            let s = d.norm();
            if s > 1e-12 {
                d / s.sqrt()
            } else {
                Vector2::zeros()
            }
        })
        .collect();
    let norm = inner(&q, &q).sqrt();
    if norm > 0.0 {
        for v in &mut q {
            *v /= norm;
        }
    }
    q
}

/// <a, b> = mean over samples of a_s . b_s.
pub fn inner(a: &[Vector2<f64>], b: &[Vector2<f64>]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum::<f64>() / a.len().max(1) as f64
}

/// ||a - b||^2 in the same discrete norm.
pub fn dist2(a: &[Vector2<f64>], b: &[Vector2<f64>]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).norm_squared())
        .sum::<f64>()
        / a.len().max(1) as f64
}

/// The rotation angle theta maximising <q1, R(theta) q2> (Kabsch in 2D: always a proper rotation,
/// never a reflection).
pub fn best_rotation(q1: &[Vector2<f64>], q2: &[Vector2<f64>]) -> f64 {
    let (mut c, mut s) = (0.0, 0.0);
    for (a, b) in q1.iter().zip(q2) {
        c += a.dot(b);
        s += b.x * a.y - b.y * a.x;
    }
    s.atan2(c)
}

/// Rotate every vector by theta.
pub fn rotate(q: &[Vector2<f64>], theta: f64) -> Vec<Vector2<f64>> {
    let (s, c) = theta.sin_cos();
    q.iter()
        .map(|v| Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y))
        .collect()
}

/// The position term of a DP between curves drawn in one frame: both curves' arc-length samples
/// on the same grids as their SRVFs (in units of a length scale), and its weight. A piece of the
/// warp then costs, besides the SRVF difference, `weight * |a(t) - b(gamma(t))|^2` per sample:
/// of two warps that match the shapes alike, the one that pairs nearby points wins.
#[derive(Clone, Copy, Debug)]
pub struct Anchor<'a> {
    /// Curve A's samples (q1's grid).
    pub a: &'a [Vector2<f64>],
    /// Curve B's samples (q2's grid).
    pub b: &'a [Vector2<f64>],
    /// The weight (0: the SRVF energy alone).
    pub weight: f64,
}

impl Anchor<'_> {
    /// The position energy of a warp given at A's samples in B's sample units (mean over
    /// samples, times the weight).
    pub fn energy(&self, gamma_samples: &[f64]) -> f64 {
        let n = self.a.len().max(1) as f64;
        self.weight
            * self
                .a
                .iter()
                .zip(gamma_samples)
                .map(|(a, &y)| (a - interp(self.b, y)).norm_squared())
                .sum::<f64>()
            / n
    }
}

/// Linear interpolation of q at fractional index y (clamped to the grid).
#[inline]
pub(super) fn interp(q: &[Vector2<f64>], y: f64) -> Vector2<f64> {
    let last = q.len() - 1;
    let y = y.clamp(0.0, last as f64);
    let k = (y as usize).min(last.saturating_sub(1));
    let u = y - k as f64;
    if last == 0 {
        q[0]
    } else {
        q[k] * (1.0 - u) + q[k + 1] * u
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srvf_has_unit_norm_and_ignores_translation_and_scale() {
        let b: Vec<Point2<f64>> = (0..50)
            .map(|i| {
                let t = i as f64 / 50.0 * std::f64::consts::TAU;
                Point2::new(3.0 * t.cos(), t.sin())
            })
            .collect();
        let q = srvf(&b, true);
        assert!((inner(&q, &q) - 1.0).abs() < 1e-12);
        let moved: Vec<Point2<f64>> = b
            .iter()
            .map(|p| Point2::new(7.0 * p.x + 5.0, 7.0 * p.y - 2.0))
            .collect();
        assert!(dist2(&q, &srvf(&moved, true)) < 1e-20);
    }

    #[test]
    fn best_rotation_recovers_a_known_angle() {
        let b: Vec<Point2<f64>> = (0..40)
            .map(|i| Point2::new(i as f64, (i as f64 * 0.3).sin()))
            .collect();
        let q = srvf(&b, false);
        let r = rotate(&q, 0.7);
        assert!((best_rotation(&r, &q) - 0.7).abs() < 1e-12);
    }
}
