//! The baselines' matching rules: closest point on the projected model contour (ICP), and
//! nearest neighbour with a contour-normal angle test (ICP-NormVec).

use nalgebra::{Point2, Vector2};

/// Closest point on the closed model contour polyline for each sample; returns the point and the
/// nearer end vertex of the segment it lies on.
pub fn icp_matches(
    samples: &[Point2<f64>],
    _closed: bool,
    model: &[Point2<f64>],
) -> Vec<Option<(Point2<f64>, usize)>> {
    let n = model.len();
    samples
        .iter()
        .map(|s| {
            let mut best: Option<(f64, Point2<f64>, usize)> = None;
            for i in 0..n {
                let (a, b) = (model[i], model[(i + 1) % n]);
                let ab = b - a;
                let u = if ab.norm_squared() > 0.0 {
                    ((s - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let p = a + ab * u;
                let d = (s - p).norm_squared();
                if best.is_none_or(|b| d < b.0) {
                    best = Some((d, p, if u < 0.5 { i } else { (i + 1) % n }));
                }
            }
            best.map(|(_, p, k)| (p, k))
        })
        .collect()
}

/// Unit normals of a polyline (tangent by central differences, turned by -90 degrees).
pub fn curve_normals(p: &[Point2<f64>], closed: bool) -> Vec<Vector2<f64>> {
    let n = p.len();
    (0..n)
        .map(|i| {
            let (prev, next) = if closed {
                (p[(i + n - 1) % n], p[(i + 1) % n])
            } else {
                (p[i.saturating_sub(1)], p[(i + 1).min(n - 1)])
            };
            let t = next - prev;
            Vector2::new(t.y, -t.x)
                .try_normalize(1e-12)
                .unwrap_or_else(Vector2::zeros)
        })
        .collect()
}

/// Nearest model contour vertex whose normal is within `max_angle_deg` of the sample's normal;
/// `None` when no vertex passes (the sample is rejected).
pub fn icp_normvec_matches(
    samples: &[Point2<f64>],
    closed: bool,
    model: &[Point2<f64>],
    max_angle_deg: f64,
) -> Vec<Option<(Point2<f64>, usize)>> {
    let ns = curve_normals(samples, closed);
    let nm = curve_normals(model, true);
    let cos_max = max_angle_deg.to_radians().cos();
    samples
        .iter()
        .zip(&ns)
        .map(|(s, n_s)| {
            let mut best: Option<(f64, usize)> = None;
            for (k, (m, n_m)) in model.iter().zip(&nm).enumerate() {
                // Open annotations have no known side: compare normals up to sign.
                let c = n_s.dot(n_m);
                let ok = if closed {
                    c >= cos_max
                } else {
                    c.abs() >= cos_max
                };
                if !ok {
                    continue;
                }
                let d = (s - m).norm_squared();
                if best.is_none_or(|b| d < b.0) {
                    best = Some((d, k));
                }
            }
            best.map(|(_, k)| (model[k], k))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Vec<Point2<f64>> {
        vec![
            Point2::new(0.0, 0.0),
            Point2::new(10.0, 0.0),
            Point2::new(10.0, 10.0),
            Point2::new(0.0, 10.0),
        ]
    }

    #[test]
    fn icp_takes_the_closest_point_and_normvec_respects_the_normal() {
        let m = square();
        let r = icp_matches(&[Point2::new(3.0, -1.0)], true, &m);
        assert_eq!(r[0].unwrap().0, Point2::new(3.0, 0.0));
        // A sample near the bottom edge but whose own normal points along +x is matched to the
        // right edge by the normal test.
        let samples = vec![
            Point2::new(9.0, -1.0),
            Point2::new(9.0, 0.0),
            Point2::new(9.0, 1.0),
        ];
        let dense: Vec<Point2<f64>> = (0..40)
            .map(|i| {
                let (side, u) = (i / 10, (i % 10) as f64);
                [
                    Point2::new(u, 0.0),
                    Point2::new(10.0, u),
                    Point2::new(10.0 - u, 10.0),
                    Point2::new(0.0, 10.0 - u),
                ][side]
            })
            .collect();
        let r = icp_normvec_matches(&samples, false, &dense, 30.0);
        let p = r[1].unwrap().0;
        assert_eq!(p.x, 10.0, "{p}");
        assert!(icp_matches(&samples, false, &dense)[1].unwrap().0.y == 0.0);
    }
}
