//! Stage A: the template turned (or moved and scaled) as a rigid cap onto the outlines, the
//! mirrored orientation probed beside it, and the per-view pose corrections of stage A'.

use super::correspondences::{check_finite, residuals_px, Ctx};
use super::{ReconError, ReconParams};
use crate::correspond::Observation;
use crate::geom::Mesh;
use crate::solve::Problem;
use crate::solve::{
    apply_similarity, corrected_camera, levenberg_marquardt, LmInfo, LmParams, PoseProblem,
    SimilarityProblem, SIM_PARAMS,
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
    let mut damping = Damping::default();
    for _ in 0..max_rounds {
        let mut obs = ctx.correspondences(&mesh, ctx.cams, "similarity")?;
        for o in obs.iter_mut().filter(|o| on_rim[o.vertex as usize]) {
            o.weight *= prm.placement.rim_weight;
        }
        let (moved, shift, info) = similarity_step(
            &mesh,
            ctx.cams,
            &obs,
            prm,
            &sim_lm,
            about,
            &mut placement,
            prm.placement.damped.then_some(&mut damping),
        )?;
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

/// Stage A's rounds damped where they turn back. A round is one step of a fixed-point
/// iteration: correspondences from the cap as it is, then the similarity they ask for. Where
/// the correspondences found at the new cap ask to undo the last move, the rounds are caught in
/// a cycle: measured, the phantom's cap turned back and forth between two axes 2.7 degrees
/// apart for all ten rounds, and an atlas acetabulum's (a24_lhip, level 3) between two 9
/// degrees apart, so that the cap stage A handed on was whichever of the two the number of
/// rounds picked, and the rounds never met `tol_mm`. Each such reversal halves the share of the
/// asked-for move that is taken (a damped fixed-point iteration), so the rounds settle between
/// the two caps, where the correspondences balance.
#[derive(Debug)]
pub(super) struct Damping {
    /// The share of the solved move taken.
    share: f64,
    /// The last solved move, in mm (`Damping::in_mm`): the direction of the move taken, which
    /// the share (a positive factor) does not change.
    last: Option<[f64; SIM_PARAMS]>,
}

impl Default for Damping {
    fn default() -> Self {
        Damping {
            share: 1.0,
            last: None,
        }
    }
}

impl Damping {
    /// A similarity's parameters as displacements of a cap of `radius`: the rotation vector
    /// and the log scale times the radius, the translation as it is.
    fn in_mm(f: &[f64; SIM_PARAMS], radius: f64) -> [f64; SIM_PARAMS] {
        let mut m = *f;
        for (k, v) in m.iter_mut().enumerate() {
            if k < 3 || k == 6 {
                *v *= radius;
            }
        }
        m
    }

    /// The share of the solved move `f` to take on a cap of `radius`: halved when `f` points
    /// against the last move. Remembers `f`.
    fn share_of(&mut self, f: &[f64; SIM_PARAMS], radius: f64) -> f64 {
        let now = Self::in_mm(f, radius);
        if let Some(last) = &self.last {
            let dot: f64 = last.iter().zip(&now).map(|(a, b)| a * b).sum();
            if dot < 0.0 {
                self.share *= 0.5;
            }
        }
        self.last = Some(now);
        self.share
    }
}

/// One similarity solve on fixed correspondences: the moved mesh, and how far the cap moved (mm),
/// measured on its placement (`placement` is moved along): centre shift + radius change + the
/// axis's turn times the radius. Vertex motion would count turns about the cap's own axis, which
/// change nothing and which the correspondences leave free. With `damping`, the share of the
/// solved move it says is taken (stage A's rounds).
#[allow(clippy::too_many_arguments)]
pub(super) fn similarity_step(
    mesh: &Mesh,
    cams: &[Camera],
    obs: &[Observation],
    prm: &ReconParams,
    lm: &LmParams,
    rotation_about: Option<Point3<f64>>,
    placement: &mut Placement,
    damping: Option<&mut Damping>,
) -> Result<(Mesh, f64, LmInfo), ReconError> {
    let mut problem = SimilarityProblem::new(&mesh.vertices, cams, obs);
    problem.tangential = prm.tangential();
    if let Some(c) = rotation_about {
        problem.center = c;
        problem.rotation_only = true;
    }
    let x0 = vec![0.0; problem.block_size()];
    let (mut x, info) =
        levenberg_marquardt(&problem, x0, lm).map_err(|source| ReconError::Solve {
            stage: "similarity",
            source,
        })?;
    if let Some(d) = damping {
        let share = d.share_of(&crate::solve::full_state(&x), placement.radius);
        x.iter_mut().for_each(|v| *v *= share);
    }
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
            ctx.prm.tangential(),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A move of `turn` radians about z and `shift` mm along x.
    fn mv(turn: f64, shift: f64) -> [f64; SIM_PARAMS] {
        [0.0, 0.0, turn, shift, 0.0, 0.0, 0.0]
    }

    #[test]
    fn a_move_that_turns_back_halves_the_share_taken() {
        let mut d = Damping::default();
        assert_eq!(d.share_of(&mv(0.05, 1.0), 25.0), 1.0);
        // Back by about as much: a two-cycle, the share halves, and again at the next reversal.
        assert_eq!(d.share_of(&mv(-0.05, -1.0), 25.0), 0.5);
        assert_eq!(d.share_of(&mv(0.04, 0.5), 25.0), 0.25);
        // On in the same direction as the last move taken: the share stays.
        assert_eq!(d.share_of(&mv(0.01, 0.2), 25.0), 0.25);
    }

    #[test]
    fn moves_that_keep_their_direction_are_taken_whole() {
        // Companion: shrinking moves that go on the same way, as rounds that converge make,
        // and a turn back in one component outweighed by the others (the cap still moves on).
        let mut d = Damping::default();
        for k in 0..6 {
            let f = 0.5f64.powi(k);
            assert_eq!(d.share_of(&mv(0.05 * f, 1.0 * f), 25.0), 1.0);
        }
        assert_eq!(d.share_of(&mv(-0.001, 0.1), 25.0), 1.0);
        // The rotation counts by its arc on the cap: 0.05 rad on 25 mm is 1.25 mm, and outweighs
        // a 1 mm shift the other way.
        let mut d = Damping::default();
        d.share_of(&mv(0.05, 0.0), 25.0);
        assert_eq!(d.share_of(&mv(0.05, -1.0), 25.0), 1.0);
        assert_eq!(d.share_of(&mv(-0.05, 1.0), 25.0), 0.5);
    }
}
