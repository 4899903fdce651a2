//! The cup uncertainty's calibration: what the resampling cannot see. Resampling the contours
//! measures how much the cup moves with the annotation's noise; it cannot measure how far the
//! outlines' sphere is from the whole acetabulum's (the walls no view outlines), which differs
//! from patient to patient and dominates the error (docs/population.md: resampled SDs of
//! 0.1-0.3 mm against cup errors of about 1.2 mm RMS). That part is learned from studies on
//! acetabula whose cup is known: a model-error SD added in quadrature, chosen so that 68 % of
//! the training runs' errors lie within the total SD (`CupCalibration::learn`). The same
//! training runs give the estimator's bias and, where its error is large against the spread of
//! acetabula, a shrink toward their mean (`CupParams::corrected`).

mod learn;
mod shipped;
#[cfg(test)]
mod tests;

pub use learn::{Learn, TrainingRun};
pub use shipped::{Shipped, ViewFit, VIEW_MATCH_DEG};

use super::params::{CupEstimator, CupParams};
use crate::views::ViewRotation;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The nominal coverage of +-1 SD.
pub const NOMINAL_COVERAGE: f64 = 0.6827;

/// A learned cup calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CupCalibration {
    /// The cup estimator it was learned for (`CupEstimator::name`; files without the field were
    /// learned for the observed part's sphere).
    #[serde(default = "observed_part")]
    pub estimator: String,
    /// The estimator's bias, mm: the training runs' mean cup error (estimate - truth), subtracted
    /// from every cup (`CupParams::bias_mm`); 0 in files without the field.
    #[serde(default)]
    pub bias_mm: f64,
    /// The share of a fitted diameter's departure from `shrink_to_mm` taken off
    /// (`CupParams::shrink`): where the estimate's error is large against the spread of the
    /// population's cups (open outlines, uncertain poses), the least-squares line from estimate to
    /// truth is flatter than 1, and the cup is pulled toward the training cups by that much. 0 in
    /// files without the field.
    #[serde(default)]
    pub shrink: f64,
    /// The diameter the shrink pulls toward, mm: the training runs' mean fitted diameter.
    #[serde(default)]
    pub shrink_to_mm: f64,
    /// The result's depth offset, mm: the training runs' mean translation to their truth along
    /// the result's depth axis (`pipeline::depth_axis`), by which every result is moved
    /// (`CupParams::depth_mm`); 0 in files without the field, and where the training runs do not
    /// record it.
    #[serde(default)]
    pub depth_mm: f64,
    /// Model-error SD of the cup diameter, mm, added in quadrature to the resampled SD (learned
    /// on the errors less the bias).
    pub model_sd_mm: f64,
    /// What it was learned from (the studies' protocol, runs, meshes); free text for people.
    pub learned_from: String,
    /// Training runs.
    pub runs: usize,
    /// Share of the training runs within their total SD (about 0.68 by construction).
    pub training_coverage: f64,
    /// The views of the studies it was learned on, each as the antero-posterior view turned
    /// about body axes (`ViewRotation` text, "z:20"); absent in files that do not say. A
    /// calibration holds for its views: the bias and SD of a cup read from other views differ
    /// (docs/population.md, "Which views under the realistic protocol").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub views: Option<Vec<String>>,
}

/// Why a calibration file cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CalibrationError {
    /// The file cannot be read.
    #[error("{path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a calibration.
    #[error("{path}: not a cup calibration: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// A field holds a value that cannot be used.
    #[error("{path}: {field} = {value}: must be {expected}")]
    Field {
        /// The file.
        path: PathBuf,
        /// The field.
        field: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        expected: &'static str,
    },
    /// The calibration was learned for another cup estimator than the one used.
    #[error("{path}: estimator = {learned_for}: learned for that cup estimator, not {used}; learn one for {used} (acetab calibrate on studies made with it) or use --calibration none")]
    Estimator {
        /// The file.
        path: PathBuf,
        /// What it was learned for.
        learned_for: String,
        /// The estimator used.
        used: &'static str,
    },
    /// The training runs give a bias or an SD no calibration file may hold (`parse` would
    /// refuse it): their cup errors are not those of a method on acetabula.
    #[error("the training runs' cup errors give {field} = {value}, which must be {expected}: they are not errors of a cup on acetabula (the largest is {largest} mm); look for a broken study among them")]
    Learned {
        /// The learned field.
        field: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        expected: &'static str,
        /// The largest |cup error| among the runs.
        largest: String,
    },
    /// Too few runs to learn from.
    #[error("{runs} runs with a cup SD to learn from; at least {min} are needed")]
    TooFewRuns {
        /// How many.
        runs: usize,
        /// The least.
        min: usize,
    },
}

fn observed_part() -> String {
    CupEstimator::ObservedPart.name().to_string()
}

/// Fewest training runs a calibration is learned from.
pub const MIN_TRAINING_RUNS: usize = 20;

impl CupCalibration {
    /// No calibration: no model error, no bias, for `estimator`.
    pub fn none(estimator: CupEstimator) -> CupCalibration {
        CupCalibration {
            estimator: estimator.name().to_string(),
            bias_mm: 0.0,
            shrink: 0.0,
            shrink_to_mm: 0.0,
            depth_mm: 0.0,
            model_sd_mm: 0.0,
            learned_from: "none".into(),
            runs: 0,
            training_coverage: 0.0,
            views: None,
        }
    }

    /// The estimator it was learned for.
    pub fn cup_estimator(&self) -> Option<CupEstimator> {
        CupEstimator::parse(&self.estimator)
    }

    /// The calibration a run uses for a calibration choice and cup estimator: None, the
    /// `shipped` one; "none", no model error and no bias; anything else, the file at that path
    /// (`read`). A calibration learned for another estimator is refused (`path` names it).
    pub fn for_estimator(
        choice: Option<&str>,
        shipped: impl FnOnce() -> CupCalibration,
        estimator: CupEstimator,
    ) -> Result<CupCalibration, CalibrationError> {
        let (c, path) = match choice {
            None => (shipped(), PathBuf::from("the shipped calibration")),
            Some("none") => return Ok(Self::none(estimator)),
            Some(path) => (Self::read(Path::new(path))?, PathBuf::from(path)),
        };
        if c.cup_estimator() != Some(estimator) {
            return Err(CalibrationError::Estimator {
                path,
                learned_for: c.estimator,
                used: estimator.name(),
            });
        }
        Ok(c)
    }

    /// Read and check a calibration file.
    pub fn read(path: &Path) -> Result<CupCalibration, CalibrationError> {
        let text = std::fs::read_to_string(path).map_err(|source| CalibrationError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parse and check calibration JSON (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<CupCalibration, CalibrationError> {
        let c: CupCalibration =
            crate::io::parse_json(text).map_err(|reason| CalibrationError::Parse {
                path: path.to_path_buf(),
                reason,
            })?;
        if c.cup_estimator().is_none() {
            return Err(CalibrationError::Field {
                path: path.to_path_buf(),
                field: "estimator",
                value: c.estimator.clone(),
                expected: "a cup estimator (observed-part or prior-region)",
            });
        }
        if let Some(views) = &c.views {
            let bad = views.iter().find(|v| v.parse::<ViewRotation>().is_err());
            if views.is_empty() || bad.is_some() {
                return Err(CalibrationError::Field {
                    path: path.to_path_buf(),
                    field: "views",
                    value: crate::io::shown(&format!("{views:?}")),
                    expected: "a list of views, each AXIS:DEGREES turns of the antero-posterior view (\"z:20\", \"z:20+x:-15\")",
                });
            }
        }
        if let Some((field, value, expected)) = c.unusable() {
            return Err(CalibrationError::Field {
                path: path.to_path_buf(),
                field,
                value: crate::io::shown(&value.to_string()),
                expected,
            });
        }
        Ok(c)
    }

    /// The first number a calibration cannot be used with (field, value, what it must be): a
    /// bias beyond +-10 mm, a model SD outside 0-20 mm, a coverage that is not a share, fewer
    /// training runs than any calibration is learned from (`learn` refuses them: a file that
    /// says so was not learned).
    fn unusable(&self) -> Option<(&'static str, f64, &'static str)> {
        if let Some(bad) = self.correcting(CupParams::default()).invalid_correction() {
            return Some(bad);
        }
        if self.runs < MIN_TRAINING_RUNS {
            return Some((
                "runs",
                self.runs as f64,
                "at least 20 training runs (the fewest a calibration is learned from)",
            ));
        }
        if !(self.model_sd_mm.is_finite() && (0.0..=20.0).contains(&self.model_sd_mm)) {
            return Some(("model_sd_mm", self.model_sd_mm, "finite, 0 to 20 mm"));
        }
        if !(self.training_coverage.is_finite() && (0.0..=1.0).contains(&self.training_coverage)) {
            return Some((
                "training_coverage",
                self.training_coverage,
                "a share, 0 to 1",
            ));
        }
        None
    }

    /// `cup` with this calibration's bias, shrink and depth offset.
    pub fn correcting(&self, cup: CupParams) -> CupParams {
        CupParams {
            bias_mm: self.bias_mm,
            shrink: self.shrink,
            shrink_to_mm: self.shrink_to_mm,
            depth_mm: self.depth_mm,
            ..cup
        }
    }

    /// This calibration as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
    }
}
