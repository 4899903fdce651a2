//! Stage A: the template turned (or moved and scaled) as a rigid cap onto the outlines, the
//! mirrored orientation probed beside it, and the per-view pose corrections of stage A'.

use super::correspondences::{check_finite, residuals_px, Ctx};
use super::{ReconError, ReconParams};
use crate::correspond::Observation;
use crate::geom::Mesh;
use crate::solve::Problem;
use crate::solve::{
    apply_similarity, corrected_camera, levenberg_marquardt, LmInfo, LmParams, PoseProblem,
    SimilarityProblem,
};
use crate::template::Placement;
use crate::views::Camera;
use nalgebra::{Point3, Vector3};

/// The mirrored start replaces the given one when its score is below this fraction of the given
/// one's, and is dropped when above its inverse; in between both go on to stage B. On the shared
/// acetabula a wrong orientation scores about twice the right one where the cap fits the
/// acetabulum, while on m1_rhip the two mirror images score within about 15 % of each other
/// whichever is right.
pub(super) const MIRROR_SWITCH: f64 = 0.7;

/// Similarity rounds the mirrored start gets before it is compared.
pub(super) const MIRROR_PROBE_ROUNDS: usize = 4;

/// What one run of stage A ended with.
pub(super) struct StageA {
    pub(super) mesh: Mesh,
    pub(super) placement: Placement,
    pub(super) rounds: usize,
    pub(super) iterations: usize,
    /// Median reprojection residual (px) of the last round's correspondences: ranks starts.
    pub(super) score: f64,
}

/// LM settings of one similarity solve.
pub(super) fn similarity_lm(prm: &ReconParams) -> LmParams {
    LmParams {
        max_iterations: 10,
        ..prm.lm.clone()
    }
}

/// The axis of `start` mirrored through the first view's image plane, when it differs.
pub(super) fn mirrored_axis(
    start: &Placement,
    cams: &[Camera],
) -> Option<nalgebra::Unit<Vector3<f64>>> {
    let d = cams.first()?.r.matrix().row(2).transpose();
    let a = start.axis.into_inner();
    nalgebra::Unit::try_new(a - 2.0 * a.dot(&d) * d, 1e-9)
        .filter(|m| (m.into_inner() - a).norm() > 1e-3)
}

/// Stage A from `mesh` (the template at `placement`, `on_rim` marking its rim): similarity (or
/// rotation about `about`) solves on correspondences recomputed each round until the cap
/// settles, at most `max_rounds`.
pub(super) fn similarity_stage(
    ctx: &Ctx,
    on_rim: &[bool],
    mut mesh: Mesh,
    mut placement: Placement,
    about: Option<Point3<f64>>,
    max_rounds: usize,
) -> Result<StageA, ReconError> {
    let prm = ctx.prm;
    let sim_lm = similarity_lm(prm);
    let (mut rounds, mut iterations) = (0, 0);
    let mut last = Vec::new();
    for _ in 0..max_rounds {
        let mut obs = ctx.correspondences(&mesh, ctx.cams, "similarity")?;
        for o in obs.iter_mut().filter(|o| on_rim[o.vertex as usize]) {
            o.weight *= prm.placement.rim_weight;
        }
        let (moved, shift, info) =
            similarity_step(&mesh, ctx.cams, &obs, prm, &sim_lm, about, &mut placement)?;
        mesh = moved;
        rounds += 1;
        iterations += info.iterations;
        last = obs;
        if shift < prm.placement.tol_mm {
            break;
        }
    }
    let mut r = residuals_px(&mesh, ctx.cams, &last);
    r.sort_by(f64::total_cmp);
    let score = r.get(r.len() / 2).copied().unwrap_or(f64::INFINITY);
    Ok(StageA {
        mesh,
        placement,
        rounds,
        iterations,
        score,
    })
}

/// One similarity solve on fixed correspondences: the moved mesh, and how far the cap moved (mm),
/// measured on its placement (`placement` is moved along): centre shift + radius change + the
/// axis's turn times the radius. Vertex motion would count turns about the cap's own axis, which
/// change nothing and which the correspondences leave free.
pub(super) fn similarity_step(
    mesh: &Mesh,
    cams: &[Camera],
    obs: &[Observation],
    prm: &ReconParams,
    lm: &LmParams,
    rotation_about: Option<Point3<f64>>,
    placement: &mut Placement,
) -> Result<(Mesh, f64, LmInfo), ReconError> {
    let mut problem = SimilarityProblem::new(&mesh.vertices, cams, obs);
    problem.tangential = prm.weights.tangential;
    if let Some(c) = rotation_about {
        problem.center = c;
        problem.rotation_only = true;
    }
    let x0 = vec![0.0; problem.block_size()];
    let (x, info) = levenberg_marquardt(&problem, x0, lm).map_err(|source| ReconError::Solve {
        stage: "similarity",
        source,
    })?;
    let moved = apply_similarity(&x, &problem.center, &mesh.vertices);
    let f = crate::solve::full_state(&x);
    let rot = nalgebra::Rotation3::new(Vector3::new(f[0], f[1], f[2]));
    let scale = f[6].exp();
    let center = problem.center
        + Vector3::new(f[3], f[4], f[5])
        + scale * (rot * (placement.center - problem.center));
    let axis = rot * placement.axis;
    let turn = placement.axis.dot(&axis).clamp(-1.0, 1.0).acos();
    let shift = (center - placement.center).norm()
        + (scale - 1.0).abs() * placement.radius
        + turn * placement.radius;
    *placement = Placement {
        center,
        radius: placement.radius * scale,
        axis,
    };
    let out = mesh.with_vertices(moved);
    check_finite(&out)?;
    Ok((out, shift, info))
}

/// The per-view pose corrections (stage A' and, with `pose`, stage B): six parameters a view
/// (rotation vector, translation) about `center`, and the views they make.
#[derive(Clone, Debug)]
pub(super) struct Poses {
    pub(super) center: Point3<f64>,
    pub(super) x: Vec<f64>,
    pub(super) cams_now: Vec<Camera>,
}

impl Poses {
    /// No correction yet: the views as given.
    pub(super) fn none(center: Point3<f64>, cams: &[Camera]) -> Self {
        Poses {
            center,
            x: vec![0.0; 6 * cams.len()],
            cams_now: cams.to_vec(),
        }
    }

    /// One pose solve on fixed correspondences and shape (`ctx.prm.pose`'s settings; nothing
    /// without them); updates the corrections and the views. The solver's iterations.
    pub(super) fn refine(
        &mut self,
        ctx: &Ctx,
        mesh: &Mesh,
        obs: &[Observation],
    ) -> Result<usize, ReconError> {
        let Some(pp) = &ctx.prm.pose else {
            return Ok(0);
        };
        let pose = PoseProblem::new(
            &mesh.vertices,
            self.center,
            ctx.cams,
            obs,
            pp,
            ctx.prm.weights.tangential,
        );
        let (x, info) =
            levenberg_marquardt(&pose, self.x.clone(), &ctx.prm.lm).map_err(|source| {
                ReconError::Solve {
                    stage: "pose refinement",
                    source,
                }
            })?;
        if let Some(k) = x.iter().position(|v| !v.is_finite()) {
            return Err(ReconError::NonFinitePose { view: k / 6 });
        }
        self.x = x;
        self.cams_now = (0..ctx.cams.len())
            .map(|k| corrected_camera(&ctx.cams[k], &self.center, &self.x[6 * k..6 * k + 6]))
            .collect();
        Ok(info.iterations)
    }

    /// Per view, the size of the correction: degrees and mm.
    pub(super) fn sizes(&self) -> Vec<[f64; 2]> {
        self.x
            .chunks(6)
            .map(|c| {
                let deg = Vector3::new(c[0], c[1], c[2]).norm().to_degrees();
                let mm = Vector3::new(c[3], c[4], c[5]).norm();
                [deg, mm]
            })
            .collect()
    }
}
