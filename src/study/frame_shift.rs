//! Where a population's results lie as a whole: per method, the mean and RMS over the runs of
//! the translation that brings each result nearest its truth (runs.csv's `frame_shift_x_mm`,
//! `_y_mm`, `_z_mm`), axis by axis. A mean far from zero along one axis is a displacement every
//! acetabulum shares: with the paper's views, which all turn about the long axis z, the
//! results sit about 1 mm off along y, the direction none of them looks across
//! (docs/population.md, "Where the result sits, and the observation weight"), unless a
//! calibration's depth offset moves them back (`CupParams::depth_mm`; the mean of runs.csv's
//! `depth_offset_mm`, also kept here, is what it learns).

use super::runs_csv::{methods_in, per_mesh, Row};
use super::StudyMethod;
use serde::Serialize;

/// One method's translations to the truth over a population's runs.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct FrameShift {
    /// The method.
    pub method: StudyMethod,
    /// Runs with a result and all three components finite (a failed run, or one read from a
    /// runs.csv written before the components, is left out).
    pub runs: usize,
    /// Meshes with at least one such run.
    pub meshes: usize,
    /// Mean translation to the truth, x / y / z (body axes), mm; NaN without runs.
    pub mean_mm: [f64; 3],
    /// Its root mean square, x / y / z, mm; NaN without runs.
    pub rms_mm: [f64; 3],
    /// The mean translation to the truth along each result's depth axis, before any depth
    /// offset (runs.csv's `depth_offset_mm`, `pipeline::depth_axis`), mm: what a calibration
    /// learns as the offset; NaN where no run records it.
    pub depth_mean_mm: f64,
    /// Runs recording it.
    pub depth_runs: usize,
}

/// Per method (in order), the translations over `meshes` (name, runs).
pub fn frame_shifts(meshes: &[(String, Vec<Row>)]) -> Vec<FrameShift> {
    methods_in(meshes)
        .into_iter()
        .map(|method| {
            let shifts = per_mesh(meshes, method, |r| {
                let t = [r.frame_shift_x_mm, r.frame_shift_y_mm, r.frame_shift_z_mm];
                t.iter().all(|v| v.is_finite()).then_some(t)
            });
            let all: Vec<[f64; 3]> = shifts.iter().flatten().copied().collect();
            let depth: Vec<f64> = per_mesh(meshes, method, |r| {
                r.depth_offset_mm.is_finite().then_some(r.depth_offset_mm)
            })
            .into_iter()
            .flatten()
            .collect();
            let axis = |k: usize, f: fn(f64) -> f64| -> f64 {
                crate::geom::mean(&all.iter().map(|t| f(t[k])).collect::<Vec<f64>>())
            };
            FrameShift {
                method,
                runs: all.len(),
                meshes: shifts.len(),
                mean_mm: [0, 1, 2].map(|k| axis(k, |v| v)),
                rms_mm: [0, 1, 2].map(|k| axis(k, |v| v * v).sqrt()),
                depth_mean_mm: crate::geom::mean(&depth),
                depth_runs: depth.len(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::Task;

    /// A failed srvf run (level 1).
    fn failed(run: usize) -> Row {
        let task = Task {
            method: StudyMethod::Srvf,
            level: 1,
            run,
            seed: run as u64 + 1,
        };
        Row::failed(&task, "boom")
    }

    /// A run of `method` with a result whose translation to the truth is `t`.
    fn run(method: StudyMethod, t: [f64; 3]) -> Row {
        Row {
            method,
            mae_mm: 0.5,
            frame_shift_x_mm: t[0],
            frame_shift_y_mm: t[1],
            frame_shift_z_mm: t[2],
            error: String::new(),
            ..failed(0)
        }
    }

    #[test]
    fn the_mean_translation_is_taken_axis_by_axis_over_the_runs_with_one() {
        // srvf: (1, -2, 0) and (3, -2, 0) on mesh a, (-1, -2, 3) on mesh b; a failed run and a
        // run from an older runs.csv (NaN) are left out; icp apart.
        let mut older = run(StudyMethod::Srvf, [f64::NAN; 3]);
        older.mae_mm = 0.7;
        let mut a = vec![
            run(StudyMethod::Srvf, [1.0, -2.0, 0.0]),
            run(StudyMethod::Srvf, [3.0, -2.0, 0.0]),
            run(StudyMethod::Icp, [9.0, 9.0, 9.0]),
            older,
        ];
        a[0].depth_offset_mm = 0.5;
        a[1].depth_offset_mm = 1.5;
        let b = vec![run(StudyMethod::Srvf, [-1.0, -2.0, 3.0]), failed(1)];
        let s = frame_shifts(&[("a".into(), a), ("b".into(), b)]);
        let srvf = s.iter().find(|f| f.method == StudyMethod::Srvf).unwrap();
        assert_eq!((srvf.runs, srvf.meshes), (3, 2));
        let close = |x: f64, y: f64| (x - y).abs() < 1e-12;
        assert!(close(srvf.mean_mm[0], 1.0) && close(srvf.mean_mm[1], -2.0));
        assert!(close(srvf.mean_mm[2], 1.0));
        // RMS: sqrt((1 + 9 + 1) / 3), 2, sqrt(9 / 3).
        assert!(close(srvf.rms_mm[0], (11.0f64 / 3.0).sqrt()) && close(srvf.rms_mm[1], 2.0));
        assert!(close(srvf.rms_mm[2], 3.0f64.sqrt()));
        let icp = s.iter().find(|f| f.method == StudyMethod::Icp).unwrap();
        assert_eq!((icp.runs, icp.meshes), (1, 1));
        assert!(close(icp.mean_mm[1], 9.0));
        // The depth offset over the two runs recording it; none recorded for icp.
        assert_eq!(srvf.depth_runs, 2);
        assert!(close(srvf.depth_mean_mm, 1.0));
        assert!(icp.depth_runs == 0 && icp.depth_mean_mm.is_nan());
    }

    #[test]
    fn displacements_that_cancel_have_no_mean_but_keep_their_rms() {
        // Companion: results displaced +1 and -1 mm along y average to no displacement, which
        // the RMS still shows; a mean of the lengths (`frame_shift_mm`) would read 1 mm shared.
        let s = frame_shifts(&[(
            "a".into(),
            vec![
                run(StudyMethod::Srvf, [0.0, 1.0, 0.0]),
                run(StudyMethod::Srvf, [0.0, -1.0, 0.0]),
            ],
        )]);
        assert!(s[0].mean_mm[1].abs() < 1e-12, "{:?}", s[0]);
        assert!((s[0].rms_mm[1] - 1.0).abs() < 1e-12, "{:?}", s[0]);
        // Only failed runs: no runs, NaN figures.
        let none = frame_shifts(&[("a".into(), vec![failed(0)])]);
        assert_eq!((none[0].runs, none[0].meshes), (0, 0));
        assert!(none[0]
            .mean_mm
            .iter()
            .chain(&none[0].rms_mm)
            .all(|v| v.is_nan()));
    }
}
