//! Learning a calibration from training runs (`CupCalibration::learn`): the cup's bias and
//! shrink, its model-error SD and the result's depth offset, every source of truths weighing the
//! same.

use super::{CalibrationError, CupCalibration, MIN_TRAINING_RUNS, NOMINAL_COVERAGE};
use crate::pipeline::params::{CupEstimator, CupParams, MAX_SHRINK};

/// One training run of a calibration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainingRun {
    /// The estimator's diameter before any bias or shrink, mm.
    pub fitted_mm: f64,
    /// The truth's cup diameter, mm.
    pub truth_mm: f64,
    /// The resampled SD of the diameter (without any model error), mm.
    pub resample_sd_mm: f64,
    /// The result's translation to the truth along its depth axis, before any depth offset, mm
    /// (runs.csv's `depth_offset_mm`); NaN where the run does not record it.
    pub depth_offset_mm: f64,
    /// Which source of truths the run's acetabulum came from (a population: runs of each source
    /// weigh the same in the bias and the shrink).
    pub source: usize,
}

/// What a calibration learns besides the model-error SD.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Learn {
    /// Only the model-error SD (no bias, no shrink).
    SdOnly,
    /// The bias too.
    Bias,
    /// The bias and the shrink.
    BiasAndShrink,
}

impl CupCalibration {
    /// Learn the calibration of `estimator` from training runs (`TrainingRun`: what the
    /// estimator fitted, before any correction, and the truth). With `Learn::Bias` the bias is
    /// the runs' mean error; with `Learn::BiasAndShrink` also the shrink: one minus the slope of
    /// the least-squares line from fitted diameter to truth (kept within 0 to `MAX_SHRINK`),
    /// about the runs' mean fitted diameter (`shrink_to_mm`). In both, every source of truths
    /// weighs the same, however many runs it holds, so that the largest collection of
    /// acetabula does not set the correction for the others. The model-error SD is then the
    /// smallest s >= 0 with at least `NOMINAL_COVERAGE` of the runs' corrected errors within
    /// sqrt(sd^2 + s^2), sd the resampled SD as the correction scales it. Runs with a non-finite
    /// member are skipped. The depth offset is learned too, whatever `what` asks of the cup, from
    /// every run that records it (`depth_offset`).
    pub fn learn(
        runs: &[TrainingRun],
        estimator: CupEstimator,
        what: Learn,
        learned_from: String,
    ) -> Result<Self, CalibrationError> {
        let depth_mm = depth_offset(runs);
        let runs: Vec<TrainingRun> = runs
            .iter()
            .copied()
            .filter(|r| {
                r.fitted_mm.is_finite()
                    && r.truth_mm.is_finite()
                    && r.resample_sd_mm.is_finite()
                    && r.resample_sd_mm >= 0.0
            })
            .collect();
        if runs.len() < MIN_TRAINING_RUNS {
            return Err(CalibrationError::TooFewRuns {
                runs: runs.len(),
                min: MIN_TRAINING_RUNS,
            });
        }
        let correction = correction_of(&runs, what);
        let shrink = correction.shrink;
        // (corrected error, resampled SD as the correction scales it)
        let pairs: Vec<(f64, f64)> = runs
            .iter()
            .map(|r| {
                (
                    correction.corrected(r.fitted_mm) - r.truth_mm,
                    (1.0 - shrink) * r.resample_sd_mm,
                )
            })
            .collect();
        let (s, covered) = model_sd(&pairs);
        let learned = CupCalibration {
            estimator: estimator.name().to_string(),
            bias_mm: correction.bias_mm,
            shrink,
            shrink_to_mm: correction.shrink_to_mm,
            depth_mm,
            model_sd_mm: s,
            learned_from,
            runs: pairs.len(),
            training_coverage: covered as f64 / pairs.len() as f64,
            // The runs do not say; the caller who read their studies does.
            views: None,
        };
        // Never write a file that reading it back would refuse.
        match learned.unusable() {
            None => Ok(learned),
            Some((field, value, expected)) => {
                let largest = runs
                    .iter()
                    .map(|r| (r.fitted_mm - r.truth_mm).abs())
                    .fold(0.0, f64::max);
                Err(CalibrationError::Learned {
                    field,
                    value: crate::io::shown(&value.to_string()),
                    expected,
                    largest: crate::io::shown(&format!("{largest:.1}")),
                })
            }
        }
    }
}

/// The correction `what` asks for, learned from `runs` (each source of truths weighing the same,
/// `source_weights`): none, the mean error as a bias, or a bias and a shrink toward the mean
/// fitted cup (one less the regression slope of the truth on the fitted cup, at most
/// `MAX_SHRINK`).
fn correction_of(runs: &[TrainingRun], what: Learn) -> CupParams {
    let weight = source_weights(runs);
    let mean = |f: &dyn Fn(&TrainingRun) -> f64| runs.iter().map(|r| weight(r) * f(r)).sum::<f64>();
    let (bias_mm, shrink, shrink_to_mm) = match what {
        Learn::SdOnly => (0.0, 0.0, 0.0),
        Learn::Bias => (mean(&|r| r.fitted_mm - r.truth_mm), 0.0, 0.0),
        Learn::BiasAndShrink => {
            let (mf, mt) = (mean(&|r| r.fitted_mm), mean(&|r| r.truth_mm));
            let var = mean(&|r| (r.fitted_mm - mf).powi(2));
            let cov = mean(&|r| (r.fitted_mm - mf) * (r.truth_mm - mt));
            let shrink = if var > 0.0 {
                (1.0 - cov / var).clamp(0.0, MAX_SHRINK)
            } else {
                0.0
            };
            (mean(&|r| r.fitted_mm - r.truth_mm), shrink, mf)
        }
    };
    CupParams {
        bias_mm,
        shrink,
        shrink_to_mm,
        ..Default::default()
    }
}

/// The smallest model-error SD s >= 0 with at least `NOMINAL_COVERAGE` of the (corrected error,
/// resampled SD) `pairs` within sqrt(sd^2 + s^2), and how many pairs it covers (`pairs` not
/// empty).
fn model_sd(pairs: &[(f64, f64)]) -> (f64, usize) {
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
    (s, covered)
}

/// The training runs' mean depth offset (`TrainingRun::depth_offset_mm`), every source of
/// truths weighing the same as in the bias; 0 where fewer than `MIN_TRAINING_RUNS` record it
/// (studies from before the column), since an offset learned from a few runs would move every
/// result by their chance.
pub fn depth_offset(runs: &[TrainingRun]) -> f64 {
    let with: Vec<&TrainingRun> = runs
        .iter()
        .filter(|r| r.depth_offset_mm.is_finite())
        .collect();
    if with.len() < MIN_TRAINING_RUNS {
        return 0.0;
    }
    let weight = source_weights(with.iter().copied());
    with.iter().map(|r| weight(r) * r.depth_offset_mm).sum()
}

/// Each run's weight in a mean over `runs` where every source of truths weighs the same: one
/// unit per source, shared by its runs.
fn source_weights<'a>(
    runs: impl IntoIterator<Item = &'a TrainingRun>,
) -> impl Fn(&TrainingRun) -> f64 {
    let mut per_source = std::collections::BTreeMap::<usize, usize>::new();
    for r in runs {
        *per_source.entry(r.source).or_default() += 1;
    }
    let sources = per_source.len() as f64;
    move |r: &TrainingRun| 1.0 / (sources * per_source[&r.source] as f64)
}
