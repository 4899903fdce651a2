//! The whole method, stage after stage: place the template on the sphere the outlines' limbs
//! define (stage 0), then alternate model contours -> correspondences -> solve, first turning the
//! cap about that sphere's centre (stage A; the full similarity when there is no limb sphere),
//! then for the deformation graph with its sphere prior (stage B), and fit the cup sphere to the
//! observed part of the result.

mod calibration;
mod correspondences;
mod cup;
mod deformation;
mod depth;
mod fallback;
mod guards;
mod input_check;
mod log;
mod params;
mod placement;
mod restart;
mod rim_pairs;
mod uncertainty;

#[cfg(test)]
mod tests;

pub use calibration::{
    CalibrationError, CupCalibration, Learn, Shipped, TrainingRun, ViewFit, MIN_TRAINING_RUNS,
    NOMINAL_COVERAGE, VIEW_MATCH_DEG,
};
pub use cup::{
    cup_spheres, observed_part_sphere, prior_region_sphere, CupSpheres, PriorRegion,
    REGION_MIN_COVERAGE,
};
pub use depth::{depth_axis, FACING_RAMP};
pub use fallback::{params_used, Fallback, FALLBACKS};
pub use guards::{
    annotated_shares, first_failure, folded_share, odd_view, view_label, GuardFailure, GuardParams,
    Judged, Refusal, ALONG_PX, VIEW_NOTE_MIN_PX, VIEW_NOTE_RATIO,
};
pub use input_check::{
    check_input, check_views, fills_hull, ABSURD, IMAGE_MARGIN, MAX_OUTLINE_POINTS, MIN_HULL_FILL,
    MIN_OUTLINE_EXTENT_PX, MIN_OUTLINE_POINTS, START_RADIUS_MM,
};
pub use log::{OrientationTrial, RestartCause, SolveLog};
pub use params::{
    CupEstimator, CupParams, DeformationParams, PlacementParams, ReconParams, MAX_DEPTH_MM,
    MAX_SHRINK,
};
pub use restart::outline_distance_px;
pub use rim_pairs::RimPairs;
pub use uncertainty::{
    cup_report, CupReport, SizeProbability, UncertaintyParams, MAX_RESAMPLES, MIN_RESAMPLES,
};

use crate::contours::ModelContour;
use crate::correspond::srvf::SrvfError;
use crate::correspond::Observation;
use crate::engine::{KernelError, Kernels};
use crate::geom::{Curve, Mesh, Sphere, SphereFitError};
use crate::report::CupSize;
use crate::solve::{limb_sphere, LimbSphere, SolveError};
use crate::template::{Placement, Template, TemplateError};
use crate::views::Camera;
use correspondences::{rms_px, Ctx};
use deformation::{Deformation, StageB};
use nalgebra::Point3;
use placement::{
    mirrored_axis, similarity_lm, similarity_stage, similarity_step, Poses, StageA,
    MIRROR_PROBE_ROUNDS, MIRROR_SWITCH,
};
use restart::restarting;

/// Why a reconstruction failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReconError {
    /// A kernel (model contour, deformation) failed.
    #[error("{0}")]
    Kernel(#[from] KernelError),
    /// Correspondences could not be found for an observed contour.
    #[error("view {view}, contour {contour}: correspondence: {source}")]
    Correspond {
        /// The view.
        view: usize,
        /// The contour's index in that view.
        contour: usize,
        /// Why.
        source: SrvfError,
    },
    /// Fewer correspondences than a solve needs (MIN_CORRESPONDENCES).
    #[error("{stage}: too few correspondences ({count}) to solve")]
    TooFewCorrespondences {
        /// The stage.
        stage: &'static str,
        /// How many there were.
        count: usize,
    },
    /// The solver failed.
    #[error("{stage}: solver: {source}")]
    Solve {
        /// The stage.
        stage: &'static str,
        /// Why.
        source: SolveError,
    },
    /// A solve left a vertex NaN or infinite.
    #[error("the solver diverged: vertex {vertex} is not finite")]
    NonFiniteVertex {
        /// The first such vertex.
        vertex: usize,
    },
    /// A pose refinement left a view's correction NaN or infinite.
    #[error("the solver diverged: the pose correction of view {view} is not finite")]
    NonFinitePose {
        /// The view.
        view: usize,
    },
    /// No cup sphere could be fitted to the result.
    #[error("cup sphere fit: {0}")]
    Sphere(#[from] SphereFitError),
    /// The number of views and of observed outline sets differ.
    #[error("views ({views}) and observed contour sets ({observed}) differ in number")]
    Mismatch {
        /// Views.
        views: usize,
        /// Observed outline sets.
        observed: usize,
    },
    /// The template cannot be used.
    #[error("template: {0}")]
    Template(#[from] TemplateError),
    /// The result failed a guard and no fallback passed (see `reconstruct`).
    #[error("the result was refused: {0}")]
    Guard(Refusal),
    /// A view, outline or start that no run can stand behind (see `check_input`).
    #[error("input {field} = {value}: must be {expected}")]
    Input {
        /// The input, as a path into `Input` (`cameras[1].k.fx`, `observed[0][0].points[17]`).
        field: String,
        /// Its value.
        value: String,
        /// What it must be.
        expected: String,
    },
    /// A cup report whose resamples leave the plausible cups (`GuardParams::cup_range_mm`): the
    /// spread they give is not a cup's, so no SD or size probability is stated (see
    /// `cup_report`).
    #[error("the cup's spread cannot be stated: {outside} of {samples} resampled cups lie outside {lo}-{hi} mm ({smallest:.1} to {largest:.1} mm) under contour noise of SD {noise_px} px; the noise SD must be an annotation's (a few pixels), or the result is too loose to resample")]
    Resamples {
        /// Resamples outside the range.
        outside: usize,
        /// Resamples drawn.
        samples: usize,
        /// The range, mm.
        lo: f64,
        /// Its upper end, mm.
        hi: f64,
        /// The smallest resampled diameter, mm.
        smallest: f64,
        /// The largest, mm.
        largest: f64,
        /// The contour noise SD the resamples were drawn with, px.
        noise_px: f64,
    },
    /// A setting outside what the method can run with (see `ReconParams::validate`).
    #[error("setting {field} = {value}: must be {expected}")]
    Param {
        /// The setting, as a path into ReconParams.
        field: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        expected: &'static str,
    },
}

/// The result.
#[derive(Clone, Debug)]
pub struct Reconstruction {
    /// The reconstructed surface.
    pub mesh: Mesh,
    /// The template at the given start.
    pub initial: Mesh,
    /// The cup sphere: fitted (robustly) to the part of the reconstructed surface the X-rays
    /// observe, the vertices the last correspondences tie to the outlines (see
    /// `observed_part_sphere`); the whole surface's fit when too few.
    pub sphere: Sphere,
    /// The same sphere before the calibration's bias and shrink (`CupParams::corrected`): the
    /// cup's geometry, which the rim's orientation is read from; `sphere` is the size.
    pub fitted_sphere: Sphere,
    /// The sphere fitted (robustly) to every reconstructed vertex.
    pub surface_sphere: Sphere,
    /// The cup's nearest catalogue size.
    pub cup: CupSize,
    /// What the solver did.
    pub log: SolveLog,
    /// Model contours of the initial and final meshes per view.
    pub initial_contours: Vec<ModelContour>,
    /// Model contours of the final mesh per view.
    pub final_contours: Vec<ModelContour>,
    /// Correspondences of the last round.
    pub observations: Vec<Observation>,
    /// The cameras the result was fitted with (the input ones, or with the pose corrections).
    pub cameras: Vec<Camera>,
}

/// One reconstruction's inputs: the views, the outlines observed in each (one or more a view),
/// where the template starts, and the template itself.
#[derive(Clone, Copy, Debug)]
pub struct Input<'a> {
    /// The views.
    pub cameras: &'a [Camera],
    /// Per view, the observed outlines (one or more), started anywhere and traced either way
    /// round (`reconstruct` enters each as its shape fixes: `Curve::entered`).
    pub observed: &'a [Vec<Curve>],
    /// Where the template starts.
    pub init: &'a Placement,
    /// The template (`Template::standard()` for the paper's hemisphere).
    pub template: &'a Template,
}

impl<'a> Input<'a> {
    /// The input of these views, outlines, start and template.
    pub fn new(
        cameras: &'a [Camera],
        observed: &'a [Vec<Curve>],
        init: &'a Placement,
        template: &'a Template,
    ) -> Self {
        Input {
            cameras,
            observed,
            init,
            template,
        }
    }
}

/// Reconstruct: the method's stages in order, each kernel on `kernels` (`Kernels::Cpu`, or the
/// caller's GPU). With `prm.guards`, a result that fails a guard is not returned: the fallbacks
/// (`FALLBACKS`) are tried in turn, and the first that passes is returned with the fallback
/// and the failure in its log; when none does, the error (`Refusal`) names the first failure,
/// and the view whose outline disagreed with the others in that result, if one did.
pub fn reconstruct(
    input: &Input,
    prm: &ReconParams,
    kernels: Kernels,
) -> Result<Reconstruction, ReconError> {
    prm.validate()?;
    check_pose_view(input, prm)?;
    let observed = entered(input.observed);
    let input = &Input {
        observed: &observed,
        ..*input
    };
    // The fallbacks change no placement setting, so they share the limb sphere too.
    let limb = LimbOnce::new(input, prm);
    let ctx = Ctx {
        cams: input.cameras,
        observed: input.observed,
        prm,
        kernels,
    };
    if prm.guards.is_none() {
        let (rec, _) = restarting(input, prm, kernels, &limb)?;
        return calibrated(&ctx, rec);
    }
    // `restarting` judged its result by the guards already.
    let (failure, outline_px_per_view) = match restarting(input, prm, kernels, &limb) {
        Ok((rec, None)) => return calibrated(&ctx, rec),
        Ok((rec, Some(f))) => (f, rec.log.outline_px_per_view),
        Err(ReconError::NonFiniteVertex { vertex }) => {
            (GuardFailure::NonFiniteVertex { vertex }, Vec::new())
        }
        Err(ReconError::NonFinitePose { view }) => {
            (GuardFailure::NonFinitePose { view }, Vec::new())
        }
        Err(e) => return Err(e),
    };
    for fb in Fallback::order(&failure) {
        let Some(p) = fb.params(prm) else { continue };
        if let Ok((mut rec, None)) = restarting(input, &p, kernels, &limb) {
            rec.log.fallback = Some(fb.name());
            rec.log.guard = Some(failure);
            return calibrated(&ctx, rec);
        }
    }
    Err(ReconError::Guard(Refusal {
        failure,
        outline_px_per_view,
        names: Vec::new(),
    }))
}

/// Every outline of `observed` entered at the point and in the direction its shape fixes, so
/// that where it was started, and which way round, changes nothing the method returns
/// (`Curve::entered`): what `reconstruct` and `cup_report` both solve with.
pub(crate) fn entered(observed: &[Vec<Curve>]) -> Vec<Vec<Curve>> {
    observed
        .iter()
        .map(|view| view.iter().map(Curve::entered).collect())
        .collect()
}

/// The first guard `rec` fails under `g`, if any.
pub(super) fn guard_failure(g: &GuardParams, rec: &Reconstruction) -> Option<GuardFailure> {
    first_failure(
        g,
        &Judged {
            mesh: &rec.mesh,
            cup: &rec.sphere,
            limb: rec.log.limb_sphere,
            rms_px: rec.log.reprojection_rms_px,
            outline_px: rec.log.outline_px,
            annotated_share: rec.log.annotated_share,
        },
    )
}

/// The outlines' limb sphere (`solve::limb_sphere`), fitted at most once for all the passes of
/// one `reconstruct` call: it depends only on the views, their outlines and
/// `placement.limb_scale_mm`, which every start, restart and fallback shares. None when no
/// sphere fits.
pub(super) struct LimbOnce<'a> {
    cams: &'a [Camera],
    observed: &'a [Vec<Curve>],
    scale_mm: f64,
    fit: std::sync::OnceLock<Option<LimbSphere>>,
}

impl<'a> LimbOnce<'a> {
    fn new(input: &Input<'a>, prm: &ReconParams) -> Self {
        LimbOnce {
            cams: input.cameras,
            observed: input.observed,
            scale_mm: prm.placement.limb_scale_mm,
            fit: std::sync::OnceLock::new(),
        }
    }

    pub(super) fn get(&self) -> Option<LimbSphere> {
        *self
            .fit
            .get_or_init(|| limb_sphere(self.cams, self.observed, self.scale_mm).ok())
    }
}

/// One pass of the method, unguarded.
pub(super) fn attempt(
    input: &Input,
    prm: &ReconParams,
    kernels: Kernels,
    limb: &LimbOnce,
) -> Result<Reconstruction, ReconError> {
    let ctx = Ctx {
        cams: input.cameras,
        observed: input.observed,
        prm,
        kernels,
    };
    let mut log = SolveLog::default();
    let start = limb_start(&ctx, input.init, limb, &mut log);
    let placed = place(&ctx, input.template, &start, &mut log)?;
    let posed = refine_views(&ctx, input.template, placed.best, &mut log)?;
    let deformed = deform(&ctx, posed, placed.orientations, &mut log)?;
    finish(&ctx, input, deformed, log)
}

/// The input (`check_input`), and the pose refinement's reference view among its views.
fn check_pose_view(input: &Input, prm: &ReconParams) -> Result<(), ReconError> {
    check_input(input)?;
    if let Some(pp) = prm
        .pose
        .as_ref()
        .filter(|pp| pp.reference_view >= input.cameras.len())
    {
        return Err(ReconError::Param {
            field: "pose.reference_view",
            value: pp.reference_view.to_string(),
            expected: "the index of one of the views",
        });
    }
    Ok(())
}

/// Where stage A starts: the given placement, or its axis on the limb sphere.
struct Start {
    placement: Placement,
    /// Stage A turns the cap about the sphere's centre only.
    about: Option<Point3<f64>>,
}

/// Stage 0: the template on the sphere the outlines' limbs define (the given axis kept). The
/// limb sphere needs the views' poses as given; with pose refinement it is left out.
fn limb_start(ctx: &Ctx, init: &Placement, limb: &LimbOnce, log: &mut SolveLog) -> Start {
    let prm = ctx.prm;
    let mut placement = init.clone();
    if prm.placement.limb_start && prm.pose.is_none() {
        if let Some(ls) = limb.get() {
            placement.center = ls.center;
            placement.radius = ls.radius;
            log.limb_sphere = Some([ls.center.x, ls.center.y, ls.center.z, ls.radius]);
        }
    }
    let rotation_only = prm.placement.rotation_only && log.limb_sphere.is_some();
    Start {
        about: rotation_only.then_some(placement.center),
        placement,
    }
}

/// What stage A settled on, and which orientations stage B is to compare.
struct Placed {
    best: StageA,
    orientations: Orientations,
}

/// The orientations stage A leaves to stage B: `lead` names where `Placed::best` came from
/// ("stage A", the given start, or "mirrored"), and `rivals` are the other settled caps, by
/// name, when the outlines leave the choice open (empty when stage A's was the only one).
struct Orientations {
    lead: &'static str,
    rivals: Vec<(&'static str, Mesh, Placement)>,
}

/// Stage A: similarity, correspondences recomputed each round. When the sphere is known the
/// axis mirrored through the first view's image plane is probed too: an acetabulum opening
/// forwards and one opening backwards by as much cast nearly the same outline in a frontal
/// view, and only the oblique views tell them apart. The mirrored one leads when it reprojects
/// clearly better (by the factor MIRROR_SWITCH) and is dropped when clearly worse; in between,
/// the rigid cap cannot tell them apart. Unless it is dropped, both go on to stage B, which
/// compares them after a deformation round (see `DeformationParams::orientation_rounds`): a
/// rigid cap's score is not the last word even when the mirrored one leads, since the given
/// start's cap may not have settled in its rounds (an atlas acetabulum tilted 12 degrees, level
/// 3: the given cap 24 degrees off the truth's axis after 10 rounds, the mirrored one 57 degrees
/// off but scoring 0.58 of it; stage B's round told them apart, 3.7 against 18.7 px).
fn place(
    ctx: &Ctx,
    template: &Template,
    start: &Start,
    log: &mut SolveLog,
) -> Result<Placed, ReconError> {
    let prm = ctx.prm;
    // The similarity stage fixes only a handful of parameters: coarser SRVF curves do.
    let mut coarse = prm.clone();
    let srvf = &mut coarse.correspond.srvf;
    srvf.samples = srvf.samples.min(prm.placement.srvf_samples.max(16));
    srvf.seed_candidates = srvf
        .seed_candidates
        .min(prm.placement.seed_candidates.max(1));
    let coarse_ctx = Ctx {
        prm: &coarse,
        ..*ctx
    };
    let unit = template.mesh();
    // Stage A from `placement`.
    let solve = |mesh: Mesh, placement: Placement, max_rounds: usize| {
        similarity_stage(
            &coarse_ctx,
            template.on_rim(),
            mesh,
            placement,
            start.about,
            max_rounds,
        )
    };
    // Its work added to the log.
    let logged = |r: Result<StageA, ReconError>, log: &mut SolveLog| {
        let r = r?;
        log.similarity_rounds += r.rounds;
        log.gn_iterations += r.iterations;
        Ok::<_, ReconError>(r)
    };
    let s = &start.placement;
    let mirrored = mirrored_axis(s, ctx.cams)
        .filter(|_| start.about.is_some() && prm.placement.mirrored_start)
        .map(|axis| Placement { axis, ..s.clone() });
    // The given start and the mirrored probe are independent: on the CPU they run side by side
    // (as `Kernels::map_parts` runs parts; on the GPU paths in turn). A failed given start is
    // reported before the probe is looked at, as when they ran in turn.
    let given = || solve(s.place(unit), s.clone(), prm.placement.rounds);
    // A few rounds tell a clearly wrong orientation from a right one; the mirrored start goes
    // on to convergence unless it is clearly worse.
    let probe = || {
        mirrored
            .clone()
            .map(|m| solve(m.place(unit), m, MIRROR_PROBE_ROUNDS))
    };
    let (first, probe) = match ctx.kernels {
        Kernels::Cpu => rayon::join(given, probe),
        _ => {
            let first = given();
            let probe = if first.is_ok() { probe() } else { None };
            (first, probe)
        }
    };
    let mut best = logged(first, log)?;
    let mut lead = "stage A";
    let mut rivals = Vec::new();
    if let Some(probe) = probe {
        let probe = logged(probe, log)?;
        let clear = probe.score < best.score * MIRROR_SWITCH;
        let open = !clear
            && prm.deformation.orientation_rounds > 0
            && probe.score < best.score / MIRROR_SWITCH;
        if clear || open {
            let settled = logged(
                solve(probe.mesh, probe.placement, prm.placement.rounds),
                log,
            )?;
            if clear {
                let given = std::mem::replace(&mut best, settled);
                lead = "mirrored";
                if prm.deformation.orientation_rounds > 0 {
                    rivals.push(("stage A", given.mesh, given.placement));
                }
            } else {
                rivals.push(("mirrored", settled.mesh, settled.placement));
            }
        }
    }
    Ok(Placed {
        best,
        orientations: Orientations { lead, rivals },
    })
}

/// Where stage B starts: the placed cap and the views' corrections so far.
struct Posed {
    mesh: Mesh,
    placement: Placement,
    poses: Poses,
}

/// Stage A': with pose refinement, similarity and per-view pose corrections alternate on
/// correspondences recomputed each round, from where stage A settled. Without it, the views
/// stay as given.
fn refine_views(
    ctx: &Ctx,
    template: &Template,
    placed: StageA,
    log: &mut SolveLog,
) -> Result<Posed, ReconError> {
    let prm = ctx.prm;
    let (mut mesh, mut placement) = (placed.mesh, placed.placement);
    let mut poses = Poses::none(crate::geom::centroid(&mesh.vertices), ctx.cams);
    if prm.pose.is_some() {
        let sim_lm = similarity_lm(prm);
        for _ in 0..prm.placement.rounds {
            let mut obs = ctx.correspondences(&mesh, &poses.cams_now, "pose refinement")?;
            for o in obs
                .iter_mut()
                .filter(|o| template.on_rim()[o.vertex as usize])
            {
                o.weight *= prm.placement.rim_weight;
            }
            let before = poses.x.clone();
            log.gn_iterations += poses.refine(ctx, &mesh, &obs)?;
            // The full similarity here: the limb sphere was fitted with the uncorrected views,
            // so centre and size must follow the corrections.
            let (moved, shift, info) = similarity_step(
                &mesh,
                &poses.cams_now,
                &obs,
                prm,
                &sim_lm,
                None,
                &mut placement,
                None,
            )?;
            mesh = moved;
            log.gn_iterations += info.iterations;
            let pose_step = before
                .iter()
                .zip(&poses.x)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            if shift < prm.placement.tol_mm && pose_step < 1e-4 {
                break;
            }
        }
    }
    Ok(Posed {
        mesh,
        placement,
        poses,
    })
}

/// Stage B: embedded deformation (with the per-view pose corrections when asked for). With a
/// rival orientation from stage A, each candidate deforms for a few rounds and the one that
/// then reprojects best goes on: stage A's rigid cap cannot tell mirror-image orientations
/// apart where the acetabulum is not a cap, but the deformed surface of a wrong one cannot
/// follow the oblique views' outlines.
fn deform(
    ctx: &Ctx,
    posed: Posed,
    Orientations { lead, rivals }: Orientations,
    log: &mut SolveLog,
) -> Result<Deformation, ReconError> {
    let b = StageB::new(ctx.prm);
    let center = posed.poses.center;
    let mut run = Deformation::new(posed.mesh, &posed.placement, posed.poses);
    if !rivals.is_empty() {
        let k = ctx.prm.deformation.orientation_rounds.min(b.rounds);
        run.advance(ctx, &b, k)?;
        log.orientations.push(OrientationTrial {
            source: lead,
            rms_px: run.rms_px(),
        });
        for (source, m, p) in rivals {
            let mut other = Deformation::new(m, &p, Poses::none(center, ctx.cams));
            other.advance(ctx, &b, k)?;
            let rms_px = other.rms_px();
            log.orientations.push(OrientationTrial { source, rms_px });
            if rms_px < run.rms_px() {
                std::mem::swap(&mut run, &mut other);
            }
            log.gn_iterations += other.gn_iterations;
        }
    }
    run.advance(ctx, &b, b.rounds)?;
    log.correspondence_updates += run.rounds;
    log.gn_iterations += run.gn_iterations;
    Ok(run)
}

/// The calibration's depth offset (`CupParams::depth_mm`) applied to a result the restarts and
/// guards have judged: the surface and its spheres moved that far along its depth axis (a fit
/// to moved points is the moved fit), its final contours drawn again. It comes after the
/// judging so that a learned correction for what no outline shows is not read as a fit that
/// missed its outlines: the log's outline distances stay the fit's, which the restarts, the
/// guards and the resamples' contour noise go by.
fn calibrated(ctx: &Ctx, mut rec: Reconstruction) -> Result<Reconstruction, ReconError> {
    let depth = ctx.prm.cup.depth_mm;
    let Some(a) = rec.log.depth_axis.map(nalgebra::Vector3::from) else {
        return Ok(rec);
    };
    if depth == 0.0 {
        return Ok(rec);
    }
    let v = a * depth;
    rec.log.depth_moved_mm = depth;
    rec.mesh = depth::moved(&rec.mesh, &v);
    rec.sphere = rec.sphere.moved(&v);
    rec.fitted_sphere = rec.fitted_sphere.moved(&v);
    rec.surface_sphere = rec.surface_sphere.moved(&v);
    rec.final_contours = ctx.contours(&rec.mesh, &rec.cameras)?;
    Ok(rec)
}

/// The result: the cup sphere fitted to the observed part, the contours before and after, and
/// the log.
fn finish(
    ctx: &Ctx,
    input: &Input,
    run: Deformation,
    mut log: SolveLog,
) -> Result<Reconstruction, ReconError> {
    let Deformation {
        mesh,
        obs,
        converged,
        poses,
        state,
        ..
    } = run;
    log.prior_sphere = state
        .prior_sphere
        .filter(|_| ctx.prm.deformation.sphere_prior > 0.0)
        .map(|(c, r)| [c.x, c.y, c.z, r]);
    if ctx.prm.pose.is_some() {
        log.pose_corrections = poses.sizes();
    }
    log.converged = converged;
    log.reprojection_rms_px = rms_px(&mesh, &poses.cams_now, &obs);
    log.correspondences = obs.len();
    let spheres = cup_spheres(&mesh, &obs, &ctx.prm.cup, log.prior_region(ctx.prm))?;
    let axis = depth_axis(&mesh, &spheres.surface.center_point(), &poses.cams_now);
    log.depth_axis = axis.map(|a| [a.x, a.y, a.z]);
    let (sphere, fitted_sphere, surface_sphere) = (spheres.cup, spheres.fitted, spheres.surface);
    let cup = ctx.prm.cup.catalogue.nearest(sphere.diameter());
    let initial = input.init.place(input.template.mesh());
    let final_contours = ctx.contours(&mesh, &poses.cams_now)?;
    (log.outline_px_per_view, log.outline_px) =
        restart::outline_distances_px(&final_contours, ctx.observed);
    log.annotated_share_per_view = guards::annotated_shares(&final_contours, ctx.observed);
    log.annotated_share = log
        .annotated_share_per_view
        .iter()
        .copied()
        .fold(0.0, f64::max);
    Ok(Reconstruction {
        initial_contours: ctx.contours(&initial, ctx.cams)?,
        final_contours,
        mesh,
        initial,
        sphere,
        fitted_sphere,
        surface_sphere,
        cup,
        log,
        observations: obs,
        cameras: poses.cams_now,
    })
}
