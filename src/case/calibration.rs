//! Which cup calibration a case's cup gets: a calibration holds for the views it was learned
//! on, so by default the shipped one learned on the case's views is taken (the paper's views'
//! when none was), and a user's calibration learned on other views is used with a warning.

use crate::case::Case;
use crate::pipeline::{CupCalibration, CupEstimator, ReconParams, UncertaintyParams, ViewFit};
use nalgebra::{Matrix3, Point2, Point3, Vector2, Vector3};

/// How a case's cup is calibrated.
#[derive(Clone, Debug)]
pub enum CalibrationChoice {
    /// The shipped calibration of the realistic protocol (or the ideal one) for the cup
    /// estimator, learned on the case's views (`CupCalibration::shipped_for_views`).
    Shipped {
        /// The realistic protocol's calibrations (patients' X-rays) rather than the ideal's.
        realistic: bool,
        /// The cup estimator.
        estimator: CupEstimator,
    },
    /// No calibration: the fitted cup and the resamples' spread alone.
    None {
        /// The cup estimator.
        estimator: CupEstimator,
    },
    /// A given calibration (read from `name`), whatever views it was learned on.
    Given {
        /// The calibration.
        calibration: CupCalibration,
        /// Where it came from (a file's path).
        name: String,
    },
}

/// The calibration a case's cup got, as report.json records it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CalibrationUsed {
    /// Which: a shipped file's repository name, a user's file, or "none".
    pub name: String,
    /// The views it was learned on (None when it does not say).
    pub views: Option<Vec<String>>,
    /// Whether those are the case's views: "same", "other" or "unrecorded" ("none" without a
    /// calibration).
    pub views_fit: &'static str,
}

/// A case's parameters with its calibration applied, what the report records of it, and the
/// warning, if any (`CalibrationChoice::apply`).
pub type Calibrated = (
    ReconParams,
    UncertaintyParams,
    CalibrationUsed,
    Option<String>,
);

impl CalibrationChoice {
    /// From a `--calibration` argument: none given, the shipped one for the case's views;
    /// "none", no calibration; a path, `given` (the file as read and checked).
    pub fn from_arg(
        arg: Option<&str>,
        realistic: bool,
        estimator: CupEstimator,
        given: CupCalibration,
    ) -> Self {
        match arg {
            None => CalibrationChoice::Shipped {
                realistic,
                estimator,
            },
            Some("none") => CalibrationChoice::None { estimator },
            Some(path) => CalibrationChoice::Given {
                calibration: given,
                name: path.to_string(),
            },
        }
    }

    /// `prm` and `up` with the calibration for `case` in place of their cup correction and
    /// model SD (`resolve`).
    pub fn apply(&self, case: &Case, prm: &ReconParams, up: &UncertaintyParams) -> Calibrated {
        let (calibration, used, warning) = self.resolve(case);
        let prm = ReconParams {
            cup: calibration.correcting(prm.cup.clone()),
            ..prm.clone()
        };
        let up = UncertaintyParams {
            model_sd_mm: calibration.model_sd_mm,
            ..up.clone()
        };
        (prm, up, used, warning)
    }

    /// The calibration for `case`, what the report records of it, and a warning when it was
    /// learned on other views than the case's.
    pub fn resolve(&self, case: &Case) -> (CupCalibration, CalibrationUsed, Option<String>) {
        let directions = case.source_directions();
        let (calibration, name) = match self {
            CalibrationChoice::None { estimator } => {
                let used = CalibrationUsed {
                    name: "none".into(),
                    views: None,
                    views_fit: "none",
                };
                return (CupCalibration::none(*estimator), used, None);
            }
            CalibrationChoice::Shipped {
                realistic,
                estimator,
            } => {
                let (c, name, _) =
                    CupCalibration::shipped_for_views(*realistic, *estimator, &directions);
                (c, name.to_string())
            }
            CalibrationChoice::Given { calibration, name } => (calibration.clone(), name.clone()),
        };
        let fit = calibration.view_fit(&directions);
        let warning = calibration.view_warning(&name, &directions, &case.view_turns());
        let used = CalibrationUsed {
            name,
            views: calibration.views.clone(),
            views_fit: match fit {
                ViewFit::Same => "same",
                ViewFit::Other(_) => "other",
                ViewFit::Unrecorded => "unrecorded",
            },
        };
        (calibration, used, warning)
    }
}

impl Case {
    /// Each view's source direction seen from the object (unit; in the body frame when the
    /// case is in body axes, as the cup's orientation and the prior need). The object is where
    /// the rays through the views' outline centroids pass closest to each other (least
    /// squares), the template's start where they do not cross.
    pub fn source_directions(&self) -> Vec<Vector3<f64>> {
        let object = self.outlines_meet().unwrap_or(self.init.center);
        self.cameras
            .iter()
            .map(|c| (c.center() - object).normalize())
            .collect()
    }

    /// The point nearest to the rays through each view's outline centroid, or None when they
    /// are (nearly) parallel or a view has no outline point.
    fn outlines_meet(&self) -> Option<Point3<f64>> {
        let mut a = Matrix3::zeros();
        let mut b = Vector3::zeros();
        for (cam, curves) in self.cameras.iter().zip(&self.observed) {
            let points: Vec<_> = curves.iter().flat_map(|c| &c.points).collect();
            if points.is_empty() {
                return None;
            }
            let n = points.len() as f64;
            let centroid = Point2::from(points.iter().map(|p| p.coords).sum::<Vector2<f64>>() / n);
            let r = cam.ray(&centroid);
            let across = Matrix3::identity() - r * r.transpose();
            a += across;
            b += across * cam.center().coords;
        }
        // Rays 2 degrees apart leave the smallest eigenvalue about 1e-3 (a case's views are
        // held 15 apart, MIN_VIEW_SPREAD_DEG); parallel ones 0.
        let smallest = a.symmetric_eigenvalues().min();
        if !(smallest > 1e-4) {
            return None;
        }
        a.lu().solve(&b).map(Point3::from)
    }

    /// The views as turns of the antero-posterior view about the longitudinal axis z, to the
    /// nearest degree, with the tilt about x where a source leaves the horizontal plane by a
    /// degree or more ("z:0,z:20,z:-20", "z:0,z:20+x:15"): how a warning names them.
    pub fn view_turns(&self) -> String {
        self.source_directions()
            .iter()
            .map(|d| {
                // "z:t+x:a" puts the source at Rx(a) Rz(t) y = (-sin t, cos t cos a, cos t sin a).
                let turn = (-d.x).atan2(d.y.hypot(d.z)).to_degrees();
                let tilt = d.z.atan2(d.y).to_degrees();
                let z = format!("z:{}", turn.round() as i64);
                if tilt.abs() >= 1.0 {
                    format!("{z}+x:{}", tilt.round() as i64)
                } else {
                    z
                }
            })
            .collect::<Vec<_>>()
            .join(",")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::case::CaseFile;
    use crate::sim::{phantom, simulate_case, NoiseLevel, PhantomParams, XrayGeometry};
    use crate::views::{view_set_mismatch_deg, ViewRotation};
    use std::path::Path;

    /// A phantom case taken with `views` (as `--views` writes them), through a case file.
    fn case_with(views: &str) -> Case {
        let truth = phantom(&PhantomParams::default()).mesh;
        let geometry = XrayGeometry {
            views: views.split(',').map(|v| v.parse().unwrap()).collect(),
            ..Default::default()
        };
        let level = NoiseLevel::level(1).unwrap();
        let sim = simulate_case(&truth, &geometry, 2.0, &level, 3).unwrap();
        CaseFile::from_parts(&sim.cameras, &sim.observed, &sim.init)
            .validate(Path::new("case.json"))
            .unwrap()
    }

    const SHIPPED: CalibrationChoice = CalibrationChoice::Shipped {
        realistic: true,
        estimator: CupEstimator::ObservedPart,
    };

    #[test]
    fn a_case_gets_the_shipped_calibration_learned_on_its_views() {
        let judet = case_with("z:0,z:45,z:-45");
        assert_eq!(judet.view_turns(), "z:0,z:45,z:-45");
        let (c, used, warning) = SHIPPED.resolve(&judet);
        assert_eq!(used.name, "calibration/realistic-judet.json");
        assert_eq!(used.views_fit, "same");
        assert_eq!(c, CupCalibration::shipped_realistic_judet());
        assert_eq!(warning, None);
        // Companion: the paper's views get the paper's calibration, not the Judet one.
        let paper = case_with("z:0,z:20,z:-20");
        let (c, used, warning) = SHIPPED.resolve(&paper);
        assert_eq!(used.name, "calibration/realistic.json");
        assert_eq!(c, CupCalibration::shipped_realistic());
        assert_eq!(warning, None);
        // Views turned a few degrees from the Judet ones (a patient turned 48 degrees) still
        // count as them.
        let (_, used, _) = SHIPPED.resolve(&case_with("z:2,z:48,z:-43"));
        assert_eq!(used.name, "calibration/realistic-judet.json");
    }

    #[test]
    fn views_no_calibration_was_learned_on_are_warned_of() {
        // An inlet view in place of an oblique: no shipped calibration was learned on these, so
        // the paper's is used and the warning names both sets.
        let inlet = case_with("z:0,z:20,x:25");
        let spec: Vec<Vector3<f64>> = ["z:0", "z:20", "x:25"]
            .iter()
            .map(|v| v.parse::<ViewRotation>().unwrap().source_direction())
            .collect();
        let off = view_set_mismatch_deg(&inlet.source_directions(), &spec).unwrap();
        assert!(off < 1.5, "{off}");
        let turns = inlet.view_turns();
        assert!(turns.starts_with("z:0,z:20,z:0+x:2"), "{turns}");
        let (c, used, warning) = SHIPPED.resolve(&inlet);
        assert_eq!(c, CupCalibration::shipped_realistic());
        assert_eq!(used.views_fit, "other");
        let w = warning.expect("a warning");
        assert!(
            w.contains("z:0,z:20,z:-20") && w.contains(&turns) && w.contains("stands 2"),
            "{w}"
        );
        // A given calibration learned on other views is used as given, with the warning.
        let given = CalibrationChoice::Given {
            calibration: CupCalibration::shipped_realistic(),
            name: "mine.json".into(),
        };
        let (c, used, warning) = given.resolve(&case_with("z:0,z:45,z:-45"));
        assert_eq!(c, CupCalibration::shipped_realistic());
        assert_eq!((used.name.as_str(), used.views_fit), ("mine.json", "other"));
        assert!(warning.is_some_and(|w| w.contains("mine.json")));
        // A calibration that does not say its views, and none at all, warn of nothing.
        let unrecorded = CalibrationChoice::Given {
            calibration: CupCalibration {
                views: None,
                ..CupCalibration::shipped_realistic()
            },
            name: "old.json".into(),
        };
        let (_, used, warning) = unrecorded.resolve(&inlet);
        assert_eq!((used.views_fit, warning), ("unrecorded", None));
        let none = CalibrationChoice::None {
            estimator: CupEstimator::ObservedPart,
        };
        let (c, used, warning) = none.resolve(&inlet);
        assert_eq!(
            (c.model_sd_mm, used.name.as_str(), warning),
            (0.0, "none", None)
        );
    }
}
