//! The whole method, stage after stage: place the template on the sphere the outlines' limbs
//! define (stage 0), then alternate model contours -> correspondences -> solve, first turning the
//! cap about that sphere's centre (stage A; the full similarity when there is no limb sphere),
//! then for the deformation graph with its sphere prior (stage B), and fit the cup sphere to the
//! observed part of the result.

mod correspondences;
mod cup;
mod deformation;
mod params;
mod placement;
mod uncertainty;

pub use cup::{cup_spheres, observed_part_sphere, CupSpheres};
pub use deformation::resolve_from;
pub use params::{
    CupParams, DeformationParams, PlacementParams, ReconParams, TemplateParams,
    MAX_TEMPLATE_VERTICES,
};
pub use uncertainty::{cup_report, CupReport, SizeProbability, UncertaintyParams};

use crate::contours::ModelContour;
use crate::correspond::srvf::SrvfError;
use crate::correspond::Observation;
use crate::engine::{KernelError, Kernels};
use crate::geom::Curve;
use crate::geom::Mesh;
use crate::geom::{Sphere, SphereFitError};
use crate::report::CupSize;
use crate::solve::limb_sphere;
use crate::solve::SolveError;
use crate::template::{spherical_cap, Placement};
use crate::views::Camera;
use correspondences::{contours, rms_px, weighted_correspondences};
use deformation::{Deformation, StageB};
use nalgebra::Vector3;
use placement::{
    mirrored_axis, refine_poses, similarity_lm, similarity_stage, similarity_step,
    MIRROR_PROBE_ROUNDS, MIRROR_SWITCH,
};

/// Why a reconstruction failed.
#[derive(Debug, thiserror::Error)]
pub enum ReconError {
    #[error("{0}")]
    Kernel(#[from] KernelError),
    #[error("view {view}, contour {contour}: correspondence: {source}")]
    Correspond {
        view: usize,
        contour: usize,
        source: SrvfError,
    },
    #[error("{stage}: too few correspondences ({count}) to solve")]
    TooFewCorrespondences { stage: &'static str, count: usize },
    #[error("{stage}: solver: {source}")]
    Solve {
        stage: &'static str,
        source: SolveError,
    },
    #[error("the solver diverged: {what}")]
    Diverged { what: String },
    #[error("cup sphere fit: {0}")]
    Sphere(#[from] SphereFitError),
    #[error("views ({views}) and observed contour sets ({observed}) differ in number")]
    Mismatch { views: usize, observed: usize },
    /// A setting outside what the method can run with (see `ReconParams::validate`).
    #[error("setting {field} = {value}: must be {expected}")]
    Param {
        field: &'static str,
        value: String,
        expected: &'static str,
    },
}

/// What the solver did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SolveLog {
    pub similarity_rounds: usize,
    pub correspondence_updates: usize,
    pub gn_iterations: usize,
    pub converged: bool,
    /// Final reprojection RMS over the last correspondences, pixels.
    pub reprojection_rms_px: f64,
    pub correspondences: usize,
    /// Per view, the size of the pose correction found (degrees, mm); empty without refinement.
    pub pose_corrections: Vec<[f64; 2]>,
    /// The sphere fitted to the outlines' limbs (centre x, y, z and radius, mm), when used.
    pub limb_sphere: Option<[f64; 4]>,
    /// The orientations stage B compared (none when stage A's was the only one), with their
    /// reprojection RMS after `deformation.orientation_rounds`; the lowest went on.
    pub orientations: Vec<OrientationTrial>,
}

/// One orientation stage B tried.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct OrientationTrial {
    /// "stage A" (its result) or "mirrored" (the mirrored start, settled by stage A).
    pub source: &'static str,
    pub rms_px: f64,
}

/// The result.
#[derive(Clone, Debug)]
pub struct Reconstruction {
    pub mesh: Mesh,
    pub initial: Mesh,
    /// The cup sphere: fitted (robustly) to the part of the reconstructed surface the X-rays
    /// observe, the vertices the last correspondences tie to the outlines (see
    /// `observed_part_sphere`); the whole surface's fit when too few.
    pub sphere: Sphere,
    /// The sphere fitted (robustly) to every reconstructed vertex.
    pub surface_sphere: Sphere,
    pub cup: CupSize,
    pub log: SolveLog,
    /// Model contours of the initial and final meshes per view.
    pub initial_contours: Vec<ModelContour>,
    pub final_contours: Vec<ModelContour>,
    /// Correspondences of the last round.
    pub observations: Vec<Observation>,
    /// The cameras the result was fitted with (the input ones, or with the pose corrections).
    pub cameras: Vec<Camera>,
}

/// Reconstruct from cameras and observed contours (per view, one or more), starting from `init`,
/// with every kernel on the CPU.
pub fn reconstruct(
    cams: &[Camera],
    observed: &[Vec<Curve>],
    init: &Placement,
    prm: &ReconParams,
) -> Result<Reconstruction, ReconError> {
    reconstruct_with(cams, observed, init, prm, Kernels::Cpu)
}

/// As `reconstruct`, with the model contours and the deformation on the given kernels.
pub fn reconstruct_with(
    cams: &[Camera],
    observed: &[Vec<Curve>],
    init: &Placement,
    prm: &ReconParams,
    kernels: Kernels,
) -> Result<Reconstruction, ReconError> {
    prm.validate()?;
    if cams.len() != observed.len() {
        return Err(ReconError::Mismatch {
            views: cams.len(),
            observed: observed.len(),
        });
    }
    if let Some(pp) = prm
        .pose
        .as_ref()
        .filter(|pp| pp.reference_view >= cams.len())
    {
        return Err(ReconError::Param {
            field: "pose.reference_view",
            value: pp.reference_view.to_string(),
            expected: "the index of one of the views",
        });
    }
    let unit = spherical_cap(
        1.0,
        prm.template.vertices,
        prm.template.polar_deg.to_radians(),
    );
    let initial = init.place(&unit);
    let mut log = SolveLog::default();
    let mut start = init.clone();
    // The limb sphere needs the views' poses as given; with pose refinement it is left out.
    if prm.placement.limb_start && prm.pose.is_none() {
        if let Ok(ls) = limb_sphere(cams, observed, prm.placement.limb_scale_mm) {
            start.center = ls.center;
            start.radius = ls.radius;
            log.limb_sphere = Some([ls.center.x, ls.center.y, ls.center.z, ls.radius]);
        }
    }
    let rotation_only = prm.placement.rotation_only && log.limb_sphere.is_some();
    let mut on_rim = vec![false; unit.vertex_count()];
    for [a, b] in unit.boundary_edges() {
        on_rim[a as usize] = true;
        on_rim[b as usize] = true;
    }
    let about = rotation_only.then_some(start.center);

    // Stage A: similarity, correspondences recomputed each round. When the sphere is known the
    // axis mirrored through the first view's image plane is probed too: an acetabulum opening
    // forwards and one opening backwards by as much cast nearly the same outline in a frontal
    // view, and only the oblique views tell them apart. The mirrored one replaces the given
    // start when it reprojects clearly better (by the factor MIRROR_SWITCH) and is dropped when
    // clearly worse; in between, the rigid cap cannot tell them apart and both go on to stage B
    // (see `DeformationParams::orientation_rounds`).
    // The similarity stage fixes only a handful of parameters: coarser SRVF curves do.
    let mut coarse = prm.clone();
    let srvf = &mut coarse.correspond.srvf;
    srvf.samples = srvf.samples.min(prm.placement.srvf_samples.max(16));
    srvf.seed_candidates = srvf
        .seed_candidates
        .min(prm.placement.seed_candidates.max(1));
    // Stage A from `mesh` (the template at `placement`), its work added to the log.
    let stage = |mesh: Mesh, placement: Placement, max_rounds: usize, log: &mut SolveLog| {
        let r = similarity_stage(
            mesh, cams, observed, &coarse, kernels, &on_rim, about, max_rounds, placement,
        )?;
        log.similarity_rounds += r.rounds;
        log.gn_iterations += r.iterations;
        Ok::<_, ReconError>(r)
    };
    let mut best = stage(
        start.place(&unit),
        start.clone(),
        prm.placement.rounds,
        &mut log,
    )?;
    // The mirrored orientation when the outlines leave it open: carried through stage B beside
    // the start's (see `DeformationParams::orientation_rounds`).
    let mut rivals: Vec<(&'static str, Mesh, Placement)> = Vec::new();
    if let Some(axis) =
        mirrored_axis(&start, cams).filter(|_| rotation_only && prm.placement.mirrored_start)
    {
        let mirrored = Placement {
            axis,
            ..start.clone()
        };
        // A few rounds tell a clearly wrong orientation from a right one; the mirrored start
        // goes on to convergence unless it is clearly worse.
        let probe = stage(
            mirrored.place(&unit),
            mirrored,
            MIRROR_PROBE_ROUNDS,
            &mut log,
        )?;
        let clear = probe.score < best.score * MIRROR_SWITCH;
        let open = !clear
            && prm.deformation.orientation_rounds > 0
            && probe.score < best.score / MIRROR_SWITCH;
        if clear || open {
            let settled = stage(probe.mesh, probe.placement, prm.placement.rounds, &mut log)?;
            if clear {
                best = settled;
            } else {
                rivals.push(("mirrored", settled.mesh, settled.placement));
            }
        }
    }
    let (mut mesh, mut placement) = (best.mesh, best.placement);
    let sim_lm = similarity_lm(prm);

    // Stage A': with pose refinement, similarity and per-view pose corrections alternate on
    // correspondences recomputed each round, from where stage A settled.
    let pose_center = crate::geom::centroid(&mesh.vertices);
    let mut pose_x = vec![0.0; 6 * cams.len()];
    let mut cams_now: Vec<Camera> = cams.to_vec();
    if let Some(pp) = &prm.pose {
        for _ in 0..prm.placement.rounds {
            let mut obs = weighted_correspondences(
                &mesh,
                &cams_now,
                observed,
                prm,
                kernels,
                "pose refinement",
            )?;
            for o in obs.iter_mut().filter(|o| on_rim[o.vertex as usize]) {
                o.weight *= prm.placement.rim_weight;
            }
            let before = pose_x.clone();
            let it = refine_poses(
                &mesh,
                &pose_center,
                cams,
                &obs,
                pp,
                prm,
                &mut pose_x,
                &mut cams_now,
            )?;
            log.gn_iterations += it;
            // The full similarity here: the limb sphere was fitted with the uncorrected views,
            // so centre and size must follow the corrections.
            let (moved, shift, info) =
                similarity_step(&mesh, &cams_now, &obs, prm, &sim_lm, None, &mut placement)?;
            mesh = moved;
            log.gn_iterations += info.iterations;
            let pose_step = before
                .iter()
                .zip(&pose_x)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            if shift < prm.placement.tol_mm && pose_step < 1e-4 {
                break;
            }
        }
    }

    // Stage B: embedded deformation (with the per-view pose corrections when asked for).
    let ctx = StageB::new(cams, observed, prm, kernels, pose_center);
    let mut run = Deformation::new(mesh, &placement, cams_now, pose_x);
    if !rivals.is_empty() {
        // Each candidate deforms for a few rounds; the one that then reprojects best goes on.
        // Stage A's rigid cap cannot tell mirror-image orientations apart where the acetabulum
        // is not a cap, but the deformed surface of a wrong one cannot follow the oblique views'
        // outlines.
        let k = prm.deformation.orientation_rounds.min(ctx.rounds);
        run.advance(&ctx, k)?;
        log.orientations.push(OrientationTrial {
            source: "stage A",
            rms_px: run.rms_px(),
        });
        for (source, m, p) in rivals {
            let mut other = Deformation::new(m, &p, cams.to_vec(), vec![0.0; 6 * cams.len()]);
            other.advance(&ctx, k)?;
            let rms_px = other.rms_px();
            log.orientations.push(OrientationTrial { source, rms_px });
            if rms_px < run.rms_px() {
                std::mem::swap(&mut run, &mut other);
            }
            log.gn_iterations += other.gn_iterations;
        }
    }
    run.advance(&ctx, ctx.rounds)?;
    log.correspondence_updates += run.rounds;
    log.gn_iterations += run.gn_iterations;
    let Deformation {
        mesh,
        obs,
        converged,
        cams_now,
        pose_x,
        ..
    } = run;
    log.pose_corrections = if prm.pose.is_some() {
        pose_x
            .chunks(6)
            .map(|c| {
                let deg = Vector3::new(c[0], c[1], c[2]).norm().to_degrees();
                let mm = Vector3::new(c[3], c[4], c[5]).norm();
                [deg, mm]
            })
            .collect()
    } else {
        Vec::new()
    };
    log.converged = converged;
    log.reprojection_rms_px = rms_px(&mesh, &cams_now, &obs);
    log.correspondences = obs.len();
    let spheres = cup_spheres(&mesh, &obs)?;
    let (sphere, surface_sphere) = (spheres.cup, spheres.surface);
    let cup = prm.cup.catalogue.nearest(sphere.diameter());
    Ok(Reconstruction {
        initial_contours: contours(&initial, cams, prm, kernels)?,
        final_contours: contours(&mesh, &cams_now, prm, kernels)?,
        mesh,
        initial,
        sphere,
        surface_sphere,
        cup,
        log,
        observations: obs,
        cameras: cams_now,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::XrayGeometry;
    use crate::sim::{phantom, PhantomParams};
    use crate::sim::{simulate_case, NoiseLevel};

    #[test]
    fn a_reference_view_that_is_not_a_view_is_named() {
        let truth = phantom(&PhantomParams::default()).mesh;
        let level = NoiseLevel::level(1).unwrap();
        let sim = simulate_case(&truth, &XrayGeometry::default(), 2.0, &level, 3).unwrap();
        let with_reference = |reference_view| ReconParams {
            pose: Some(crate::solve::PoseParams {
                reference_view,
                ..Default::default()
            }),
            ..Default::default()
        };
        let r = reconstruct(&sim.cameras, &sim.observed, &sim.init, &with_reference(3));
        assert!(
            matches!(
                r,
                Err(ReconError::Param {
                    field: "pose.reference_view",
                    ..
                })
            ),
            "{r:?}"
        );
        // Companion: the last view is a view.
        let ok = reconstruct(&sim.cameras, &sim.observed, &sim.init, &with_reference(2));
        assert!(ok.is_ok(), "{:?}", ok.err());
    }
}
