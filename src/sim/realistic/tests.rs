//! The realistic protocol's tests: the drift's SD and correlation length, an arc left out and the
//! outline moved by the errors, clicked annotations, mask boundaries, and settings refused.

use super::*;
use crate::sim::{phantom, PhantomParams, XrayGeometry};

fn setup() -> (Mesh, SimSetup) {
    let truth = phantom(&PhantomParams::default()).mesh;
    let s = SimSetup::new(&truth, &XrayGeometry::default()).unwrap();
    (truth, s)
}

#[test]
fn the_drift_has_the_sd_and_correlation_length_asked_for() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let s: Vec<f64> = (0..400).map(|i| i as f64 * 2.0).collect();
    let (mut v0, mut c10, mut c40, mut n) = (0.0, 0.0, 0.0, 0.0);
    for _ in 0..200 {
        let d = smooth_process(&s, 800.0, true, 2.0, 20.0, &mut rng);
        for i in 0..s.len() {
            v0 += d[i] * d[i];
            c10 += d[i] * d[(i + 5) % s.len()];
            c40 += d[i] * d[(i + 20) % s.len()];
            n += 1.0;
        }
    }
    let sd = (v0 / n).sqrt();
    let (r10, r40) = (c10 / v0, c40 / v0);
    assert!((sd - 2.0).abs() < 0.15, "sd {sd}");
    // Squared-exponential of length 20: exp(-1/8) = 0.88 at 10 px, exp(-2) = 0.14 at 40.
    assert!((r10 - 0.88).abs() < 0.06, "10 px: {r10}");
    assert!((r40 - 0.135).abs() < 0.08, "40 px: {r40}");
    // Companion: white jitter's correlation at 10 px is near zero, which the test refuses.
    let white: Vec<f64> = (0..400)
        .map(|_| rand_distr::StandardNormal.sample(&mut rng))
        .collect();
    let w10: f64 = (0..400)
        .map(|i| white[i] * white[(i + 5) % 400])
        .sum::<f64>()
        / white.iter().map(|x| x * x).sum::<f64>();
    assert!(
        (w10 - 0.88).abs() >= 0.06,
        "white noise passed as drift: {w10}"
    );
}

#[test]
fn a_realistic_case_leaves_out_an_arc_and_moves_the_outline_by_the_errors() {
    let (truth, s) = setup();
    let level = NoiseLevel::level(1).unwrap();
    let e = RealisticErrors::default();
    let case = s.realistic_case(&truth, &e, &level, 11).unwrap();
    assert_eq!(
        case.cameras, s.cameras,
        "the reconstruction gets the nominal views"
    );
    for (v, curves) in case.observed.iter().enumerate() {
        let c = &curves[0];
        assert!(!c.closed);
        let full = crate::geom::polyline_length(&s.outlines[v], true);
        let kept = crate::geom::polyline_length(&c.points, false);
        assert!(
            (0.6..0.8).contains(&(kept / full)),
            "view {v}: kept {kept:.0} of {full:.0} px"
        );
    }
    // Same seed, same case; another seed, another.
    let again = s.realistic_case(&truth, &e, &level, 11).unwrap();
    assert_eq!(case.observed[1][0].points, again.observed[1][0].points);
    let other = s.realistic_case(&truth, &e, &level, 12).unwrap();
    assert_ne!(case.observed[1][0].points, other.observed[1][0].points);
    // No errors and nothing left out: the ideal outline, closed and exact.
    let none = RealisticErrors::jitter_only(0.0);
    let exact = s.realistic_case(&truth, &none, &level, 11).unwrap();
    for v in 0..s.cameras.len() {
        assert!(exact.observed[v][0].closed);
        assert_eq!(exact.observed[v][0].points, s.outlines[v]);
    }
    // A 5 % magnification error is seen: the outline grows about the principal point.
    let big = RealisticErrors {
        magnification: 0.05,
        ..none.clone()
    };
    let grown = (0..20)
        .map(|seed| {
            let c = s.realistic_case(&truth, &big, &level, seed).unwrap();
            let l = crate::geom::polyline_length(&c.observed[0][0].points, true);
            (l / crate::geom::polyline_length(&s.outlines[0], true) - 1.0).abs()
        })
        .fold(0.0, f64::max);
    assert!(grown > 0.03, "magnification not applied: {grown}");
}

/// Clicks 20 px apart: each annotation is a polygon of about its length / 20 points, 20 px
/// apart give or take the drift and jitter, over the same arc, and the method gets the curve
/// through them; the default keeps the outline's own points, a few px apart, and hands them
/// on as they are (the companions: clicks not applied are told apart, and a traced line is
/// not taken for clicks).
#[test]
fn clicks_make_the_annotation_a_polygon_of_points_that_far_apart() {
    let (truth, s) = setup();
    let level = NoiseLevel::level(1).unwrap();
    let dense = RealisticErrors::default();
    let clicks = RealisticErrors {
        click_px: 20.0,
        ..dense.clone()
    };
    let spacing = |c: &Curve| {
        let mut d: Vec<f64> = c.points.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    let a = s.realistic_case(&truth, &dense, &level, 5).unwrap();
    let (given, _) = s.realistic_annotations(&truth, &clicks, &level, 5).unwrap();
    let handed = s.realistic_case(&truth, &clicks, &level, 5).unwrap();
    let (traced, _) = s.realistic_annotations(&truth, &dense, &level, 5).unwrap();
    for v in 0..s.cameras.len() {
        let (da, db) = (&a.observed[v][0], &given[v][0]);
        assert_eq!(handed.observed[v][0], db.clicked());
        // The case keeps the clicks for the overlays; a traced line has none.
        assert_eq!(handed.clicks[v], db.points);
        assert!(a.clicks[v].is_empty());
        assert!(handed.observed[v][0].points.len() > db.points.len());
        assert_eq!(*da, traced[v][0]);
        assert!(!db.closed);
        let length = crate::geom::polyline_length(&db.points, false);
        assert!(
            (17.0..23.0).contains(&spacing(db)),
            "view {v}: {}",
            spacing(db)
        );
        assert!(
            (db.points.len() as f64 - length / 20.0 - 1.0).abs() < 0.15 * length / 20.0,
            "view {v}: {} points over {length:.0} px",
            db.points.len()
        );
        assert!(
            spacing(da) < 10.0,
            "view {v}: the default's {}",
            spacing(da)
        );
        let kept = crate::geom::polyline_length(&da.points, false);
        assert!((length / kept - 1.0).abs() < 0.1, "{length} against {kept}");
    }
    // Companion: a negative or infinite distance is refused, naming the setting.
    for bad in [-1.0, f64::INFINITY] {
        let e = RealisticErrors {
            click_px: bad,
            ..dense.clone()
        };
        let err = s
            .realistic_case(&truth, &e, &level, 5)
            .unwrap_err()
            .to_string();
        assert!(err.contains("click_px"), "{err}");
    }
    // Clicks farther apart than the outline is long leave too few points: refused as the
    // annotation's, with the count and the setting, not as the truth's outline.
    let sparse = RealisticErrors {
        click_px: 1e9,
        ..dense.clone()
    };
    let err = s.realistic_case(&truth, &sparse, &level, 5).unwrap_err();
    assert!(
        matches!(err, SimError::Annotation { view: 0, count, click_px, .. }
            if count < MIN_KEPT_POINTS && click_px == 1e9),
        "{err}"
    );
    let err = err.to_string();
    assert!(
        err.contains("simulated annotation in view 0") && err.contains("click_px 1000000000"),
        "{err}"
    );
}

/// A mask's boundary: with `raster_px` every annotation point is the centre of a grid cell,
/// consecutive points (round the closed outline) are 8-neighbours, every point lies within
/// half a cell's diagonal of the outline and every outline point within a cell of the
/// chain. The companions: without it the points are off the grid; a pitch below 0, above
/// 100 px or not finite is refused naming the setting.
#[test]
fn a_mask_boundary_is_a_staircase_of_grid_cells_along_the_outline() {
    let (truth, s) = setup();
    let level = NoiseLevel::level(1).unwrap();
    let exact = RealisticErrors::jitter_only(0.0);
    let on_grid =
        |p: &Point2<f64>, pitch: f64| (p.x / pitch).fract() == 0.0 && (p.y / pitch).fract() == 0.0;
    for pitch in [1.0, 4.0] {
        let e = RealisticErrors {
            raster_px: pitch,
            ..exact.clone()
        };
        let case = s.realistic_case(&truth, &e, &level, 5).unwrap();
        for v in 0..s.cameras.len() {
            let c = &case.observed[v][0];
            assert!(c.closed);
            let n = c.points.len();
            let outline = &s.outlines[v];
            let length = crate::geom::polyline_length(outline, true);
            assert!(
                n as f64 > 0.7 * length / pitch,
                "view {v}: {n} cells over {length:.0} px"
            );
            for (i, p) in c.points.iter().enumerate() {
                assert!(on_grid(p, pitch), "view {v}: {p:?}");
                let d = (c.points[(i + 1) % n] - p) / pitch;
                assert!(
                    d.x.abs() <= 1.0 && d.y.abs() <= 1.0 && d.norm() > 0.0,
                    "view {v}: step {d:?} at {i}"
                );
            }
            let far = |from: &[Point2<f64>], to: &[Point2<f64>]| {
                let segs = crate::geom::Segments::new(to, true);
                from.iter().map(|p| segs.distance(p)).fold(0.0, f64::max)
            };
            assert!(far(&c.points, outline) <= 0.5 * std::f64::consts::SQRT_2 * pitch + 1e-9);
            assert!(far(outline, &c.points) <= pitch);
        }
    }
    // Companion: the traced points, off the grid.
    let traced = s.realistic_case(&truth, &exact, &level, 5).unwrap();
    let off = traced.observed[0][0]
        .points
        .iter()
        .filter(|p| !on_grid(p, 1.0))
        .count();
    assert!(off > traced.observed[0][0].points.len() / 2, "{off}");
    for bad in [-1.0, 101.0, f64::NAN] {
        let e = RealisticErrors {
            raster_px: bad,
            ..exact.clone()
        };
        let err = s
            .realistic_case(&truth, &e, &level, 5)
            .unwrap_err()
            .to_string();
        assert!(err.contains("raster_px"), "{err}");
    }
}

#[test]
fn realistic_settings_no_draw_can_be_made_with_are_refused() {
    let (truth, s) = setup();
    let level = NoiseLevel::level(1).unwrap();
    let ok = RealisticErrors::default();
    for bad in [
        RealisticErrors {
            pose_deg: f64::NAN,
            ..ok.clone()
        },
        RealisticErrors {
            jitter_px: -1.0,
            ..ok.clone()
        },
        RealisticErrors {
            magnification: 0.5,
            ..ok.clone()
        },
        RealisticErrors {
            left_out: 0.9,
            ..ok.clone()
        },
        RealisticErrors {
            drift_length_px: 0.0,
            ..ok.clone()
        },
        // Finite but beyond any one view's error: named, not run into unprojectable views.
        RealisticErrors {
            pose_deg: 1e300,
            ..ok.clone()
        },
        RealisticErrors {
            pose_mm: 101.0,
            ..ok.clone()
        },
        RealisticErrors {
            drift_px: 1e9,
            ..ok.clone()
        },
    ] {
        assert!(matches!(
            s.realistic_case(&truth, &bad, &level, 1),
            Err(SimError::Setting { .. })
        ));
    }
    let e = RealisticErrors {
        pose_deg: 1e300,
        ..ok.clone()
    };
    let msg = e.validate().unwrap_err().to_string();
    assert!(
        msg.contains("pose_deg = 1e300") && msg.contains("0 to 30 degrees"),
        "{msg}"
    );
    assert!(s.realistic_case(&truth, &ok, &level, 1).is_ok());
    // Companion: the largest errors taken still make a case.
    let edge = RealisticErrors {
        pose_deg: MAX_POSE_DEG,
        pose_mm: MAX_POSE_MM,
        ..ok.clone()
    };
    assert!(edge.validate().is_ok());
}
