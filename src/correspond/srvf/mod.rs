//! SRVF elastic registration: q = b' / sqrt(|b'|); rotation, seed and warp by dynamic programming.
//! `align_on` takes a pair of curves of any kind to its alignment: closed and open ones in
//! `align`, an open arc against part of a closed curve in `partial`.

mod align;
mod band;
mod band_tables;
mod batch;
mod curve;
mod dp;
mod dp_many;
mod partial;

pub use align::{
    align_closed, align_open, Alignment, CurveKind, SrvfError, SrvfParams, MAX_SAMPLES, MIN_SAMPLES,
};
pub(crate) use band::prepare as prepare_steps;
pub use band::{trace_band, BandProblem, BandSolver, DpOn, NO_STEP};
pub use batch::{align_batch, aligned_b, AlignProblem};
pub use curve::{best_rotation, dist2, inner, rotate, srvf, Anchor};
pub use dp::{coprime_steps, dp_warp, edge_cost, traceback, warp_from_path, CurvePair, Warp};
use nalgebra::Point2;
pub use partial::align_partial;

/// Align with the given kind.
pub fn align(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    kind: CurveKind,
    prm: &SrvfParams,
) -> Result<Alignment, SrvfError> {
    align_on(a, b, kind, prm, DpOn::Host)
}

/// `align` with its DPs run where `on` says (the host's f64 DP, or an engine's: the GPU's in a
/// study on the device).
pub fn align_on(
    a: &[Point2<f64>],
    b: &[Point2<f64>],
    kind: CurveKind,
    prm: &SrvfParams,
    on: DpOn,
) -> Result<Alignment, SrvfError> {
    match kind {
        CurveKind::Closed => align::align_closed_on(a, b, prm, false, on),
        CurveKind::Open => align::align_open_on(a, b, prm, on),
        CurveKind::Partial => partial::align_partial_on(a, b, prm, on),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point2;

    /// A closed, non-symmetric blob.
    fn blob(n: usize, phase: f64) -> Vec<Point2<f64>> {
        (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * (i as f64 / n as f64 + phase);
                let r = 1.0 + 0.3 * (2.0 * t).cos() + 0.15 * (3.0 * t + 0.4).sin();
                Point2::new(r * t.cos(), 0.8 * r * t.sin())
            })
            .collect()
    }

    fn similarity(p: &[Point2<f64>], theta: f64, s: f64, tx: f64, ty: f64) -> Vec<Point2<f64>> {
        let (sn, c) = theta.sin_cos();
        p.iter()
            .map(|q| Point2::new(s * (c * q.x - sn * q.y) + tx, s * (sn * q.x + c * q.y) + ty))
            .collect()
    }

    /// Re-parameterise: sample the same curve at unevenly spaced parameter values.
    fn uneven(n: usize) -> Vec<Point2<f64>> {
        (0..n)
            .map(|i| {
                let u = i as f64 / n as f64;
                let w = u + 0.08 * (std::f64::consts::TAU * u).sin();
                let t = std::f64::consts::TAU * w;
                let r = 1.0 + 0.3 * (2.0 * t).cos() + 0.15 * (3.0 * t + 0.4).sin();
                Point2::new(r * t.cos(), 0.8 * r * t.sin())
            })
            .collect()
    }

    fn prm(t: usize) -> SrvfParams {
        SrvfParams {
            samples: t,
            ..Default::default()
        }
    }

    #[test]
    fn closed_distance_is_zero_for_similar_reparameterised_shifted_copies() {
        let a = blob(300, 0.0);
        let b = similarity(&uneven(257), 0.9, 2.5, 40.0, -7.0);
        let b: Vec<Point2<f64>> = b[80..].iter().chain(&b[..80]).cloned().collect(); // new start
        let al = align_closed(&a, &b, &prm(100), false).unwrap();
        assert!(al.distance < 0.05, "distance {}", al.distance);
        assert!(
            ((al.rotation + 0.9 + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI)
                .abs()
                < 0.05,
            "rotation {}",
            al.rotation
        );
        // The matched points map back onto A under the inverse similarity.
        let back = similarity(&al.b_points, -0.9, 1.0 / 2.5, 0.0, 0.0);
        let off = nalgebra::Vector2::new(40.0, -7.0);
        let (sn, c) = (-0.9f64).sin_cos();
        let off = nalgebra::Vector2::new(c * off.x - sn * off.y, sn * off.x + c * off.y) / 2.5;
        let err = al
            .a_points
            .iter()
            .zip(&back)
            .map(|(a, b)| (a - (b - off)).norm())
            .fold(0.0, f64::max);
        assert!(err < 0.1, "max correspondence error {err}");
        // The companion: a different shape is far.
        let other: Vec<Point2<f64>> = (0..200)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 200.0;
                Point2::new(t.cos(), 0.3 * t.sin())
            })
            .collect();
        assert!(align_closed(&a, &other, &prm(100), false).unwrap().distance > 0.2);
    }

    #[test]
    fn seed_search_finds_a_known_shift() {
        let t = 120;
        let n = 600;
        let a = blob(n, 0.0);
        for shift in [0usize, 85, 305, 500] {
            let b: Vec<Point2<f64>> = (0..n).map(|i| a[(i + shift) % n]).collect();
            let al = align_closed(&a, &b, &prm(t), false).unwrap();
            // B starts at a[shift], arc length s from a[0]: the seed that brings B back onto A's
            // start is (L - s) / L * T samples.
            let s: f64 = (0..shift).map(|i| (a[i + 1] - a[i]).norm()).sum();
            let l = crate::geom::polyline_length(&a, true);
            let expect = (((l - s) / l * t as f64).round() as usize) % t;
            let d = (al.seed as isize - expect as isize).rem_euclid(t as isize) as usize;
            assert!(
                d.min(t - d) <= 1,
                "shift {shift}: seed {} expected {expect}, distance {}",
                al.seed,
                al.distance
            );
            assert!(al.distance < 0.05, "distance {}", al.distance);
        }
    }

    #[test]
    fn fast_closed_search_matches_the_exhaustive_oracle() {
        let a = blob(150, 0.0);
        let b = similarity(&uneven(140), 0.4, 1.3, 0.0, 0.0);
        let b: Vec<Point2<f64>> = b.iter().map(|p| Point2::new(p.x * 1.15, p.y)).collect(); // a different shape
        let p = prm(48);
        let fast = align_closed(&a, &b, &p, false).unwrap();
        let exact = align_closed(&a, &b, &p, true).unwrap();
        assert!(
            fast.distance <= exact.distance * 1.01 + 1e-9,
            "fast {} exhaustive {}",
            fast.distance,
            exact.distance
        );
        assert!(exact.distance <= fast.distance + 1e-12);
    }

    #[test]
    fn fast_search_is_within_one_percent_of_exhaustive_on_varied_curves() {
        let shape = |n: usize, k2: f64, k3: f64, ph: f64, sx: f64| -> Vec<Point2<f64>> {
            (0..n)
                .map(|i| {
                    let t = std::f64::consts::TAU * i as f64 / n as f64;
                    let r = 1.0
                        + k2 * (2.0 * t).cos()
                        + k3 * (3.0 * t + ph).sin()
                        + 0.05 * (5.0 * t).cos();
                    Point2::new(sx * r * t.cos(), r * t.sin())
                })
                .collect()
        };
        let cases = [
            (
                shape(200, 0.3, 0.15, 0.4, 1.0),
                shape(180, 0.25, 0.2, 0.9, 1.1),
                0.8,
                40,
            ),
            (
                shape(200, 0.1, 0.3, 0.0, 0.8),
                shape(220, 0.2, 0.25, 0.0, 0.9),
                -1.9,
                150,
            ),
            (
                shape(150, 0.4, 0.05, 1.0, 1.3),
                shape(160, 0.35, 0.1, 1.3, 1.0),
                2.5,
                7,
            ),
            (
                shape(240, 0.05, 0.05, 0.0, 0.6),
                shape(240, 0.08, 0.02, 0.5, 0.7),
                0.2,
                100,
            ),
            (
                shape(200, 0.3, 0.3, 2.0, 1.0),
                shape(200, 0.2, 0.1, 2.2, 1.2),
                -0.7,
                0,
            ),
            (
                shape(180, 0.2, 0.0, 0.0, 1.5),
                shape(190, 0.25, 0.05, 0.3, 1.4),
                1.1,
                60,
            ),
        ];
        let p = prm(64);
        for (i, (a, b, rot, start)) in cases.iter().enumerate() {
            let b = similarity(b, *rot, 1.7, 3.0, -2.0);
            let b: Vec<Point2<f64>> = b[*start..].iter().chain(&b[..*start]).cloned().collect();
            let fast = align_closed(a, &b, &p, false).unwrap();
            let exact = align_closed(a, &b, &p, true).unwrap();
            assert!(
                fast.distance <= exact.distance * 1.01 + 1e-9,
                "case {i}: fast {} exhaustive {}",
                fast.distance,
                exact.distance
            );
        }
    }

    /// Open wiggly arcs of varied shape for the quality checks.
    fn wiggle(n: usize, f: f64, amp: f64, bend: f64) -> Vec<Point2<f64>> {
        (0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64 * 3.0;
                Point2::new(t + 0.1 * (f * t).cos(), amp * (f * t).sin() + bend * t * t)
            })
            .collect()
    }

    #[test]
    fn fast_open_alignment_is_within_one_percent_of_the_exhaustive_answer() {
        // Exhaustive: full-grid DP at every step and rotation/DP alternation to convergence.
        let exact = SrvfParams {
            band: 0,
            max_alternations: 30,
            rel_tol: 0.0,
            ..prm(200)
        };
        let cases = [
            (wiggle(120, 2.0, 1.0, 0.2), wiggle(150, 2.6, 0.8, 0.3), 0.9),
            (wiggle(200, 4.0, 0.5, 0.0), wiggle(90, 3.0, 0.7, 0.1), -2.0),
            (wiggle(80, 1.0, 1.5, 0.4), wiggle(80, 1.5, 1.2, -0.2), 2.8),
            (
                wiggle(150, 5.0, 0.3, 0.3),
                wiggle(170, 5.5, 0.35, 0.25),
                0.1,
            ),
        ];
        for (i, (a, b, rot)) in cases.iter().enumerate() {
            let b = similarity(b, *rot, 0.6, 1.0, 2.0);
            let fast = align_open(a, &b, &prm(200)).unwrap();
            let best = align_open(a, &b, &exact).unwrap();
            assert!(
                fast.distance <= best.distance * 1.01 + 1e-9,
                "case {i}: fast {} exhaustive {}",
                fast.distance,
                best.distance
            );
        }
    }

    #[test]
    fn fast_partial_alignment_is_within_one_percent_of_a_dense_search() {
        // The oracle: every start (T of them) x 15 lengths x both directions, each aligned with
        // the full-grid DP; the fast search must do at least as well within 1 %.
        let t = 40;
        let p = SrvfParams { band: 0, ..prm(t) };
        let b = blob(300, 0.0);
        let poly = crate::geom::ClosedPolyline::new(&b);
        let cases = [
            (40usize, 130usize, 0.5, false),
            (200, 330, -1.0, true),
            (10, 70, 2.0, false),
        ];
        for (i, &(s0, s1, rot, rev)) in cases.iter().enumerate() {
            let idx: Vec<usize> = (s0..=s1).collect();
            let arc: Vec<Point2<f64>> = idx.iter().map(|&k| b[k % 300]).collect();
            // A different shape: stretch the arc before moving it.
            let arc: Vec<Point2<f64>> = arc.iter().map(|q| Point2::new(q.x * 1.2, q.y)).collect();
            let mut a = similarity(&arc, rot, 2.0, -1.0, 4.0);
            if rev {
                a.reverse();
            }
            let fast = align_partial(&a, &b, &p).unwrap();
            let ratio = crate::geom::polyline_length(&a, false)
                / 2.0
                / crate::geom::polyline_length(&b, true);
            let mut best = f64::INFINITY;
            for dir in [false, true] {
                let mut aa = a.clone();
                if dir {
                    aa.reverse();
                }
                for k in 0..t {
                    for f in 0..15 {
                        let len = ratio * (0.6 + 0.06 * f as f64) * poly.total;
                        let start = poly.total * k as f64 / t as f64;
                        let sub: Vec<Point2<f64>> = (0..t)
                            .map(|r| poly.at(start + len * r as f64 / (t - 1) as f64).0)
                            .collect();
                        let al = align_open(&aa, &sub, &p).unwrap();
                        best = best.min(al.distance);
                    }
                }
            }
            assert!(
                fast.distance <= best * 1.01 + 1e-9,
                "case {i}: fast {} dense search {best}",
                fast.distance
            );
        }
    }

    #[test]
    fn open_curves_align_up_to_similarity() {
        let a: Vec<Point2<f64>> = (0..90)
            .map(|i| {
                let t = i as f64 / 89.0 * 3.0;
                Point2::new(t, (2.0 * t).sin() + 0.2 * t * t)
            })
            .collect();
        let b = similarity(&a, -1.2, 0.5, 3.0, 3.0);
        let al = align_open(&a, &b, &prm(100)).unwrap();
        assert!(al.distance < 0.05, "{}", al.distance);
        assert!((al.rotation - 1.2).abs() < 0.05);
        let other: Vec<Point2<f64>> = (0..90).map(|i| Point2::new(i as f64, 0.0)).collect();
        assert!(align_open(&a, &other, &prm(100)).unwrap().distance > 0.3);
    }

    #[test]
    fn partial_arc_lands_on_the_right_part_of_the_closed_curve() {
        let b = blob(400, 0.0);
        // A is 40 % of B, from sample 100 to 260, moved, and drawn the other way round.
        let mut a = similarity(&b[100..=260], 0.3, 1.7, 5.0, 5.0);
        a.reverse();
        let al = align_partial(&a, &b, &prm(100)).unwrap();
        assert!(al.reversed);
        assert!(al.distance < 0.08, "distance {}", al.distance);
        // First point of A (B's sample 260) should land near B's vertex 260, the last near 100.
        let first = al.b_index[0];
        let last = al.b_index[al.b_index.len() - 1];
        assert!((first - 260.0).abs() < 8.0, "first {first}");
        assert!((last - 100.0).abs() < 8.0, "last {last}");
    }

    #[test]
    fn bad_curves_are_errors_not_panics() {
        let p = prm(50);
        let one = vec![Point2::new(0.0, 0.0)];
        let dup = vec![Point2::new(1.0, 1.0); 10];
        let nan = vec![
            Point2::new(0.0, 0.0),
            Point2::new(f64::NAN, 1.0),
            Point2::new(1.0, 0.0),
        ];
        let ok = blob(20, 0.0);
        assert!(matches!(
            align_closed(&one, &ok, &p, false),
            Err(SrvfError::TooFewPoints { .. })
        ));
        assert!(matches!(
            align_open(&ok, &dup, &p),
            Err(SrvfError::ZeroLength { curve: "B" })
        ));
        assert!(matches!(
            align_partial(&nan, &ok, &p),
            Err(SrvfError::NonFinite { index: 1, .. })
        ));
        assert!(matches!(
            align_closed(&ok, &ok, &prm(3), false),
            Err(SrvfError::SampleCount(3))
        ));
        assert!(matches!(
            align_closed(&ok, &ok, &prm(MAX_SAMPLES + 1), false),
            Err(SrvfError::SampleCount(50_001))
        ));
        assert!(align_closed(&ok, &ok, &prm(MIN_SAMPLES), false).is_ok());
        // Finite coordinates whose distances overflow (1e308 apart) cannot be measured.
        let huge = vec![
            Point2::new(1e308, 1e308),
            Point2::new(-1e308, 1e308),
            Point2::new(-1e308, -1e308),
            Point2::new(1e308, -1e308),
        ];
        assert!(matches!(
            align_closed(&huge, &ok, &p, false),
            Err(SrvfError::Overflow { curve: "A" })
        ));
        // Companion: the same shape at 1e150 is measured, and matches a square.
        let big: Vec<_> = huge
            .iter()
            .map(|q| Point2::from(q.coords * 1e-158))
            .collect();
        let square: Vec<_> = huge
            .iter()
            .map(|q| Point2::from(q.coords * 1e-308))
            .collect();
        let al = align_closed(&big, &square, &p, false).unwrap();
        assert!(al.distance < 0.05, "{}", al.distance);
        // Distinct points all within 1e-12 units of each other have no measurable length, and
        // the error says so instead of calling them one point.
        let speck: Vec<_> = huge
            .iter()
            .map(|q| Point2::from(q.coords * 1e-322))
            .collect();
        assert!(speck.windows(2).all(|w| w[0] != w[1]));
        let e = align_closed(&ok, &speck, &p, false).unwrap_err();
        assert_eq!(e, SrvfError::ZeroLength { curve: "B" });
        assert!(e.to_string().contains("within 1e-12"), "{e}");
        // Companion: the same square at 1e-3 units is measured.
        let small: Vec<_> = huge
            .iter()
            .map(|q| Point2::from(q.coords * 1e-311))
            .collect();
        assert!(align_closed(&small, &square, &p, false).is_ok());
    }
}
