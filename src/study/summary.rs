//! The per-method-and-level summary of a study's runs (summary.json's `summary`).

use super::method::StudyMethod;
use super::runs_csv::Row;
use serde::Serialize;
use std::collections::BTreeMap;

/// Per method and level.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    /// The method.
    pub method: StudyMethod,
    /// The start's noise level.
    pub level: u32,
    /// Runs.
    pub runs: usize,
    /// Runs whose last solve converged.
    pub converged: usize,
    /// Runs that failed.
    pub failed: usize,
    /// Runs whose result came from a fallback.
    pub fallbacks: usize,
    /// Runs that restarted, from tilted starts or the limb sphere (`Row::restart` not empty).
    pub restarted: usize,
    /// Restarted runs whose result came from another start than the given one (a tilted start
    /// or the limb sphere).
    pub restart_tilted: usize,
    /// Restarted runs by why (`Row::restart_cause`: "outlines", "folded", "guard-" and the
    /// guard); runs read from a runs.csv written before the cause was recorded are not counted.
    pub restart_causes: BTreeMap<String, usize>,
    /// Runs that fell back, by the guard the method's own result failed (`Row::fallback_guard`).
    pub fallback_guards: BTreeMap<String, usize>,
    /// Mean MAE, mm.
    pub mae_mean: f64,
    /// SD of the MAE (dividing by n), mm.
    pub mae_sd: f64,
    /// Mean cup error, mm.
    pub cup_error_mean: f64,
    /// SD of the cup error, mm.
    pub cup_error_sd: f64,
    /// Runs with |cup diameter - truth| <= 1 mm.
    pub cup_within_1mm: usize,
    /// The same for the whole-surface sphere fit and for the limb sphere (None, null in JSON,
    /// when no run had a limb sphere: the paper's protocol and pose refinement skip stage 0).
    pub surface_fit_within_1mm: usize,
    /// See `surface_fit_within_1mm`.
    pub limb_within_1mm: Option<usize>,
    /// Runs with a cup SD (`Row::cup_sd_mm`), and of those, the share whose cup error is
    /// within it (68 % for a Gaussian that means what it says); None without resamples.
    pub cup_sd_runs: usize,
    /// See `cup_sd_runs`.
    pub cup_sd_coverage: Option<f64>,
    /// Mean Brier score of the size probabilities over those runs; None without resamples.
    pub brier_mean: Option<f64>,
    /// Median seconds per run.
    pub median_seconds: f64,
}

/// Mean and SD of the runs themselves (the SD divides by n).
fn mean_sd(v: &[f64]) -> (f64, f64) {
    crate::geom::mean_sd(v, false)
}

/// Runs whose `diameter` is within 1 mm of the truth's.
fn within(rows: &[&Row], diameter: impl Fn(&Row) -> f64) -> usize {
    rows.iter()
        .filter(|r| (diameter(r) - r.gt_cup_diameter_mm).abs() <= 1.0)
        .count()
}

/// How often each non-empty name occurs.
fn counts<'a>(names: impl Iterator<Item = &'a str>) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    for n in names.filter(|n| !n.is_empty()) {
        *out.entry(n.to_string()).or_insert(0) += 1;
    }
    out
}

/// Summaries in canonical order. Failed runs count in `runs` and `failed`, not in the means.
pub fn summarize(rows: &[Row]) -> Vec<Summary> {
    let mut keys: Vec<(StudyMethod, u32)> = rows.iter().map(|r| (r.method, r.level)).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .map(|(method, level)| {
            let g: Vec<&Row> = rows
                .iter()
                .filter(|r| r.method == method && r.level == level)
                .collect();
            let ok: Vec<&Row> = g
                .iter()
                .copied()
                .filter(|r| r.error.is_empty() && r.mae_mm.is_finite())
                .collect();
            let (mae_mean, mae_sd) = mean_sd(&ok.iter().map(|r| r.mae_mm).collect::<Vec<_>>());
            let ce: Vec<f64> = ok.iter().map(|r| r.cup_error_mm()).collect();
            let (cup_error_mean, cup_error_sd) = mean_sd(&ce);
            let with_sd: Vec<&Row> = ok
                .iter()
                .copied()
                .filter(|r| r.cup_sd_mm.is_finite() && r.brier.is_finite())
                .collect();
            let mut secs: Vec<f64> = g.iter().map(|r| r.seconds).collect();
            secs.sort_by(f64::total_cmp);
            Summary {
                method,
                level,
                runs: g.len(),
                converged: g.iter().filter(|r| r.converged).count(),
                failed: g.len() - ok.len(),
                fallbacks: g.iter().filter(|r| !r.fallback.is_empty()).count(),
                restarted: g.iter().filter(|r| !r.restart.is_empty()).count(),
                restart_tilted: g
                    .iter()
                    .filter(|r| !r.restart.is_empty() && r.restart != "given")
                    .count(),
                restart_causes: counts(g.iter().map(|r| r.restart_cause.as_str())),
                fallback_guards: counts(g.iter().map(|r| r.fallback_guard.as_str())),
                mae_mean,
                mae_sd,
                cup_error_mean,
                cup_error_sd,
                cup_within_1mm: ce.iter().filter(|e| e.abs() <= 1.0).count(),
                surface_fit_within_1mm: within(&ok, |r| r.surface_fit_diameter_mm),
                limb_within_1mm: ok
                    .iter()
                    .any(|r| r.limb_diameter_mm.is_finite())
                    .then(|| within(&ok, |r| r.limb_diameter_mm)),
                median_seconds: secs.get(secs.len() / 2).copied().unwrap_or(f64::NAN),
                cup_sd_runs: with_sd.len(),
                cup_sd_coverage: (!with_sd.is_empty()).then(|| {
                    with_sd
                        .iter()
                        .filter(|r| r.cup_error_mm().abs() <= r.cup_sd_mm)
                        .count() as f64
                        / with_sd.len() as f64
                }),
                brier_mean: (!with_sd.is_empty())
                    .then(|| with_sd.iter().map(|r| r.brier).sum::<f64>() / with_sd.len() as f64),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::runs_csv::test_row as row;
    use super::*;

    #[test]
    fn summary_counts_restarts_by_cause_and_fallbacks_by_guard() {
        let mut rows: Vec<Row> = (0..4).map(|k| row(StudyMethod::Srvf, 1, k, 0.8)).collect();
        for (r, cause) in rows.iter_mut().zip(["folded", "guard-rough", "folded"]) {
            r.restart = "+u".into();
            r.restart_cause = cause.into();
        }
        rows[3].fallback = "icp-normvec".into();
        rows[3].fallback_guard = "rough".into();
        let s = &summarize(&rows)[0];
        let map = |v: &[(&str, usize)]| -> BTreeMap<String, usize> {
            v.iter().map(|&(k, n)| (k.to_string(), n)).collect()
        };
        assert_eq!(s.restart_causes, map(&[("folded", 2), ("guard-rough", 1)]));
        assert_eq!(s.fallback_guards, map(&[("rough", 1)]));
        // Companion: a run with another cause is counted under it, not under the first's.
        rows[2].restart_cause = "outlines".into();
        let s = &summarize(&rows)[0];
        assert_ne!(s.restart_causes, map(&[("folded", 2), ("guard-rough", 1)]));
        assert_eq!(s.restart_causes["outlines"], 1);
    }

    #[test]
    fn summary_counts_the_runs_within_their_cup_sd_and_averages_brier() {
        // Cup errors +0.5 mm each (`row`); SDs 0.6, 0.4, 1.0 and one run without resamples.
        let mut rows: Vec<Row> = (0..4).map(|k| row(StudyMethod::Srvf, 1, k, 0.8)).collect();
        for (r, (sd, b)) in rows.iter_mut().zip([(0.6, 0.2), (0.4, 1.0), (1.0, 0.3)]) {
            r.cup_sd_mm = sd;
            r.brier = b;
        }
        let s = &summarize(&rows)[0];
        assert_eq!(s.cup_sd_runs, 3);
        assert!((s.cup_sd_coverage.unwrap() - 2.0 / 3.0).abs() < 1e-12);
        assert!((s.brier_mean.unwrap() - 0.5).abs() < 1e-12);
        // Companion: the same runs with every SD halved are counted as the misses they are.
        for r in rows.iter_mut().take(3) {
            r.cup_sd_mm *= 0.5;
        }
        let s = &summarize(&rows)[0];
        assert!((s.cup_sd_coverage.unwrap() - 1.0 / 3.0).abs() < 1e-12);
        // Without resamples there is nothing to cover.
        let plain = vec![row(StudyMethod::Srvf, 1, 0, 0.8)];
        let s = &summarize(&plain)[0];
        assert_eq!(
            (s.cup_sd_runs, s.cup_sd_coverage, s.brier_mean),
            (0, None, None)
        );
    }

    #[test]
    fn summary_counts_and_means() {
        let mut rows = vec![
            row(StudyMethod::Srvf, 2, 0, 0.4),
            row(StudyMethod::Srvf, 2, 1, 0.6),
            row(StudyMethod::Srvf, 2, 2, 9.0),
        ];
        rows[2].error = "failed".into();
        rows[2].converged = false;
        rows[1].cup_diameter_mm = 52.0;
        rows[0].limb_diameter_mm = 50.9;
        rows[1].limb_diameter_mm = 51.1;
        let s = summarize(&rows);
        assert_eq!(s.len(), 1);
        assert_eq!((s[0].runs, s[0].converged, s[0].failed), (3, 2, 1));
        assert!((s[0].mae_mean - 0.5).abs() < 1e-12 && (s[0].mae_sd - 0.1).abs() < 1e-12);
        assert_eq!(s[0].cup_within_1mm, 1);
        assert_eq!(
            (s[0].limb_within_1mm, s[0].surface_fit_within_1mm),
            (Some(1), 0)
        );
        rows[0].limb_diameter_mm = f64::NAN;
        rows[1].limb_diameter_mm = f64::NAN;
        assert_eq!(summarize(&rows)[0].limb_within_1mm, None);
    }
}
