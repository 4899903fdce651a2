//! The calibrations built into the program (the repository's `calibration/*.json`), and which of
//! them was learned on a case's views.

use super::CupCalibration;
use crate::pipeline::params::CupEstimator;
use crate::views::{view_set_mismatch_deg, ViewRotation};
use nalgebra::Vector3;
use std::path::Path;

/// How far each view of a case may stand from a calibration's (the angle between the two
/// sources' directions, degrees, views paired as `view_set_mismatch_deg` pairs them) for the
/// calibration to count as learned on the case's views: wide enough for a patient turned a few
/// degrees more or less than planned, narrow enough to tell the paper's obliques (20 degrees)
/// from the Judet ones (45).
pub const VIEW_MATCH_DEG: f64 = 10.0;

/// Whether a calibration was learned on a set of views.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ViewFit {
    /// Its views and the set pair within `VIEW_MATCH_DEG`.
    Same,
    /// They do not: the worst pair's angle, degrees (None when the sets differ in size).
    Other(Option<f64>),
    /// The calibration does not say which views it was learned on.
    Unrecorded,
}

/// The calibration learned from the shared populations' ideal-protocol study (47 acetabula,
/// levels 1, 3, 5 x 3 runs, srvf, seed 7; see docs/population.md and the data's attribution in
/// README.md), shipped with the program: `acetab simulate` uses it for the ideal protocol.
pub const IDEAL_JSON: &str = include_str!("../../../calibration/ideal.json");
/// The same for the prior-region cup estimator (`CupEstimator::PriorRegion`; its bias and
/// model SD, learned from the same study made with the shipped prior, leave-one-subject-out):
/// `acetab simulate --prior default --cup-estimator prior-region` uses it for the ideal protocol.
pub const IDEAL_PRIOR_REGION_JSON: &str =
    include_str!("../../../calibration/ideal-prior-region.json");
/// The same for the realistic protocol with the prior-region cup: `acetab reconstruct --prior
/// default --cup-estimator prior-region` and realistic studies use it.
pub const REALISTIC_PRIOR_REGION_JSON: &str =
    include_str!("../../../calibration/realistic-prior-region.json");
/// The same for the realistic protocol: `acetab simulate --protocol realistic` and `acetab
/// reconstruct` (a patient's X-rays) use it.
pub const REALISTIC_JSON: &str = include_str!("../../../calibration/realistic.json");
/// The same for the ideal protocol with the antero-posterior view and the two Judet obliques
/// (`z:0,z:45,z:-45`; a bias and model SD, no shrink): `acetab simulate` uses it for ideal
/// studies with those views.
pub const IDEAL_JUDET_JSON: &str = include_str!("../../../calibration/ideal-judet.json");
/// The same for the realistic protocol with the antero-posterior view and the two Judet
/// obliques (`z:0,z:45,z:-45`), with a learned shrink: `acetab reconstruct` uses it for cases
/// taken with those views, `acetab simulate --protocol realistic` for studies with them.
pub const REALISTIC_JUDET_JSON: &str = include_str!("../../../calibration/realistic-judet.json");

/// A calibration built into the program: the repository file it was made as, and the function
/// that gives it.
pub type Shipped = (&'static str, fn() -> CupCalibration);

impl CupCalibration {
    /// The shipped calibration for studies under the ideal protocol.
    pub fn shipped_ideal() -> CupCalibration {
        Self::embedded(IDEAL_JSON, "calibration/ideal.json")
    }

    /// The shipped calibration for studies under the ideal protocol with the prior-region cup.
    pub fn shipped_ideal_prior_region() -> CupCalibration {
        Self::embedded(
            IDEAL_PRIOR_REGION_JSON,
            "calibration/ideal-prior-region.json",
        )
    }

    /// The shipped calibration for the realistic protocol and patients' X-rays with the
    /// prior-region cup.
    pub fn shipped_realistic_prior_region() -> CupCalibration {
        Self::embedded(
            REALISTIC_PRIOR_REGION_JSON,
            "calibration/realistic-prior-region.json",
        )
    }

    /// The shipped calibration for the realistic protocol and patients' X-rays.
    pub fn shipped_realistic() -> CupCalibration {
        Self::embedded(REALISTIC_JSON, "calibration/realistic.json")
    }

    /// The shipped calibration for the ideal protocol with the AP and Judet views.
    pub fn shipped_ideal_judet() -> CupCalibration {
        Self::embedded(IDEAL_JUDET_JSON, "calibration/ideal-judet.json")
    }

    /// The shipped calibration for the realistic protocol with the AP and Judet views.
    pub fn shipped_realistic_judet() -> CupCalibration {
        Self::embedded(REALISTIC_JUDET_JSON, "calibration/realistic-judet.json")
    }

    /// The calibrations shipped for a protocol (`realistic` or ideal) and cup estimator, the
    /// default one (learned with the paper's views) first.
    pub fn shipped_set(realistic: bool, estimator: CupEstimator) -> Vec<Shipped> {
        match (realistic, estimator) {
            (false, CupEstimator::ObservedPart) => vec![
                ("calibration/ideal.json", Self::shipped_ideal),
                ("calibration/ideal-judet.json", Self::shipped_ideal_judet),
            ],
            (false, CupEstimator::PriorRegion) => vec![(
                "calibration/ideal-prior-region.json",
                Self::shipped_ideal_prior_region,
            )],
            (true, CupEstimator::ObservedPart) => vec![
                ("calibration/realistic.json", Self::shipped_realistic),
                (
                    "calibration/realistic-judet.json",
                    Self::shipped_realistic_judet,
                ),
            ],
            (true, CupEstimator::PriorRegion) => vec![(
                "calibration/realistic-prior-region.json",
                Self::shipped_realistic_prior_region,
            )],
        }
    }

    /// The shipped calibration of a protocol and cup estimator for views whose sources stand in
    /// `directions` (from the object, body axes): the first of `shipped_set` learned on such
    /// views, else the default one; with its file name and how its views fit.
    pub fn shipped_for_views(
        realistic: bool,
        estimator: CupEstimator,
        directions: &[Vector3<f64>],
    ) -> (CupCalibration, &'static str, ViewFit) {
        let set = Self::shipped_set(realistic, estimator);
        for &(name, make) in &set {
            let c = make();
            if c.view_fit(directions) == ViewFit::Same {
                return (c, name, ViewFit::Same);
            }
        }
        let (name, make) = set[0];
        let c = make();
        let fit = c.view_fit(directions);
        (c, name, fit)
    }

    /// The source directions of the views it was learned on (None when it does not say, or a
    /// view does not read).
    pub fn source_directions(&self) -> Option<Vec<Vector3<f64>>> {
        self.views
            .as_ref()?
            .iter()
            .map(|v| v.parse::<ViewRotation>().ok().map(|v| v.source_direction()))
            .collect()
    }

    /// Whether it was learned on views whose sources stand in `directions`.
    pub fn view_fit(&self, directions: &[Vector3<f64>]) -> ViewFit {
        let Some(own) = self.source_directions() else {
            return ViewFit::Unrecorded;
        };
        match view_set_mismatch_deg(&own, directions) {
            Some(d) if d <= VIEW_MATCH_DEG => ViewFit::Same,
            other => ViewFit::Other(other),
        }
    }

    /// What to tell a user whose views (sources in `directions`, described as `theirs`) the
    /// calibration `name` was not learned on; None when it was, or when it does not say.
    pub fn view_warning(
        &self,
        name: &str,
        directions: &[Vector3<f64>],
        theirs: &str,
    ) -> Option<String> {
        let ViewFit::Other(off) = self.view_fit(directions) else {
            return None;
        };
        let own = self.views.as_deref().unwrap_or_default().join(",");
        let how = match off {
            Some(d) => format!("a view stands {d:.0} degrees from the nearest of those"),
            None => format!(
                "{} views against {}",
                directions.len(),
                self.views.as_ref().map_or(0, Vec::len)
            ),
        };
        Some(format!(
            "the cup calibration {name} was learned on the views {own}, not on {theirs} ({how}; views are turns of the antero-posterior view, sources compared in body axes: x left-right, y toward the AP source, z up): its bias, shrink and model SD may not hold for them; learn one on these views (acetab simulate --views ... --calibration none, then acetab calibrate) or use --calibration none"
        ))
    }

    /// A calibration built into the program (`json`, the repository's file `path`).
    fn embedded(json: &str, path: &str) -> CupCalibration {
        Self::parse(json, Path::new(path)).expect("the shipped calibration is valid (tested)")
    }

    /// The shipped calibration of a protocol (`realistic` or ideal) for the cup estimator
    /// `estimator`.
    pub fn shipped(realistic: bool, estimator: CupEstimator) -> fn() -> CupCalibration {
        match (realistic, estimator) {
            (false, CupEstimator::ObservedPart) => Self::shipped_ideal,
            (false, CupEstimator::PriorRegion) => Self::shipped_ideal_prior_region,
            (true, CupEstimator::ObservedPart) => Self::shipped_realistic,
            (true, CupEstimator::PriorRegion) => Self::shipped_realistic_prior_region,
        }
    }
}
