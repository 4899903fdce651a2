//! The cup uncertainty's calibration: what the resampling cannot see. Resampling the contours
//! measures how much the cup moves with the annotation's noise; it cannot measure how far the
//! outlines' sphere is from the whole acetabulum's (the walls no view outlines), which differs
//! from patient to patient and dominates the error (docs/population.md: resampled SDs of
//! 0.1-0.3 mm against cup errors of about 1.2 mm RMS). That part is learned from studies on
//! acetabula whose cup is known: a model-error SD added in quadrature, chosen so that 68 % of
//! the training runs' errors lie within the total SD (`learn_model_sd`).

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The nominal coverage of +-1 SD.
pub const NOMINAL_COVERAGE: f64 = 0.6827;

/// A learned cup calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CupCalibration {
    /// Model-error SD of the cup diameter, mm, added in quadrature to the resampled SD.
    pub model_sd_mm: f64,
    /// What it was learned from (the studies' protocol, runs, meshes); free text for people.
    pub learned_from: String,
    /// Training runs.
    pub runs: usize,
    /// Share of the training runs within their total SD (about 0.68 by construction).
    pub training_coverage: f64,
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
    /// Too few runs to learn from.
    #[error("{runs} runs with a cup SD to learn from; at least {min} are needed")]
    TooFewRuns {
        /// How many.
        runs: usize,
        /// The least.
        min: usize,
    },
}

/// Fewest training runs a calibration is learned from.
pub const MIN_TRAINING_RUNS: usize = 20;

/// The calibration learned from the shared populations' ideal-protocol study (47 acetabula,
/// levels 1, 3, 5 x 3 runs, srvf, seed 7; see docs/population.md and the data's attribution in
/// README.md), shipped with the program: `acetab simulate` uses it for the ideal protocol.
pub const IDEAL_JSON: &str = include_str!("../../calibration/ideal.json");
/// The same for the realistic protocol: `acetab simulate --protocol realistic` and `acetab
/// reconstruct` (a patient's X-rays) use it.
pub const REALISTIC_JSON: &str = include_str!("../../calibration/realistic.json");

impl CupCalibration {
    /// The shipped calibration for studies under the ideal protocol.
    pub fn shipped_ideal() -> CupCalibration {
        Self::parse(IDEAL_JSON, Path::new("calibration/ideal.json"))
            .expect("the shipped calibration is valid (tested)")
    }

    /// The shipped calibration for the realistic protocol and patients' X-rays.
    pub fn shipped_realistic() -> CupCalibration {
        Self::parse(REALISTIC_JSON, Path::new("calibration/realistic.json"))
            .expect("the shipped calibration is valid (tested)")
    }

    /// The model-error SD a run uses for a calibration choice: None, the `shipped` one;
    /// "none", no model error (0); anything else, the file at that path (`read`).
    pub fn model_sd_for(
        choice: Option<&str>,
        shipped: fn() -> CupCalibration,
    ) -> Result<f64, CalibrationError> {
        match choice {
            None => Ok(shipped().model_sd_mm),
            Some("none") => Ok(0.0),
            Some(path) => Ok(Self::read(Path::new(path))?.model_sd_mm),
        }
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
            serde_json::from_str(text).map_err(|e| CalibrationError::Parse {
                path: path.to_path_buf(),
                reason: e.to_string(),
            })?;
        let field = |field, value: f64, expected| CalibrationError::Field {
            path: path.to_path_buf(),
            field,
            value: value.to_string(),
            expected,
        };
        if !(c.model_sd_mm.is_finite() && (0.0..=20.0).contains(&c.model_sd_mm)) {
            return Err(field("model_sd_mm", c.model_sd_mm, "finite, 0 to 20 mm"));
        }
        if !(c.training_coverage.is_finite() && (0.0..=1.0).contains(&c.training_coverage)) {
            return Err(field(
                "training_coverage",
                c.training_coverage,
                "a share, 0 to 1",
            ));
        }
        Ok(c)
    }

    /// Learn the model-error SD from training runs (cup error, resampled SD) pairs: the
    /// smallest s >= 0 with at least `NOMINAL_COVERAGE` of the runs' |error| <= sqrt(sd^2 +
    /// s^2). Pairs with a non-finite member are skipped.
    pub fn learn(pairs: &[(f64, f64)], learned_from: String) -> Result<Self, CalibrationError> {
        let pairs: Vec<(f64, f64)> = pairs
            .iter()
            .copied()
            .filter(|(e, sd)| e.is_finite() && sd.is_finite() && *sd >= 0.0)
            .collect();
        if pairs.len() < MIN_TRAINING_RUNS {
            return Err(CalibrationError::TooFewRuns {
                runs: pairs.len(),
                min: MIN_TRAINING_RUNS,
            });
        }
        // Each run is covered once s^2 >= e^2 - sd^2: the answer is that quantile.
        let mut need: Vec<f64> = pairs
            .iter()
            .map(|(e, sd)| (e * e - sd * sd).max(0.0))
            .collect();
        need.sort_by(f64::total_cmp);
        let k = ((NOMINAL_COVERAGE * need.len() as f64).ceil() as usize).clamp(1, need.len());
        let s = need[k - 1].sqrt();
        let covered = pairs
            .iter()
            .filter(|(e, sd)| e.abs() <= (sd * sd + s * s).sqrt() + 1e-12)
            .count();
        Ok(CupCalibration {
            model_sd_mm: s,
            learned_from,
            runs: pairs.len(),
            training_coverage: covered as f64 / pairs.len() as f64,
        })
    }

    /// This calibration as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_calibrations_parse() {
        for c in [
            CupCalibration::shipped_ideal(),
            CupCalibration::shipped_realistic(),
        ] {
            assert!(c.model_sd_mm > 0.0 && c.runs >= MIN_TRAINING_RUNS, "{c:?}");
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
        let c = CupCalibration::learn(&pairs, "test".into()).unwrap();
        let total = (c.model_sd_mm.powi(2) + 0.04).sqrt();
        assert!((total - 1.2).abs() < 0.08, "total SD {total}");
        assert!((c.training_coverage - NOMINAL_COVERAGE).abs() < 0.01);
        // Companion: the resampled SD alone covers far fewer, which a calibrated claim refuses.
        let alone = pairs.iter().filter(|(e, sd)| e.abs() <= *sd).count() as f64 / 2000.0;
        assert!((alone - NOMINAL_COVERAGE).abs() > 0.3, "{alone}");
        // Too few runs, or none finite, are refused.
        assert!(matches!(
            CupCalibration::learn(&pairs[..5], String::new()),
            Err(CalibrationError::TooFewRuns { runs: 5, .. })
        ));
        let nan = vec![(f64::NAN, 0.2); 50];
        assert!(CupCalibration::learn(&nan, String::new()).is_err());
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
    }
}
