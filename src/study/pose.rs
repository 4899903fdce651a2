//! The pose-refinement simulation: the same cases reconstructed from views whose poses are off
//! (every view but the reference turned by a fixed angle about a random axis through the object
//! and shifted by a fixed distance in a random direction), once with the per-view pose
//! refinement and once without; the truth's observations come from the true poses.

use super::runner::Prepared;
use crate::engine::Kernels;
use crate::geom::pool_map;
use crate::geom::Mesh;
use crate::pipeline::{reconstruct, Input, ReconParams};
use crate::report::accuracy_from;
use crate::sim::XrayGeometry;
use crate::sim::{perturb_poses, NoiseLevel, SimError};
use crate::solve::PoseParams;
use crate::template::TemplateParams;

/// One case, both ways.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PoseRow {
    /// The run.
    pub run: usize,
    /// Its seed.
    pub seed: u64,
    /// MAE without pose refinement, mm.
    pub mae_without_mm: f64,
    /// MAE with it, mm.
    pub mae_with_mm: f64,
    /// Cup error without, mm.
    pub cup_error_without_mm: f64,
    /// Cup error with, mm.
    pub cup_error_with_mm: f64,
    /// Size of the corrections found per view (degrees, mm).
    pub corrections: Vec<[f64; 2]>,
    /// Why the run failed (empty when it did not).
    pub error: String,
}

/// The pose study's settings.
#[derive(Clone, Debug)]
pub struct PoseStudy {
    /// Runs.
    pub runs: usize,
    /// Study seed.
    pub seed: u64,
    /// The start's noise level.
    pub level: u32,
    /// Pose error of the oblique views, degrees.
    pub deg: f64,
    /// Pose error of the oblique views, mm.
    pub mm: f64,
    /// Worker threads.
    pub threads: usize,
    /// The refinement's settings.
    pub pose: PoseParams,
}

impl Default for PoseStudy {
    fn default() -> Self {
        PoseStudy {
            runs: 10,
            seed: 1,
            level: 1,
            deg: 2.0,
            mm: 5.0,
            threads: 1,
            pose: PoseParams::default(),
        }
    }
}

fn one(shared: &Prepared, cfg: &PoseStudy, run: usize) -> PoseRow {
    let seed = crate::study::run_seed(cfg.seed, 1000 + cfg.level, run);
    let mut row = PoseRow {
        run,
        seed,
        mae_without_mm: f64::NAN,
        mae_with_mm: f64::NAN,
        cup_error_without_mm: f64::NAN,
        cup_error_with_mm: f64::NAN,
        corrections: Vec::new(),
        error: String::new(),
    };
    let Some(level) = NoiseLevel::level(cfg.level) else {
        row.error = format!("no noise level {}", cfg.level);
        return row;
    };
    let sim = match shared.setup.case(2.0, &level, seed) {
        Ok(sim) => sim,
        Err(e) => {
            row.error = e.to_string();
            return row;
        }
    };
    let cams = perturb_poses(
        &sim.cameras,
        &sim.truth_placement.center,
        cfg.deg,
        cfg.mm,
        cfg.pose.reference_view,
        seed,
    );
    let gt = sim.truth_sphere.diameter();
    for refine in [false, true] {
        // The study measures what pose refinement changes: both arms return their result as
        // it stands (without refinement, views 5 mm off fold the surface, which the guards
        // would refuse).
        let prm = ReconParams {
            pose: refine.then(|| cfg.pose.clone()),
            guards: None,
            ..Default::default()
        };
        let input = Input {
            cameras: &cams,
            ..sim.input(&shared.template)
        };
        match reconstruct(&input, &prm, Kernels::Cpu) {
            Ok(rec) => {
                let mae = accuracy_from(&shared.samples, &rec.mesh).mae_mm;
                let cup = rec.sphere.diameter() - gt;
                if refine {
                    row.mae_with_mm = mae;
                    row.cup_error_with_mm = cup;
                    row.corrections = rec.log.pose_corrections.clone();
                } else {
                    row.mae_without_mm = mae;
                    row.cup_error_without_mm = cup;
                }
            }
            Err(e) => row.error = format!("{}: {e}", if refine { "with" } else { "without" }),
        }
    }
    row
}

/// Run every case (threads do not change the results). A truth that cannot be simulated at all,
/// pose errors that are not finite and >= 0, and pose settings `PoseParams::invalid` names are
/// errors before any run.
pub fn run_pose_study(truth: &Mesh, cfg: &PoseStudy) -> Result<Vec<PoseRow>, SimError> {
    for (field, v) in [("deg", cfg.deg), ("mm", cfg.mm)] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(SimError::Setting {
                field,
                value: crate::io::shown(&v.to_string()),
                expected: "finite and >= 0",
            });
        }
    }
    if let Some((field, v)) = cfg.pose.invalid() {
        return Err(SimError::Setting {
            field,
            value: crate::io::shown(&v.to_string()),
            expected: "finite and > 0",
        });
    }
    let shared = Prepared::new(truth, &XrayGeometry::default(), &TemplateParams::default())?;
    let runs: Vec<usize> = (0..cfg.runs).collect();
    Ok(pool_map(cfg.threads, &runs, |_, &k| one(&shared, cfg, k)))
}
