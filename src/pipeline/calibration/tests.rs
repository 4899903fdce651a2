//! The calibration's tests: the shipped files, learning, and refusals.

use super::*;
use crate::pipeline::params::MAX_SHRINK;
use nalgebra::Vector3;

/// Training runs of one source whose errors and resampled SDs are `pairs` (truth 50 mm).
fn runs(pairs: &[(f64, f64)]) -> Vec<TrainingRun> {
    pairs
        .iter()
        .map(|&(e, sd)| TrainingRun {
            fitted_mm: 50.0 + e,
            truth_mm: 50.0,
            resample_sd_mm: sd,
            source: 0,
            depth_offset_mm: f64::NAN,
        })
        .collect()
}

fn what(bias: bool) -> Learn {
    if bias {
        Learn::Bias
    } else {
        Learn::SdOnly
    }
}

#[test]
fn the_shipped_calibrations_parse() {
    // Every file in calibration/ reads: the built-in ones and those a user names by path
    // (other views', as realistic-judet.json).
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration");
    let mut on_disk = Vec::new();
    for e in std::fs::read_dir(&dir).unwrap() {
        let path = e.unwrap().path();
        if path.extension().is_some_and(|x| x == "json") {
            on_disk.push(CupCalibration::read(&path).unwrap_or_else(|e| panic!("{e}")));
        }
    }
    let read = on_disk.len();
    assert!(read >= 5, "{read} calibration files in {}", dir.display());
    for c in [
        CupCalibration::shipped_ideal(),
        CupCalibration::shipped_realistic(),
        CupCalibration::shipped_ideal_prior_region(),
        CupCalibration::shipped_realistic_prior_region(),
    ]
    .into_iter()
    .chain(on_disk)
    {
        assert!(c.model_sd_mm > 0.0 && c.runs >= MIN_TRAINING_RUNS, "{c:?}");
    }
    for c in [
        CupCalibration::shipped_ideal_prior_region(),
        CupCalibration::shipped_realistic_prior_region(),
    ] {
        assert_eq!(c.cup_estimator(), Some(CupEstimator::PriorRegion));
    }
}

#[test]
fn the_learned_sd_covers_68_percent_of_the_training_runs() {
    // Errors N(0, 1.2) (a fixed pseudo-random sample), resampled SDs 0.2: s near 1.18.
    let mut pairs = Vec::new();
    let mut seed = 12345.0f64;
    for _ in 0..2000 {
        // Box-Muller from a small LCG.
        seed = (seed * 48271.0) % 2147483647.0;
        let u1 = seed / 2147483647.0;
        seed = (seed * 48271.0) % 2147483647.0;
        let u2 = seed / 2147483647.0;
        let z = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        pairs.push((1.2 * z, 0.2));
    }
    let c = CupCalibration::learn(
        &runs(&pairs),
        CupEstimator::ObservedPart,
        what(false),
        "test".into(),
    )
    .unwrap();
    let total = (c.model_sd_mm.powi(2) + 0.04).sqrt();
    assert!((total - 1.2).abs() < 0.08, "total SD {total}");
    assert!((c.training_coverage - NOMINAL_COVERAGE).abs() < 0.01);
    // Companion: the resampled SD alone covers far fewer, which a calibrated claim refuses.
    let alone = pairs.iter().filter(|(e, sd)| e.abs() <= *sd).count() as f64 / 2000.0;
    assert!((alone - NOMINAL_COVERAGE).abs() > 0.3, "{alone}");
    // Too few runs, or none finite, are refused.
    assert!(matches!(
        CupCalibration::learn(
            &runs(&pairs[..5]),
            CupEstimator::ObservedPart,
            what(true),
            String::new()
        ),
        Err(CalibrationError::TooFewRuns { runs: 5, .. })
    ));
    let nan = vec![(f64::NAN, 0.2); 50];
    assert!(CupCalibration::learn(
        &runs(&nan),
        CupEstimator::ObservedPart,
        what(true),
        String::new()
    )
    .is_err());
    // With the bias: errors shifted by +0.8 mm give the same model SD and a bias of 0.8
    // (the sample's own mean); without it the shift inflates the SD (the companion).
    let mean = pairs.iter().map(|(e, _)| e).sum::<f64>() / pairs.len() as f64;
    let shifted: Vec<(f64, f64)> = pairs.iter().map(|(e, sd)| (e + 0.8, *sd)).collect();
    let b = CupCalibration::learn(
        &runs(&shifted),
        CupEstimator::PriorRegion,
        what(true),
        String::new(),
    )
    .unwrap();
    assert!((b.bias_mm - (mean + 0.8)).abs() < 1e-9, "{b:?}");
    assert_eq!(b.cup_estimator(), Some(CupEstimator::PriorRegion));
    let centred: Vec<(f64, f64)> = pairs.iter().map(|(e, sd)| (e - mean, *sd)).collect();
    let c0 = CupCalibration::learn(
        &runs(&centred),
        CupEstimator::ObservedPart,
        what(false),
        String::new(),
    )
    .unwrap();
    assert!((b.model_sd_mm - c0.model_sd_mm).abs() < 1e-9);
    let nb = CupCalibration::learn(
        &runs(&shifted),
        CupEstimator::PriorRegion,
        what(false),
        String::new(),
    )
    .unwrap();
    assert!(nb.model_sd_mm > b.model_sd_mm + 0.2, "{nb:?} {b:?}");
    // Training errors no acetabulum gives (a broken study's cups of 1e300 mm) are refused,
    // naming the field, instead of written into a file that reading back would refuse.
    let broken: Vec<(f64, f64)> = pairs.iter().map(|(e, sd)| (e + 1e300, *sd)).collect();
    let e = CupCalibration::learn(
        &runs(&broken),
        CupEstimator::ObservedPart,
        what(true),
        String::new(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("bias_mm = 1.") && e.contains("e300") && e.contains("+-10 mm"),
        "{e}"
    );
    let wide: Vec<(f64, f64)> = pairs.iter().map(|(e, sd)| (40.0 * e, *sd)).collect();
    let e = CupCalibration::learn(
        &runs(&wide),
        CupEstimator::ObservedPart,
        what(false),
        String::new(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("model_sd_mm") && e.contains("0 to 20 mm"), "{e}");
    // Companion: errors at the edge (a bias of 9 mm) are still learned.
    let edge: Vec<(f64, f64)> = centred.iter().map(|(e, sd)| (e + 9.0, *sd)).collect();
    let ok = CupCalibration::learn(
        &runs(&edge),
        CupEstimator::ObservedPart,
        what(true),
        String::new(),
    )
    .unwrap();
    assert!((ok.bias_mm - 9.0).abs() < 1e-9, "{ok:?}");
}

/// Runs of `source` whose truths spread 42-60 mm and whose fitted diameters are `fit(truth)`.
fn spread(n: usize, source: usize, fit: impl Fn(f64) -> f64) -> Vec<TrainingRun> {
    (0..n)
        .map(|k| {
            let truth = 42.0 + (k * 7 % 19) as f64;
            TrainingRun {
                fitted_mm: fit(truth),
                truth_mm: truth,
                resample_sd_mm: 0.5,
                source,
                depth_offset_mm: f64::NAN,
            }
        })
        .collect()
}

/// The observed part's calibration learned from `runs`.
fn learned(runs: &[TrainingRun], what: Learn) -> CupCalibration {
    CupCalibration::learn(runs, CupEstimator::ObservedPart, what, "t".into()).unwrap()
}

#[test]
fn the_shrink_is_one_less_the_slope_from_fitted_to_truth() {
    // An estimator that doubles each cup's departure from 50 mm and adds 1 mm: the line from
    // fitted to truth has slope 1/2, so half the departure is taken off, and every corrected
    // cup is its truth.
    let runs = spread(60, 0, |t| 51.0 + 2.0 * (t - 50.0));
    let c = learned(&runs, Learn::BiasAndShrink);
    assert!((c.shrink - 0.5).abs() < 1e-12, "{c:?}");
    let cup = c.correcting(CupParams::default());
    for r in &runs {
        assert!(
            (cup.corrected(r.fitted_mm) - r.truth_mm).abs() < 1e-9,
            "{c:?} {r:?}"
        );
    }
    // The resampled SD shrinks with the cup: covering the (zero) errors needs no model SD.
    assert!(c.model_sd_mm < 1e-9, "{c:?}");
    // Companion: the bias alone leaves the doubled departures, which the model SD must cover.
    let b = learned(&runs, Learn::Bias);
    assert_eq!((b.shrink, b.shrink_to_mm), (0.0, 0.0));
    assert!(b.model_sd_mm > 3.0, "{b:?}");
    // An estimator that halves the departures would need a slope of 2: a shrink never
    // stretches, so it stays 0 (and the bias is the mean error).
    let flat = spread(60, 0, |t| 50.0 + 0.5 * (t - 50.0));
    let f = learned(&flat, Learn::BiasAndShrink);
    assert_eq!(f.shrink, 0.0, "{f:?}");
}

#[test]
fn every_source_of_truths_weighs_the_same_in_the_bias() {
    // 200 runs of one source 3 mm too large, 20 of another 1 mm too large: the bias is 2 mm,
    // not the pooled 2.8.
    let mut runs = spread(200, 0, |t| t + 3.0);
    runs.extend(spread(20, 1, |t| t + 1.0));
    for what in [Learn::Bias, Learn::BiasAndShrink] {
        let c = learned(&runs, what);
        assert!((c.bias_mm - 2.0).abs() < 1e-9, "{c:?}");
    }
    // Companion: the same runs as one source give the pooled mean.
    let pooled: Vec<TrainingRun> = runs
        .iter()
        .map(|r| TrainingRun { source: 0, ..*r })
        .collect();
    let c = learned(&pooled, Learn::Bias);
    assert!(
        (c.bias_mm - (200.0 * 3.0 + 20.0) / 220.0).abs() < 1e-9,
        "{c:?}"
    );
}

#[test]
fn the_depth_offset_is_the_runs_mean_with_every_source_weighing_the_same() {
    // 200 runs of one source 1.0 mm too deep, 20 of another 0.5 mm: the offset is 0.75 mm,
    // not the pooled 0.95, whatever is learned of the cup; runs without one are left out.
    let deep = |n: usize, source: usize, mm: f64| -> Vec<TrainingRun> {
        spread(n, source, |t| t)
            .into_iter()
            .map(|r| TrainingRun {
                depth_offset_mm: mm,
                ..r
            })
            .collect()
    };
    let mut runs = deep(200, 0, 1.0);
    runs.extend(deep(20, 1, 0.5));
    runs.extend(spread(30, 1, |t| t));
    for what in [Learn::SdOnly, Learn::Bias, Learn::BiasAndShrink] {
        let c = learned(&runs, what);
        assert!((c.depth_mm - 0.75).abs() < 1e-9, "{c:?}");
        assert_eq!(c.correcting(CupParams::default()).depth_mm, c.depth_mm);
    }
    // Companion: runs that do not record it (studies from before the column) learn none,
    // and neither do fewer than the fewest a calibration is learned from.
    assert_eq!(learned(&spread(60, 0, |t| t), Learn::Bias).depth_mm, 0.0);
    let mut few = spread(60, 0, |t| t);
    few.extend(deep(MIN_TRAINING_RUNS - 1, 0, 2.0));
    assert_eq!(learned(&few, Learn::Bias).depth_mm, 0.0);
    // A file without the field reads as no offset; one beyond +-5 mm is refused, named.
    let ok = CupCalibration::shipped_realistic().to_json();
    let mut v: serde_json::Value = serde_json::from_str(&ok).unwrap();
    v.as_object_mut().unwrap().remove("depth_mm");
    let c = CupCalibration::parse(&v.to_string(), Path::new("c.json")).unwrap();
    assert_eq!(c.depth_mm, 0.0);
    for (value, good) in [(0.8, true), (-4.9, true), (7.0, false), (-5.5, false)] {
        v["depth_mm"] = serde_json::json!(value);
        let got = CupCalibration::parse(&v.to_string(), Path::new("c.json"));
        assert_eq!(got.is_ok(), good, "{value}: {got:?}");
        if let Err(e) = got {
            assert!(e.to_string().contains("depth_mm = "), "{e}");
        }
    }
}

#[test]
fn a_calibration_with_a_bad_shrink_is_refused() {
    let ok = CupCalibration::shipped_ideal().to_json();
    for (field, value) in [
        ("shrink", "0.95"),
        ("shrink", "-0.1"),
        ("shrink_to_mm", "1e9"),
    ] {
        let mut v: serde_json::Value = serde_json::from_str(&ok).unwrap();
        v[field] = serde_json::from_str(value).unwrap();
        let e = CupCalibration::parse(&v.to_string(), Path::new("c.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field) && e.contains("c.json"), "{e}");
    }
    // A file that says it was learned from fewer runs than any calibration is: refused,
    // named; the fewest are read.
    for (runs, good) in [
        (0, false),
        (MIN_TRAINING_RUNS - 1, false),
        (MIN_TRAINING_RUNS, true),
    ] {
        let mut v: serde_json::Value = serde_json::from_str(&ok).unwrap();
        v["runs"] = serde_json::json!(runs);
        let got = CupCalibration::parse(&v.to_string(), Path::new("c.json"));
        assert_eq!(got.is_ok(), good, "{runs}: {got:?}");
        if let Err(e) = got {
            assert!(e.to_string().contains(&format!("runs = {runs}")), "{e}");
        }
    }
    // A shrink without the diameter it pulls toward (a file that leaves `shrink_to_mm` out)
    // would cut every cup by its share: refused, naming the field.
    let mut v: serde_json::Value = serde_json::from_str(&ok).unwrap();
    v["shrink"] = serde_json::json!(0.3);
    let e = CupCalibration::parse(&v.to_string(), Path::new("c.json"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("shrink_to_mm = 0") && e.contains("where shrink > 0"),
        "{e}"
    );
    // Companion: a shrink at the edge is read.
    let mut v: serde_json::Value = serde_json::from_str(&ok).unwrap();
    v["shrink"] = serde_json::json!(MAX_SHRINK);
    v["shrink_to_mm"] = serde_json::json!(52.0);
    let c = CupCalibration::parse(&v.to_string(), Path::new("c.json")).unwrap();
    assert_eq!((c.shrink, c.shrink_to_mm), (MAX_SHRINK, 52.0));
}

#[test]
fn a_calibration_is_used_only_for_the_estimator_it_was_learned_for() {
    // A file from before the bias reads as the observed part's, without a bias.
    let old = r#"{"model_sd_mm": 1.0, "learned_from": "x", "runs": 50, "training_coverage": 0.7}"#;
    let c = CupCalibration::parse(old, Path::new("old.json")).unwrap();
    assert_eq!(
        (c.bias_mm, c.cup_estimator()),
        (0.0, Some(CupEstimator::ObservedPart))
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.json");
    std::fs::write(&path, old).unwrap();
    let arg = path.to_str();
    let ok = CupCalibration::for_estimator(
        arg,
        CupCalibration::shipped_ideal,
        CupEstimator::ObservedPart,
    );
    assert_eq!(ok.unwrap().model_sd_mm, 1.0);
    let e = CupCalibration::for_estimator(
        arg,
        CupCalibration::shipped_ideal,
        CupEstimator::PriorRegion,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("old.json") && e.contains("estimator = observed-part"),
        "{e}"
    );
    // "none": no model error, no bias, for whichever estimator.
    let none = CupCalibration::for_estimator(
        Some("none"),
        CupCalibration::shipped_ideal,
        CupEstimator::PriorRegion,
    )
    .unwrap();
    assert_eq!((none.model_sd_mm, none.bias_mm), (0.0, 0.0));
    // A bad estimator name or bias is named.
    for (field, value) in [("estimator", "\"sphere\""), ("bias_mm", "40")] {
        let mut v: serde_json::Value = serde_json::from_str(old).unwrap();
        v[field] = serde_json::from_str(value).unwrap();
        let e = CupCalibration::parse(&v.to_string(), Path::new("c.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field) && e.contains("c.json"), "{e}");
    }
}

#[test]
fn a_calibration_file_with_a_bad_field_names_it() {
    let p = Path::new("c.json");
    let ok = CupCalibration::shipped_ideal().to_json();
    assert!(CupCalibration::parse(&ok, p).is_ok());
    let mut v: serde_json::Value = serde_json::from_str(&ok).unwrap();
    v["model_sd_mm"] = serde_json::json!(-1.0);
    let bad = v.to_string();
    let e = CupCalibration::parse(&bad, p).unwrap_err().to_string();
    assert!(
        e.contains("c.json") && e.contains("model_sd_mm = -1"),
        "{e}"
    );
    let e = CupCalibration::parse("{\"model_sd\": 1}", p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a cup calibration"), "{e}");
    // The views it was learned on must read as views; a list of them does.
    for (views, ok) in [
        (serde_json::json!(["z:0", "z:45", "z:-45"]), true),
        (serde_json::json!(["z:0", "sideways"]), false),
        (serde_json::json!([]), false),
    ] {
        let mut v: serde_json::Value = serde_json::from_str(&ok_json()).unwrap();
        v["views"] = views;
        let got = CupCalibration::parse(&v.to_string(), p);
        assert_eq!(got.is_ok(), ok, "{got:?}");
        if let Err(e) = got {
            assert!(e.to_string().contains("views = "), "{e}");
        }
    }
}

fn ok_json() -> String {
    CupCalibration::shipped_realistic().to_json()
}

#[test]
fn the_shipped_calibrations_say_their_views_and_the_judet_one_is_chosen_for_its_own() {
    let dir = |s: &str| -> Vec<Vector3<f64>> {
        s.split(',')
            .map(|v| v.parse::<ViewRotation>().unwrap().source_direction())
            .collect()
    };
    for realistic in [false, true] {
        for estimator in CupEstimator::ALL {
            for (name, make) in CupCalibration::shipped_set(realistic, estimator) {
                let c = make();
                assert!(c.views.is_some(), "{name}");
                assert_eq!(c.cup_estimator(), Some(estimator), "{name}");
            }
        }
    }
    let est = CupEstimator::ObservedPart;
    let (c, name, fit) = CupCalibration::shipped_for_views(true, est, &dir("z:0,z:45,z:-45"));
    assert_eq!(
        (name, fit),
        ("calibration/realistic-judet.json", ViewFit::Same)
    );
    assert_eq!(c, CupCalibration::shipped_realistic_judet());
    // Companions: the paper's views, and views no shipped calibration was learned on, get
    // the paper's (the second told so by its fit); the ideal protocol has its own pair.
    let (_, name, fit) = CupCalibration::shipped_for_views(true, est, &dir("z:0,z:20,z:-20"));
    assert_eq!((name, fit), ("calibration/realistic.json", ViewFit::Same));
    let (_, name, fit) = CupCalibration::shipped_for_views(true, est, &dir("z:0,z:60,z:-60"));
    assert_eq!(name, "calibration/realistic.json");
    assert!(
        matches!(fit, ViewFit::Other(Some(d)) if (d - 40.0).abs() < 1e-6),
        "{fit:?}"
    );
    let (c, name, fit) = CupCalibration::shipped_for_views(false, est, &dir("z:0,z:45,z:-45"));
    assert_eq!((name, fit), ("calibration/ideal-judet.json", ViewFit::Same));
    assert_eq!(c, CupCalibration::shipped_ideal_judet());
    let (_, name, fit) = CupCalibration::shipped_for_views(false, est, &dir("z:0,z:60,z:-60"));
    assert_eq!(name, "calibration/ideal.json");
    assert!(matches!(fit, ViewFit::Other(_)));
    let (_, _, fit) = CupCalibration::shipped_for_views(true, est, &dir("z:0,z:20"));
    assert_eq!(fit, ViewFit::Other(None));
}
