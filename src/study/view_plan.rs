//! View planning: which set of X-ray views sizes the cup best. Each view set's population sweep
//! (the same acetabula, one `acetab simulate` sweep per set) is summarised per source of truths
//! and over all of them: the surface's MAE, the fitted cup's error, and the cup after a
//! correction learned leave-one-subject-out from the same set's runs (a subject's runs are
//! corrected by what the other subjects' runs of that set teach, with the rule `acetab calibrate`
//! learns by, so no acetabulum grades a correction it helped to learn). A correction belongs to
//! its views (the cup's bias differs from one set to the next), so each set learns its own.

use crate::pipeline::{CupCalibration, CupEstimator, CupParams, Learn, TrainingRun};
use crate::report::CupCatalogue;
use serde::Serialize;

/// One run of a view set's sweep, as its runs.csv and summary.json give it.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanRun {
    /// Index of the source of truths (the folder its mesh came from) in the caller's list.
    pub source: usize,
    /// The subject (both hips of one leave together).
    pub subject: String,
    /// The cup estimator's own diameter, before any correction, mm; `None` when the run failed.
    pub fitted_mm: Option<f64>,
    /// The truth's cup, mm.
    pub truth_mm: f64,
    /// The cup's resampled SD without any model error (0 when the study did not resample; NaN
    /// where it did and this run's resampling failed: the run then has no SD).
    pub resample_sd_mm: f64,
    /// The surface's mean absolute error, mm (of a run with a result).
    pub mae_mm: f64,
}

/// One view set on one source of truths (or on all of them, `source` "all").
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewSetRow {
    /// The views, as --views writes them.
    pub views: String,
    /// The source of truths, or "all".
    pub source: String,
    /// Runs.
    pub runs: usize,
    /// Runs with no result (they count as misses in every share below).
    pub failed: usize,
    /// Mean MAE of the runs with a result, mm.
    pub mae_mm: f64,
    /// The fitted cup's mean error, mm (runs with a result).
    pub fitted_bias_mm: f64,
    /// The fitted cup's RMS error, mm.
    pub fitted_rms_mm: f64,
    /// The corrected cup's mean error, mm.
    pub bias_mm: f64,
    /// The corrected cup's RMS error, mm.
    pub rms_mm: f64,
    /// Share of the runs whose corrected cup's nearest catalogue size is the truth's.
    pub exact_size: f64,
    /// Share of the runs whose corrected cup is within 1 mm of the truth's.
    pub within_1mm: f64,
    /// Share of the runs whose corrected cup's size is at most one catalogue step off.
    pub within_one_size: f64,
    /// Share of the runs with a result whose corrected cup is within the SD it would report
    /// (the resampled SD as the correction scales it and the model-error SD learned without
    /// the run's subject, in quadrature; 68 % nominal), where the sweep resampled every run.
    pub sd_coverage: Option<f64>,
}

/// What could not be planned.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PlanError {
    /// Every run of the set failed.
    #[error("views {views}: no run with a result")]
    NoResults {
        /// The view set.
        views: String,
    },
    /// A subject's correction could not be learned (too few runs left without it, say).
    #[error("views {views}: the correction for subject {subject} could not be learned from the runs of the {others} other subject(s): {reason}")]
    Learn {
        /// The view set.
        views: String,
        /// The subject left out.
        subject: String,
        /// How many subjects it would be learned from.
        others: usize,
        /// Why.
        reason: String,
    },
}

/// What each run of a view set is given, as a calibration learned without its subject would
/// give it: the correction of its cup and the model-error SD added to its resampled SD (None
/// where none could be learned).
#[derive(Clone, Debug, Default)]
struct Fix {
    cup: CupParams,
    model_sd_mm: Option<f64>,
}

/// The fix of each run of one view set: learned (`what`, and always the model-error SD) from
/// the set's runs of every other subject. `Learn::SdOnly` corrects nothing; where its SD cannot
/// be learned (too few runs) the runs get none, where a correction cannot be learned it is an
/// error.
fn corrections(
    views: &str,
    runs: &[PlanRun],
    estimator: CupEstimator,
    what: Learn,
) -> Result<Vec<Fix>, PlanError> {
    let mut subjects: Vec<&str> = runs.iter().map(|r| r.subject.as_str()).collect();
    subjects.sort_unstable();
    subjects.dedup();
    let others = subjects.len().saturating_sub(1);
    let mut learned: Vec<(&str, Fix)> = Vec::new();
    for s in subjects {
        let cup = CupParams {
            estimator,
            ..Default::default()
        };
        let train: Vec<TrainingRun> = runs
            .iter()
            .filter(|r| r.subject != s)
            .filter_map(|r| {
                r.fitted_mm.map(|f| TrainingRun {
                    fitted_mm: f,
                    truth_mm: r.truth_mm,
                    resample_sd_mm: r.resample_sd_mm,
                    source: r.source,
                    depth_offset_mm: f64::NAN,
                })
            })
            .collect();
        let fix = match CupCalibration::learn(&train, estimator, what, String::new()) {
            Ok(cal) => Fix {
                cup: cal.correcting(cup),
                model_sd_mm: Some(cal.model_sd_mm),
            },
            Err(_) if what == Learn::SdOnly => Fix {
                cup,
                model_sd_mm: None,
            },
            Err(e) => {
                return Err(PlanError::Learn {
                    views: views.to_string(),
                    subject: s.to_string(),
                    others,
                    reason: e.to_string(),
                })
            }
        };
        learned.push((s, fix));
    }
    Ok(runs
        .iter()
        .map(|r| {
            learned
                .iter()
                .find(|(s, _)| *s == r.subject)
                .map(|(_, f)| f.clone())
                .unwrap_or_default()
        })
        .collect())
}

/// A run with a result, as `plan_rows` tallies it: the run, its fitted and its corrected cup,
/// and the SD it would report (None where it did not resample or no model SD was learned).
type Tallied<'a> = (&'a PlanRun, f64, f64, Option<f64>);

/// The rows of one view set: one per source (named by `sources`, indexed by
/// `PlanRun::source`) that has runs, then "all".
pub fn plan_rows(
    views: &str,
    sources: &[String],
    runs: &[PlanRun],
    estimator: CupEstimator,
    what: Learn,
) -> Result<Vec<ViewSetRow>, PlanError> {
    if runs.iter().all(|r| r.fitted_mm.is_none()) {
        return Err(PlanError::NoResults {
            views: views.to_string(),
        });
    }
    let fixes = corrections(views, runs, estimator, what)?;
    let cat = CupCatalogue::default();
    let step = 2.0;
    let row = |source: &str, pick: &dyn Fn(&PlanRun) -> bool| -> ViewSetRow {
        let sel: Vec<(&PlanRun, &Fix)> = runs.iter().zip(&fixes).filter(|(r, _)| pick(r)).collect();
        // The runs with a result: fitted and corrected cups, and the SD each would report (its
        // resampled SD as the correction scales it and the model-error SD in quadrature; None
        // where it did not resample or no SD was learned).
        let ok: Vec<Tallied> = sel
            .iter()
            .filter_map(|(r, x)| {
                let sd = x
                    .model_sd_mm
                    .filter(|_| r.resample_sd_mm > 0.0)
                    .map(|m| ((1.0 - x.cup.shrink) * r.resample_sd_mm).hypot(m));
                r.fitted_mm.map(|f| (*r, f, x.cup.corrected(f), sd))
            })
            .collect();
        // Whether each is within its SD, over the runs that have one (none where the sweeps
        // did not resample; a run whose resampling failed has none).
        let covered: Vec<bool> = ok
            .iter()
            .filter_map(|(r, _, c, sd)| sd.map(|s| (c - r.truth_mm).abs() <= s))
            .collect();
        let n = sel.len() as f64;
        let k = ok.len().max(1) as f64;
        let mean = |f: &dyn Fn(&Tallied) -> f64| ok.iter().map(f).sum::<f64>() / k;
        let share =
            |f: &dyn Fn(&Tallied) -> bool| ok.iter().filter(|x| f(x)).count() as f64 / n.max(1.0);
        let size = |d: f64| cat.nearest(d).catalogue_mm;
        ViewSetRow {
            views: views.to_string(),
            source: source.to_string(),
            runs: sel.len(),
            failed: sel.len() - ok.len(),
            mae_mm: mean(&|(r, _, _, _)| r.mae_mm),
            fitted_bias_mm: mean(&|(r, f, _, _)| f - r.truth_mm),
            fitted_rms_mm: mean(&|(r, f, _, _)| (f - r.truth_mm).powi(2)).sqrt(),
            bias_mm: mean(&|(r, _, c, _)| c - r.truth_mm),
            rms_mm: mean(&|(r, _, c, _)| (c - r.truth_mm).powi(2)).sqrt(),
            exact_size: share(&|(r, _, c, _)| size(*c) == size(r.truth_mm)),
            within_1mm: share(&|(r, _, c, _)| (c - r.truth_mm).abs() <= 1.0),
            within_one_size: share(&|(r, _, c, _)| {
                (size(*c) - size(r.truth_mm)).abs() <= step + 1e-9
            }),
            sd_coverage: (!covered.is_empty())
                .then(|| covered.iter().filter(|&&b| b).count() as f64 / covered.len() as f64),
        }
    };
    let mut out = Vec::new();
    for (k, name) in sources.iter().enumerate() {
        if runs.iter().any(|r| r.source == k) {
            out.push(row(name, &|r| r.source == k));
        }
    }
    out.push(row("all", &|_| true));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs of `subjects` subjects, two hips each, three runs a hip: truth 50 + 2 * hip index,
    /// fitted = truth + `offset(subject)`.
    fn population(subjects: usize, offset: &dyn Fn(usize) -> f64) -> Vec<PlanRun> {
        let mut out = Vec::new();
        for s in 0..subjects {
            for hip in 0..2 {
                for run in 0..3 {
                    let truth = 50.0 + 2.0 * (2 * s + hip) as f64 * 0.37;
                    out.push(PlanRun {
                        source: s % 2,
                        subject: format!("s{s}"),
                        fitted_mm: Some(truth + offset(s) + 0.01 * run as f64),
                        truth_mm: truth,
                        resample_sd_mm: 0.0,
                        mae_mm: 0.5,
                    });
                }
            }
        }
        out
    }

    /// The rows of `runs` (two sources, a and b) under `what`.
    fn rows_of(runs: &[PlanRun], what: Learn) -> Result<Vec<ViewSetRow>, PlanError> {
        let src = ["a".to_string(), "b".to_string()];
        plan_rows("z:0", &src, runs, CupEstimator::ObservedPart, what)
    }

    fn all(rows: &[ViewSetRow]) -> &ViewSetRow {
        rows.iter().find(|r| r.source == "all").unwrap()
    }

    #[test]
    fn a_shared_bias_is_learned_from_the_other_subjects_and_removed() {
        // Every cup 1.5 mm too large: the learned bias takes it off, leave-one-subject-out.
        let runs = population(6, &|_| 1.5);
        let raw = rows_of(&runs, Learn::SdOnly).unwrap();
        let fixed = rows_of(&runs, Learn::Bias).unwrap();
        assert!((all(&raw).fitted_bias_mm - 1.51).abs() < 1e-9);
        assert!(
            (all(&raw).bias_mm - 1.51).abs() < 1e-9,
            "none: no correction"
        );
        assert!(all(&fixed).rms_mm < 0.02, "{:?}", all(&fixed));
        assert_eq!(all(&fixed).within_1mm, 1.0);
        assert!(all(&raw).within_1mm == 0.0);
        assert_eq!(raw.len(), 3, "two sources and all");
        assert_eq!(all(&fixed).runs, 36);
    }

    #[test]
    fn a_subject_never_learns_from_its_own_runs() {
        // One subject 6 mm off, the rest exact: left out, it learns (about) nothing and keeps
        // its error; had it been in its own training set, part of its error would be removed.
        let runs = population(6, &|s| if s == 0 { 6.0 } else { 0.0 });
        let rows = rows_of(&runs, Learn::Bias).unwrap();
        // Subject 0's runs keep their 6 mm; every other subject's bias is learned with
        // subject 0 in it, so it is well above zero.
        let fixes = corrections("z:0", &runs, CupEstimator::ObservedPart, Learn::Bias).unwrap();
        for (r, c) in runs.iter().zip(&fixes) {
            if r.subject == "s0" {
                assert!(
                    c.cup.bias_mm.abs() < 0.02,
                    "s0 learned from itself: {}",
                    c.cup.bias_mm
                );
            } else {
                assert!(
                    c.cup.bias_mm > 0.3,
                    "{} should see s0's error: {}",
                    r.subject,
                    c.cup.bias_mm
                );
            }
        }
        assert!(rows[0].rms_mm > 1.0);
    }

    #[test]
    fn the_companion_a_correction_learned_in_sample_is_told_apart() {
        // The wrong answer: learning from every run, s0 included, would pull s0's cups by its
        // share; the leave-one-out correction must differ from it.
        let runs = population(6, &|s| if s == 0 { 6.0 } else { 0.0 });
        let fixes = corrections("z:0", &runs, CupEstimator::ObservedPart, Learn::Bias).unwrap();
        let train: Vec<TrainingRun> = runs
            .iter()
            .map(|r| TrainingRun {
                fitted_mm: r.fitted_mm.unwrap(),
                truth_mm: r.truth_mm,
                resample_sd_mm: 0.0,
                source: r.source,
                depth_offset_mm: f64::NAN,
            })
            .collect();
        let in_sample = CupCalibration::learn(
            &train,
            CupEstimator::ObservedPart,
            Learn::Bias,
            String::new(),
        )
        .unwrap();
        assert!((fixes[0].cup.bias_mm - in_sample.bias_mm).abs() > 0.5);
    }

    #[test]
    fn a_run_whose_resampling_failed_is_left_out_of_the_sd_and_its_coverage() {
        // Every run resampled (SD 0.3 mm), one of s0's 5 mm off; its resampling failed (NaN):
        // the SDs learned and the coverage are those of the runs without it.
        let mut runs = population(6, &|_| 0.0);
        for r in &mut runs {
            r.resample_sd_mm = 0.3;
        }
        runs[0].fitted_mm = runs[0].fitted_mm.map(|f| f + 5.0);
        let coverage = |runs: &[PlanRun]| all(&rows_of(runs, Learn::SdOnly).unwrap()).sd_coverage;
        let mut failed = runs.clone();
        failed[0].resample_sd_mm = f64::NAN;
        let without = coverage(&runs[1..]);
        assert!(without.is_some());
        assert_eq!(coverage(&failed), without);
        // Companion: the same run with its SD is learned from and counted.
        assert_ne!(coverage(&runs), without);
    }

    #[test]
    fn failed_runs_count_as_misses_and_a_set_without_results_is_refused() {
        let mut runs = population(4, &|_| 0.0);
        for r in runs.iter_mut().take(6) {
            r.fitted_mm = None;
        }
        let rows = rows_of(&runs, Learn::SdOnly).unwrap();
        let a = all(&rows);
        assert_eq!((a.runs, a.failed), (24, 6));
        assert!((a.exact_size - 18.0 / 24.0).abs() < 1e-12);
        assert!((a.within_one_size - 18.0 / 24.0).abs() < 1e-12);
        for r in &mut runs {
            r.fitted_mm = None;
        }
        let err = rows_of(&runs, Learn::Bias);
        assert!(matches!(err, Err(PlanError::NoResults { .. })));
    }

    #[test]
    fn the_sd_coverage_is_that_of_a_model_sd_learned_without_the_subject() {
        // Errors spread evenly from -1.5 to +1.5 mm in every subject, resampled SD 0.2 mm: a
        // model SD learned on the others covers about 68 % of each subject's runs.
        let mut runs = population(8, &|_| 0.0);
        for (k, r) in runs.iter_mut().enumerate() {
            r.fitted_mm = Some(r.truth_mm - 1.5 + 3.0 * ((k * 7) % 48) as f64 / 47.0);
            r.resample_sd_mm = 0.2;
        }
        let cov = all(&rows_of(&runs, Learn::SdOnly).unwrap())
            .sd_coverage
            .unwrap();
        assert!((0.6..=0.76).contains(&cov), "{cov}");
        // The companion: a sweep that did not resample reports no coverage, and a subject
        // whose errors are four times the others' is covered far less than nominal.
        for r in &mut runs {
            r.resample_sd_mm = 0.0;
        }
        assert_eq!(
            all(&rows_of(&runs, Learn::SdOnly).unwrap()).sd_coverage,
            None
        );
        for r in &mut runs {
            r.resample_sd_mm = 0.2;
            if r.subject == "s0" {
                let e = r.fitted_mm.unwrap() - r.truth_mm;
                r.fitted_mm = Some(r.truth_mm + 4.0 * e);
            }
        }
        let rows = rows_of(&runs, Learn::SdOnly).unwrap();
        let s0: Vec<bool> = runs
            .iter()
            .zip(corrections("z:0", &runs, CupEstimator::ObservedPart, Learn::SdOnly).unwrap())
            .filter(|(r, _)| r.subject == "s0")
            .map(|(r, x)| {
                let e = r.fitted_mm.unwrap() - r.truth_mm;
                e.abs() <= 0.2f64.hypot(x.model_sd_mm.unwrap())
            })
            .collect();
        let s0_cov = s0.iter().filter(|&&c| c).count() as f64 / s0.len() as f64;
        assert!(s0_cov < 0.4, "{s0_cov}");
        assert!(rows[0].sd_coverage.unwrap() < cov, "{rows:?}");
    }

    #[test]
    fn one_subject_has_no_one_to_learn_from() {
        let runs: Vec<PlanRun> = population(1, &|_| 1.0);
        let err = rows_of(&runs, Learn::Bias).unwrap_err();
        assert!(
            err.to_string()
                .contains("subject s0 could not be learned from the runs of the 0 other"),
            "{err}"
        );
        // Uncorrected, one subject is enough.
        assert_eq!(all(&rows_of(&runs, Learn::SdOnly).unwrap()).runs, 6);
    }

    #[test]
    fn one_size_off_is_within_one_size_but_not_exact() {
        let mut runs = population(4, &|_| 0.0);
        for r in &mut runs {
            r.truth_mm = 50.0;
            r.fitted_mm = Some(52.1);
        }
        let rows = rows_of(&runs, Learn::SdOnly).unwrap();
        let a = all(&rows);
        assert_eq!(
            (a.exact_size, a.within_1mm, a.within_one_size),
            (0.0, 0.0, 1.0)
        );
        for r in &mut runs {
            r.fitted_mm = Some(54.1);
        }
        let rows = rows_of(&runs, Learn::SdOnly).unwrap();
        assert_eq!(all(&rows).within_one_size, 0.0, "two sizes off");
    }
}
