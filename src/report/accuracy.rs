//! The accuracy of a reconstruction against its truth, as every study and demo measures it.

use super::{error_colors, surface_distance, surface_samples, DistanceStats};
use crate::geom::Mesh;
use crate::io::{write_ply, MeshIoError};
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
    let s = DistanceStats::from(&surface_distance(samples, recon));
    Accuracy {
        mae_mm: s.mean,
        sd_mm: s.sd,
        p95_mm: s.p95,
        max_mm: s.max,
    }
}

/// Write the reconstruction as a PLY coloured by its distance to the truth (0..3 mm).
pub fn write_error_ply(recon: &Mesh, truth: &Mesh, path: &Path) -> Result<(), MeshIoError> {
    let err = surface_distance(&recon.vertices, truth);
    write_ply(recon, Some(&error_colors(&err, 3.0)), path)
}
