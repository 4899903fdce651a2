//! Batched alignment: many curve pairs at once on a pool of threads, results in input order
//! (the study sweeps and, later, the GPU DP kernel use this entry point).

use super::{align, Alignment, CurveKind, SrvfError, SrvfParams};
use nalgebra::Point2;

/// One problem: align B onto A.
#[derive(Clone, Debug)]
pub struct AlignProblem {
    /// Curve A (the reference).
    pub a: Vec<Point2<f64>>,
    /// Curve B (aligned onto A).
    pub b: Vec<Point2<f64>>,
    /// Closed, open, or open against closed.
    pub kind: CurveKind,
}

/// Align every pair; `threads` workers (at least one). Output order = input order.
pub fn align_batch(
    problems: &[AlignProblem],
    prm: &SrvfParams,
    threads: usize,
) -> Vec<Result<Alignment, SrvfError>> {
    crate::geom::pool_map(threads, problems, |_, p| align(&p.a, &p.b, p.kind, prm))
}

/// B's matched points turned by the alignment's rotation and moved and scaled onto A (same
/// centroid and length), so that any tool can score the result in its own metric.
pub fn aligned_b(al: &Alignment) -> Vec<Point2<f64>> {
    let n = al.b_points.len().max(1) as f64;
    let ca = al
        .a_points
        .iter()
        .map(|p| p.coords)
        .sum::<nalgebra::Vector2<f64>>()
        / n;
    let cb = al
        .b_points
        .iter()
        .map(|p| p.coords)
        .sum::<nalgebra::Vector2<f64>>()
        / n;
    let len = |p: &[Point2<f64>]| p.windows(2).map(|w| (w[1] - w[0]).norm()).sum::<f64>();
    let s = len(&al.a_points) / len(&al.b_points).max(1e-12);
    let (sn, c) = al.rotation.sin_cos();
    al.b_points
        .iter()
        .map(|p| {
            let d = p.coords - cb;
            Point2::from(ca + s * nalgebra::Vector2::new(c * d.x - sn * d.y, sn * d.x + c * d.y))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batch_matches_one_by_one_in_order() {
        let curve = |k: f64| -> Vec<Point2<f64>> {
            (0..120)
                .map(|i| {
                    let t = std::f64::consts::TAU * i as f64 / 120.0;
                    Point2::new((1.0 + 0.2 * (k * t).cos()) * t.cos(), 0.7 * t.sin())
                })
                .collect()
        };
        let problems: Vec<AlignProblem> = (2..6)
            .map(|k| AlignProblem {
                a: curve(2.0),
                b: curve(k as f64),
                kind: CurveKind::Closed,
            })
            .collect();
        let prm = SrvfParams {
            samples: 60,
            ..Default::default()
        };
        let batch = align_batch(&problems, &prm, 3);
        for (p, r) in problems.iter().zip(&batch) {
            let single = align(&p.a, &p.b, p.kind, &prm).unwrap();
            assert_eq!(r.as_ref().unwrap().distance, single.distance);
        }
        assert!(
            batch[0].as_ref().unwrap().distance < 1e-3,
            "same shape first"
        );
        assert!(batch[3].as_ref().unwrap().distance > batch[0].as_ref().unwrap().distance);
        // aligned B lands on A for identical shapes.
        let al = batch[0].as_ref().unwrap();
        let err = aligned_b(al)
            .iter()
            .zip(&al.a_points)
            .map(|(b, a)| (b - a).norm())
            .fold(0.0, f64::max);
        assert!(err < 0.05, "{err}");
    }
}
