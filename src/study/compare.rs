//! Our method against the better baseline on each mesh and level, run by run: the methods see
//! the same simulated case in a run, so the runs pair, and the mean difference in MAE gets a 95 %
//! interval (paired t). With it a sweep says where the method is worse than `TOLERANCE` times the
//! baseline beyond the runs' spread, where it is not, and where its runs cannot tell: with three
//! runs a mesh the means alone differ by more than 5 % between two seeds of the same method on a
//! fifth of the shared acetabula (docs/population.md).

use super::method::StudyMethod;
use super::Row;
use serde::Serialize;

/// The tolerance the method is held to: its MAE at most this times the better baseline's.
pub const TOLERANCE: f64 = 1.05;

/// What the paired runs say about the method against `TOLERANCE` times the baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// Worse than the tolerance allows, beyond the runs' spread (the whole interval above).
    Worse,
    /// Within the tolerance, beyond the runs' spread (the whole interval below).
    NotWorse,
    /// The interval straddles the tolerance (or fewer than two pairs): more runs would tell.
    Undecided,
}

impl Verdict {
    /// In words, for a line about one comparison.
    pub fn describe(self) -> String {
        match self {
            Verdict::Worse => format!("worse than {TOLERANCE}x the baseline"),
            Verdict::NotWorse => format!("within {TOLERANCE}x the baseline"),
            Verdict::Undecided => "undecided with these runs".into(),
        }
    }
}

/// One mesh and level: a method against its better baseline over the runs both finished.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Comparison {
    /// The mesh's name.
    pub mesh: String,
    /// The start's noise level.
    pub level: u32,
    /// The method (srvf, or srvf-paper against the paper's baselines).
    pub method: StudyMethod,
    /// The baseline with the lower mean MAE over the pairs.
    pub baseline: StudyMethod,
    /// Runs both finished.
    pub pairs: usize,
    /// The method's mean MAE over the pairs, mm.
    pub method_mae: f64,
    /// The baseline's, mm.
    pub baseline_mae: f64,
    /// method_mae / baseline_mae.
    pub ratio: f64,
    /// Mean of the method's MAE minus the baseline's, run by run, mm.
    pub difference_mm: f64,
    /// Its 95 % interval (paired t; NaN with fewer than two pairs), mm.
    pub difference_ci95_mm: [f64; 2],
    /// Against `TOLERANCE`: from the interval of the mean of (method - TOLERANCE x baseline).
    pub verdict: Verdict,
}

/// The two-sided 95 % quantile of Student's t with `dof` degrees of freedom (t at 0.975):
/// tabulated to 30, the Cornish-Fisher expansion about the normal quantile above (within 2e-4
/// there). NaN for 0.
pub fn t975(dof: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.7062, 4.3027, 3.1824, 2.7764, 2.5706, 2.4469, 2.3646, 2.3060, 2.2622, 2.2281, 2.2010,
        2.1788, 2.1604, 2.1448, 2.1314, 2.1199, 2.1098, 2.1009, 2.0930, 2.0860, 2.0796, 2.0739,
        2.0687, 2.0639, 2.0595, 2.0555, 2.0518, 2.0484, 2.0452, 2.0423,
    ];
    match dof {
        0 => f64::NAN,
        1..=30 => TABLE[dof - 1],
        _ => {
            let z = 1.959_963_984_540_054_f64;
            let v = dof as f64;
            z + (z.powi(3) + z) / (4.0 * v)
                + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * v * v)
        }
    }
}

/// Mean and 95 % half-width (paired t) of `d`; the half-width NaN with fewer than two values.
fn mean_ci(d: &[f64]) -> (f64, f64) {
    let n = d.len();
    let (mean, sd) = crate::geom::mean_sd(d, true);
    if n < 2 {
        return (mean, f64::NAN);
    }
    (mean, t975(n - 1) * sd / (n as f64).sqrt())
}

/// The baselines a method is held against: the nearest-point methods of the same protocol.
fn baselines_of(method: StudyMethod) -> Option<[StudyMethod; 2]> {
    match method {
        StudyMethod::Srvf => Some([StudyMethod::Icp, StudyMethod::IcpNormvec]),
        StudyMethod::SrvfPaper => Some([StudyMethod::IcpPaper, StudyMethod::IcpNormvecPaper]),
        _ => None,
    }
}

/// Each level's finished MAE of `method` in `rows`, by run number.
fn maes(rows: &[Row], method: StudyMethod, level: u32) -> Vec<(usize, f64)> {
    rows.iter()
        .filter(|r| r.method == method && r.level == level && r.error.is_empty())
        .map(|r| (r.run, r.mae_mm))
        .collect()
}

/// `method` against `baseline` at `level` over the runs both finished: (pairs of MAEs).
fn paired(rows: &[Row], method: StudyMethod, baseline: StudyMethod, level: u32) -> Vec<(f64, f64)> {
    let base = maes(rows, baseline, level);
    maes(rows, method, level)
        .into_iter()
        .filter_map(|(run, m)| base.iter().find(|(r, _)| *r == run).map(|&(_, b)| (m, b)))
        .collect()
}

/// The comparisons of one mesh's runs: for srvf (and srvf-paper), at each level, against
/// whichever of its two baselines has the lower mean MAE over the runs both finished. None
/// where the mesh has no run of a baseline.
pub fn compare(mesh: &str, rows: &[Row]) -> Vec<Comparison> {
    let mut levels: Vec<u32> = rows.iter().map(|r| r.level).collect();
    levels.sort_unstable();
    levels.dedup();
    let mut out = Vec::new();
    for method in [StudyMethod::Srvf, StudyMethod::SrvfPaper] {
        let Some(bases) = baselines_of(method) else {
            continue;
        };
        for &level in &levels {
            // Each baseline with its pairs and its mean MAE over them; the lower mean is held.
            let best = bases
                .into_iter()
                .map(|b| (b, paired(rows, method, b, level)))
                .filter(|(_, p)| !p.is_empty())
                .map(|(b, p)| {
                    let bm = crate::geom::mean(&p.iter().map(|q| q.1).collect::<Vec<f64>>());
                    (b, p, bm)
                })
                .min_by(|x, y| x.2.total_cmp(&y.2));
            let Some((baseline, pairs, bm)) = best else {
                continue;
            };
            let m: Vec<f64> = pairs.iter().map(|p| p.0).collect();
            let diff: Vec<f64> = pairs.iter().map(|p| p.0 - p.1).collect();
            let over: Vec<f64> = pairs.iter().map(|p| p.0 - TOLERANCE * p.1).collect();
            let (d, half) = mean_ci(&diff);
            let (o, ohalf) = mean_ci(&over);
            let verdict = if !ohalf.is_finite() {
                Verdict::Undecided
            } else if o - ohalf > 0.0 {
                Verdict::Worse
            } else if o + ohalf <= 0.0 {
                Verdict::NotWorse
            } else {
                Verdict::Undecided
            };
            let mm = crate::geom::mean(&m);
            out.push(Comparison {
                mesh: mesh.to_string(),
                level,
                method,
                baseline,
                pairs: pairs.len(),
                method_mae: mm,
                baseline_mae: bm,
                ratio: mm / bm,
                difference_mm: d,
                difference_ci95_mm: [d - half, d + half],
                verdict,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::Task;

    /// Student's t CDF at x for `dof` degrees of freedom, by Simpson's rule on the density.
    fn t_cdf(x: f64, dof: usize) -> f64 {
        let v = dof as f64;
        let c = (libm::lgamma((v + 1.0) / 2.0) - libm::lgamma(v / 2.0)).exp()
            / (v * std::f64::consts::PI).sqrt();
        let f = |t: f64| c * (1.0 + t * t / v).powf(-(v + 1.0) / 2.0);
        let n = 20_000;
        let h = x / n as f64;
        let mut s = f(0.0) + f(x);
        for i in 1..n {
            s += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        0.5 + s * h / 3.0
    }

    #[test]
    fn the_t_quantiles_leave_two_and_a_half_per_cent_above() {
        for dof in [1, 2, 3, 5, 10, 29, 30, 31, 60, 200] {
            let p = t_cdf(t975(dof), dof);
            assert!((p - 0.975).abs() < 2e-4, "dof {dof}: cdf {p}");
        }
        assert!(t975(0).is_nan());
        // Companion: the normal quantile is not t's at 2 degrees of freedom.
        let wrong = t_cdf(1.96, 2);
        assert!((wrong - 0.975).abs() > 0.02, "{wrong}");
    }

    fn row(method: StudyMethod, level: u32, run: usize, mae: f64) -> Row {
        let t = Task {
            method,
            level,
            run,
            seed: run as u64,
        };
        Row {
            mae_mm: mae,
            error: String::new(),
            ..Row::failed(&t, "")
        }
    }

    fn rows(level: u32, srvf: &[f64], icp: &[f64], normvec: &[f64]) -> Vec<Row> {
        let mut out = Vec::new();
        for (m, v) in [
            (StudyMethod::Srvf, srvf),
            (StudyMethod::Icp, icp),
            (StudyMethod::IcpNormvec, normvec),
        ] {
            out.extend(v.iter().enumerate().map(|(i, &x)| row(m, level, i, x)));
        }
        out
    }

    #[test]
    fn a_paired_comparison_tells_worse_from_not_worse_from_undecided() {
        // 1.08x the better baseline (icp-normvec) in every run, the runs spread alike: worse.
        let c = compare(
            "m",
            &rows(
                5,
                &[0.864, 0.972, 0.756],
                &[1.0, 1.1, 1.2],
                &[0.8, 0.9, 0.7],
            ),
        );
        assert_eq!(c.len(), 1);
        let c = &c[0];
        assert_eq!(
            (c.baseline, c.pairs, c.verdict),
            (StudyMethod::IcpNormvec, 3, Verdict::Worse)
        );
        assert!((c.ratio - 1.08).abs() < 1e-12);
        // The interval by hand: differences 0.064, 0.072, 0.056, mean 0.064, SD 0.008.
        let half = 4.3027 * 0.008 / 3f64.sqrt();
        assert!((c.difference_mm - 0.064).abs() < 1e-12);
        assert!((c.difference_ci95_mm[0] - (0.064 - half)).abs() < 1e-12);
        assert!((c.difference_ci95_mm[1] - (0.064 + half)).abs() < 1e-12);
        // Companion: 1.02x the baseline in every run is within the tolerance.
        let c = compare(
            "m",
            &rows(
                5,
                &[0.816, 0.918, 0.714],
                &[1.0, 1.1, 1.2],
                &[0.8, 0.9, 0.7],
            ),
        );
        assert_eq!(c[0].verdict, Verdict::NotWorse);
        // 1.08x on average but one run far better, one far worse: the runs cannot tell.
        let c = compare(
            "m",
            &rows(5, &[1.3, 0.6, 0.692], &[1.0, 1.1, 1.2], &[0.8, 0.9, 0.7]),
        );
        assert!((c[0].ratio - 1.08).abs() < 1e-9);
        assert_eq!(c[0].verdict, Verdict::Undecided);
    }

    #[test]
    fn only_runs_both_methods_finished_pair_and_one_pair_decides_nothing() {
        let mut r = rows(3, &[0.9, 0.9, 0.9], &[0.5, 0.5, 0.5], &[]);
        // The baseline failed runs 1 and 2: one pair left.
        for x in r
            .iter_mut()
            .filter(|x| x.method == StudyMethod::Icp && x.run > 0)
        {
            x.error = "boom".into();
        }
        let c = compare("m", &r);
        assert_eq!((c[0].pairs, c[0].baseline), (1, StudyMethod::Icp));
        assert_eq!(c[0].verdict, Verdict::Undecided);
        assert!(c[0].difference_ci95_mm[0].is_nan());
        // Companion: with all three pairs the same runs are worse beyond doubt.
        let c = compare("m", &rows(3, &[0.9, 0.91, 0.9], &[0.5, 0.51, 0.5], &[]));
        assert_eq!((c[0].pairs, c[0].verdict), (3, Verdict::Worse));
        // No baseline at all: nothing to compare.
        assert!(compare("m", &rows(3, &[0.9], &[], &[])).is_empty());
    }
}
