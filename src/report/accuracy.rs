//! The accuracy of a reconstruction against its truth, as every study and demo measures it.

use super::{error_colors, surface_distance, surface_samples, DistanceStats};
use crate::geom::Mesh;
use crate::io::{write_ply_with, MeshIoError};
use serde::Serialize;
use std::path::Path;

/// Accuracy of a reconstruction against the truth. `mae_mm` is the untrimmed mean distance from
/// points spread evenly over the truth (20,000, seed 0) to the reconstructed surface (closest
/// point on its triangles); `sd_mm`, `p95_mm` its SD and 95th percentile.
#[derive(Clone, Debug, Serialize)]
pub struct Accuracy {
    /// Mean distance, mm.
    pub mae_mm: f64,
    /// SD of the distances, mm.
    pub sd_mm: f64,
    /// 95th percentile, mm.
    pub p95_mm: f64,
    /// Largest distance, mm.
    pub max_mm: f64,
}

/// Truth -> reconstruction distances.
pub fn accuracy(truth: &Mesh, recon: &Mesh) -> Accuracy {
    accuracy_from(&accuracy_samples(truth), recon)
}

/// The points on the truth that `accuracy` measures from (20,000, evenly spread, seed 0).
pub fn accuracy_samples(truth: &Mesh) -> Vec<nalgebra::Point3<f64>> {
    surface_samples(truth, 20_000, 0)
}

/// `accuracy` from samples drawn once by `accuracy_samples`.
pub fn accuracy_from(samples: &[nalgebra::Point3<f64>], recon: &Mesh) -> Accuracy {
    accuracy_of(&surface_distance(samples, recon))
}

/// `accuracy_from` and `shifted_accuracy` together, on one closest-point structure of `recon`
/// (what a study measures of every run).
pub fn accuracy_and_shift(samples: &[nalgebra::Point3<f64>], recon: &Mesh) -> (Accuracy, Shifted) {
    match super::SurfaceQuery::new(recon) {
        Some(q) => {
            // The two measures side by side (on the caller's pool: a study's spare worker).
            let (d, shifted) = rayon::join(
                || samples.iter().map(|p| q.distance(p)).collect::<Vec<f64>>(),
                || shift_on(&q, samples),
            );
            (accuracy_of(&d), shifted)
        }
        None => (
            accuracy_of(&vec![f64::INFINITY; samples.len()]),
            Shifted::NONE,
        ),
    }
}

/// The statistics of truth -> reconstruction distances `d`.
fn accuracy_of(d: &[f64]) -> Accuracy {
    // No samples (a truth without area): nothing was measured, which is not an error of 0.
    if d.is_empty() {
        return Accuracy {
            mae_mm: f64::NAN,
            sd_mm: f64::NAN,
            p95_mm: f64::NAN,
            max_mm: f64::NAN,
        };
    }
    let s = DistanceStats::from(d);
    Accuracy {
        mae_mm: s.mean,
        sd_mm: s.sd,
        p95_mm: s.p95,
        max_mm: s.max,
    }
}

/// `accuracy_from` with the reconstruction's position taken out: the translation that brings it
/// nearest the truth and the mean distance after it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shifted {
    /// The translation (x, y, z in the frame of the samples), mm: the reconstruction moved by
    /// it lies nearest the truth, so it points from where the result lies towards where it
    /// should. Its length is `shift_mm()`.
    pub shift: [f64; 3],
    /// Mean distance from the samples to the reconstruction moved by it, mm.
    pub mae_mm: f64,
}

impl Shifted {
    /// Length of the translation, mm (NaN where there is none).
    pub fn shift_mm(&self) -> f64 {
        nalgebra::Vector3::from(self.shift).norm()
    }

    /// What a reconstruction the closest-point queries cannot take gives.
    const NONE: Shifted = Shifted {
        shift: [f64::NAN; 3],
        mae_mm: f64::NAN,
    };
}

/// Every how many of the samples the translation is fitted to.
const SHIFT_SAMPLE_STEP: usize = 20;
/// Rounds of the fit at most, and the move below which it stops, mm.
const SHIFT_ROUNDS: usize = 50;
/// See `SHIFT_ROUNDS`.
const SHIFT_TOL_MM: f64 = 1e-3;

/// The frame error taken out of `accuracy_from`: the translation t of `recon` that minimises the
/// mean squared distance from the truth's `samples` (every `SHIFT_SAMPLE_STEP`-th) to it,
/// found from no shift by moving it, round after round, by the samples' mean offset from their
/// closest points (translation-only ICP), and the mean distance from every sample to the
/// reconstruction so moved. A result displaced as a whole, as views with uncertain poses leave
/// it along their depth, keeps its shape error and sheds the displacement. NaN for a mesh the
/// closest-point queries cannot take.
pub fn shifted_accuracy(samples: &[nalgebra::Point3<f64>], recon: &Mesh) -> Shifted {
    super::SurfaceQuery::new(recon).map_or(Shifted::NONE, |q| shift_on(&q, samples))
}

/// `shifted_accuracy` on the closest-point structure `q` of the reconstruction.
fn shift_on(q: &super::SurfaceQuery, samples: &[nalgebra::Point3<f64>]) -> Shifted {
    let fit: Vec<&nalgebra::Point3<f64>> = samples.iter().step_by(SHIFT_SAMPLE_STEP).collect();
    if fit.is_empty() {
        return Shifted::NONE;
    }
    let mut t = nalgebra::Vector3::zeros();
    for _ in 0..SHIFT_ROUNDS {
        // On the reconstruction moved by t, p's closest point is the closest to p - t, plus t.
        let step = fit
            .iter()
            .map(|&p| p - (q.closest_point(&(p - t)) + t))
            .sum::<nalgebra::Vector3<f64>>()
            / fit.len() as f64;
        t += step;
        if !(step.norm() >= SHIFT_TOL_MM) {
            break;
        }
    }
    let d: Vec<f64> = samples.iter().map(|p| q.distance(&(p - t))).collect();
    Shifted {
        shift: [t.x, t.y, t.z],
        mae_mm: DistanceStats::from(&d).mean,
    }
}

/// Per vertex of `recon`, its distance to the truth's surface, mm; NaN where no truth surface lies
/// under the vertex (its closest truth point is on the truth's border: parts the truth does not
/// cover), rather than the distance to the truth's edge.
pub fn vertex_errors(recon: &Mesh, truth: &Mesh) -> Vec<f64> {
    match super::InteriorQuery::new(truth) {
        Some(q) => q.per_vertex(recon),
        None => surface_distance(&recon.vertices, truth),
    }
}

/// Write the reconstruction as a PLY coloured by its distance to the truth (blue 0 mm to red
/// 3 mm, grey where NaN) with the distance itself as the vertex property `error_mm`
/// (`vertex_errors`).
pub fn write_error_ply(recon: &Mesh, truth: &Mesh, path: &Path) -> Result<(), MeshIoError> {
    write_errors_ply(recon, &vertex_errors(recon, truth), path)
}

/// As `write_error_ply`, with the errors already measured (one per vertex).
pub fn write_errors_ply(recon: &Mesh, errors: &[f64], path: &Path) -> Result<(), MeshIoError> {
    write_ply_with(
        recon,
        Some(&error_colors(errors, 3.0)),
        Some(("error_mm", errors)),
        path,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::template::spherical_cap;

    /// A truth with nothing to sample measured no error, which is not an error of 0 (it read
    /// 0); companion: a surface against itself reads 0.
    #[test]
    fn nothing_measured_is_not_an_error_of_zero() {
        let cap = spherical_cap(25.0, 500, 60f64.to_radians());
        assert!(accuracy(&cap, &cap).mae_mm < 1e-9);
        let empty = Mesh {
            vertices: Vec::new(),
            triangles: Vec::new(),
            normals: Vec::new(),
        };
        assert!(accuracy(&empty, &cap).mae_mm.is_nan());
    }

    #[test]
    fn the_error_ply_maps_the_covered_part_and_greys_what_the_truth_lacks() {
        // The truth: a 60-degree cap; the result: a 90-degree cap of the same sphere, 0.5 mm
        // larger. Under the truth the error is 0.5 mm; beyond its rim there is no truth.
        let truth = spherical_cap(25.0, 2000, 60f64.to_radians());
        let recon = spherical_cap(25.5, 2000, 90f64.to_radians());
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("e.ply");
        write_error_ply(&recon, &truth, &p).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.contains("property float error_mm"));
        let body: Vec<&str> = text
            .split("end_header\n")
            .nth(1)
            .unwrap()
            .lines()
            .take(recon.vertex_count())
            .collect();
        let err: Vec<f64> = body
            .iter()
            .map(|l| l.split_whitespace().nth(6).unwrap().parse::<f64>().unwrap())
            .collect();
        let covered: Vec<f64> = err.iter().copied().filter(|e| !e.is_nan()).collect();
        let uncovered = err.len() - covered.len();
        assert!(
            uncovered > err.len() / 5,
            "{uncovered} of {} grey",
            err.len()
        );
        let mean = covered.iter().sum::<f64>() / covered.len() as f64;
        assert!((mean - 0.5).abs() < 0.05, "mean covered error {mean}");
        // Companion: the old measure (distance to the truth, edge included) calls the uncovered
        // part an error of millimetres.
        let raw = crate::report::surface_distance(&recon.vertices, &truth);
        assert!(raw.iter().cloned().fold(0.0, f64::max) > 5.0);
    }

    /// A result moved as a whole sheds the move: its shifted MAE is the unmoved one's and the
    /// shift is the move. The companion: a result of another size keeps its error (a
    /// translation cannot make a sphere smaller), moved or not.
    #[test]
    fn the_shift_takes_out_a_displacement_and_not_a_wrong_size() {
        let truth = spherical_cap(25.0, 3000, 80f64.to_radians());
        let samples = accuracy_samples(&truth);
        let moved = |m: &Mesh, by: nalgebra::Vector3<f64>| {
            m.with_vertices(m.vertices.iter().map(|p| p + by).collect())
        };
        let by = nalgebra::Vector3::new(3.0, -2.0, 4.0);
        let shifted = moved(&truth, by);
        assert!(accuracy_from(&samples, &shifted).mae_mm > 2.0);
        let s = shifted_accuracy(&samples, &shifted);
        assert!(s.mae_mm < 0.05, "{s:?}");
        assert!((s.shift_mm() - by.norm()).abs() < 0.05, "{s:?}");
        // The translation brings the result back: minus the move, axis by axis (a sign or an
        // axis mixed up is off by 4-8 mm).
        let back = nalgebra::Vector3::from(s.shift) + by;
        assert!(back.norm() < 0.05, "{s:?}");
        // Companion: 10 % larger, then moved the same way.
        let larger = spherical_cap(27.5, 3000, 80f64.to_radians());
        let alone = shifted_accuracy(&samples, &larger);
        let both = shifted_accuracy(&samples, &moved(&larger, by));
        assert!(alone.mae_mm > 0.5, "{alone:?}");
        assert!(
            (both.mae_mm - alone.mae_mm).abs() < 0.05,
            "{both:?} {alone:?}"
        );
        assert!(alone.mae_mm <= accuracy_from(&samples, &larger).mae_mm + 1e-9);
    }
}
