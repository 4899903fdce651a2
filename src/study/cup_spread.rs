//! Where a population's cup error lies, per method: its bias, SD and RMS over the runs with a
//! result, and the SD split into the spread of the acetabula's own mean errors (what each
//! acetabulum keeps from run to run: its shape against the views) and the runs' spread about
//! their acetabulum's mean (what changes from run to run: the annotation noise and the start).
//! A sweep writes it into population.json (`cup_spread`) and prints it.

use super::method::StudyMethod;
use super::runs_csv::{methods_in, per_mesh, Row};
use serde::Serialize;

/// One method's cup error over a population, mm (NaN, written null, where too few runs or
/// meshes leave it undefined).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CupSpread {
    /// The method.
    pub method: StudyMethod,
    /// Runs with a result and a finite cup error.
    pub runs: usize,
    /// Meshes with at least one such run.
    pub meshes: usize,
    /// Mean of cup minus truth.
    pub bias_mm: f64,
    /// SD of cup minus truth over the runs (n - 1).
    pub sd_mm: f64,
    /// Root mean square of cup minus truth.
    pub rms_mm: f64,
    /// SD of the meshes' mean errors (meshes - 1): the part each acetabulum keeps.
    pub per_acetabulum_sd_mm: f64,
    /// The runs' SD about their own mesh's mean error, pooled (runs - meshes degrees of
    /// freedom; levels together): the part that changes from run to run.
    pub run_to_run_sd_mm: f64,
}

/// Per method (in order), the cup error's spread over `meshes` (name, runs); failed runs and
/// runs without a finite cup error are left out.
pub fn cup_spread(meshes: &[(String, Vec<Row>)]) -> Vec<CupSpread> {
    methods_in(meshes)
        .into_iter()
        .map(|method| {
            let errors = per_mesh(meshes, method, |r| {
                Some(r.cup_error_mm()).filter(|e| e.is_finite())
            });
            spread(method, &errors)
        })
        .collect()
}

/// The spread of errors grouped by mesh (every group non-empty).
fn spread(method: StudyMethod, groups: &[Vec<f64>]) -> CupSpread {
    let all: Vec<f64> = groups.iter().flatten().copied().collect();
    let (n, k) = (all.len(), groups.len());
    let means: Vec<f64> = groups.iter().map(|e| crate::geom::mean(e)).collect();
    let within: f64 = groups
        .iter()
        .zip(&means)
        .flat_map(|(e, m)| e.iter().map(move |x| (x - m).powi(2)))
        .sum();
    CupSpread {
        method,
        runs: n,
        meshes: k,
        bias_mm: crate::geom::mean(&all),
        sd_mm: sample_sd(&all),
        rms_mm: crate::geom::mean(&all.iter().map(|e| e * e).collect::<Vec<f64>>()).sqrt(),
        per_acetabulum_sd_mm: sample_sd(&means),
        run_to_run_sd_mm: if n > k {
            (within / (n - k) as f64).sqrt()
        } else {
            f64::NAN
        },
    }
}

/// The SD with n - 1 degrees of freedom; NaN below two values.
fn sample_sd(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return f64::NAN;
    }
    crate::geom::mean_sd(v, true).1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::Task;

    fn run(method: StudyMethod, cup: f64, truth: f64) -> Row {
        let t = Task {
            method,
            level: 1,
            run: 0,
            seed: 1,
        };
        Row {
            mae_mm: 0.5,
            cup_diameter_mm: cup,
            gt_cup_diameter_mm: truth,
            error: String::new(),
            ..Row::failed(&t, "")
        }
    }

    #[test]
    fn the_cup_error_splits_into_what_each_acetabulum_keeps_and_what_runs_change() {
        // Mesh a: errors +1, +2, +3 (mean +2); mesh b: -1, -1 (mean -1); one failed srvf run
        // and one icp run are left out of srvf's figures.
        let a = vec![
            run(StudyMethod::Srvf, 51.0, 50.0),
            run(StudyMethod::Srvf, 52.0, 50.0),
            run(StudyMethod::Srvf, 48.0, 45.0),
            run(StudyMethod::Icp, 60.0, 50.0),
        ];
        let mut b = vec![
            run(StudyMethod::Srvf, 43.0, 44.0),
            run(StudyMethod::Srvf, 55.0, 56.0),
        ];
        b.push(Row::failed(
            &Task {
                method: StudyMethod::Srvf,
                level: 1,
                run: 2,
                seed: 3,
            },
            "boom",
        ));
        let s = cup_spread(&[("a".into(), a), ("b".into(), b)]);
        let srvf = s.iter().find(|c| c.method == StudyMethod::Srvf).unwrap();
        assert_eq!((srvf.runs, srvf.meshes), (5, 2));
        let close = |x: f64, y: f64| (x - y).abs() < 1e-12;
        // Errors 1, 2, 3, -1, -1: mean 0.8, sum of squares 16.
        assert!(close(srvf.bias_mm, 0.8));
        assert!(close(srvf.rms_mm, (16.0f64 / 5.0).sqrt()));
        assert!(close(srvf.sd_mm, ((16.0 - 5.0 * 0.64) / 4.0f64).sqrt()));
        // Means +2 and -1: SD sqrt(4.5); within: (1 + 0 + 1) + 0 over 5 - 2.
        assert!(close(srvf.per_acetabulum_sd_mm, 4.5f64.sqrt()));
        assert!(close(srvf.run_to_run_sd_mm, (2.0f64 / 3.0).sqrt()));
        let icp = s.iter().find(|c| c.method == StudyMethod::Icp).unwrap();
        assert_eq!((icp.runs, icp.meshes), (1, 1));
        assert!(close(icp.bias_mm, 10.0));
        assert!(icp.sd_mm.is_nan() && icp.per_acetabulum_sd_mm.is_nan());
        assert!(icp.run_to_run_sd_mm.is_nan());
    }

    #[test]
    fn errors_pooled_without_their_meshes_are_not_the_split() {
        // The same five errors, each run its own mesh: nothing is kept per acetabulum apart
        // from the runs, so the per-acetabulum SD is the whole SD and no run-to-run part is
        // defined. A split that ignored the grouping would read the same for both.
        let grouped = cup_spread(&[
            (
                "a".into(),
                vec![
                    run(StudyMethod::Srvf, 51.0, 50.0),
                    run(StudyMethod::Srvf, 52.0, 50.0),
                    run(StudyMethod::Srvf, 53.0, 50.0),
                ],
            ),
            (
                "b".into(),
                vec![
                    run(StudyMethod::Srvf, 49.0, 50.0),
                    run(StudyMethod::Srvf, 49.0, 50.0),
                ],
            ),
        ]);
        let single: Vec<(String, Vec<Row>)> = [51.0, 52.0, 53.0, 49.0, 49.0]
            .iter()
            .enumerate()
            .map(|(i, &c)| (format!("m{i}"), vec![run(StudyMethod::Srvf, c, 50.0)]))
            .collect();
        let single = cup_spread(&single);
        assert!((grouped[0].sd_mm - single[0].sd_mm).abs() < 1e-12);
        assert!((single[0].per_acetabulum_sd_mm - single[0].sd_mm).abs() < 1e-12);
        assert!(single[0].run_to_run_sd_mm.is_nan());
        assert!((grouped[0].per_acetabulum_sd_mm - single[0].per_acetabulum_sd_mm).abs() > 0.1);
    }
}
