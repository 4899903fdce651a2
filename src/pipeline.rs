//! The whole method, stage after stage: place the template on the sphere the outlines' limbs
//! define (stage 0), then alternate model contours -> correspondences -> solve, first turning the
//! cap about that sphere's centre (stage A; the full similarity when there is no limb sphere),
//! then for the deformation graph with its sphere prior (stage B), and fit the cup sphere to the
//! observed part of the result.

use crate::backend::{ContourSource, KernelError, Kernels};
use crate::contours::{Curve, ModelContour};
use crate::correspond::srvf::SrvfError;
use crate::correspond::{correspond, CorrespondParams, Method};
use crate::mesh::Mesh;
use crate::report::{fit_sphere_robust, CupCatalogue, CupSize, Sphere, SphereFitError};
use crate::solve::{
    apply_similarity, corrected_camera, levenberg_marquardt, levenberg_marquardt_cached,
    DeformationGraph, EdProblem, EdWeights, GraphParams, LmInfo, LmParams, Observation, PoseParams,
    PoseProblem, SimilarityProblem, SolveError, SymbolicCache,
};
use crate::solve::{limb_sphere, Problem, SpherePrior};
use crate::template::{spherical_cap, Placement};
use crate::views::Camera;
use nalgebra::{Point3, Vector3};

/// Everything that tunes a reconstruction, with documented defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct ReconParams {
    pub method: Method,
    /// Template resolution (default 2,500 vertices).
    pub template_vertices: usize,
    /// Polar extent of the template cap, degrees (default 90: the hemisphere).
    pub template_polar_deg: f64,
    pub correspond: CorrespondParams,
    pub graph: GraphParams,
    pub weights: EdWeights,
    pub lm: LmParams,
    /// Similarity stage: correspondence rounds at most (default 10); stops when a round moves
    /// the cap by less than `similarity_tol_mm` (default 0.5 mm: centre shift + radius change +
    /// axis turn times the radius).
    pub similarity_rounds: usize,
    pub similarity_tol_mm: f64,
    /// ED stage for SRVF: correspondence computations (default 3; each followed by GN until the
    /// deformation settles, the graph rebuilt on the latest shape).
    pub correspondence_updates: usize,
    /// ED stage for the ICP baselines: correspondences recomputed every GN iteration, this many
    /// times at most (default 20).
    pub icp_iterations: usize,
    /// ... or until an iteration moves the surface by less than this RMS (default 0.02 mm).
    pub icp_tol_mm: f64,
    pub catalogue: CupCatalogue,
    /// Cauchy robust weights on the reprojection residuals (default on).
    pub robust: bool,
    /// Weight of correspondences on the template's rim during the similarity stage (default
    /// 0.1). A real acetabulum is shallower than a hemisphere and notched, so its rim outline is
    /// not the hemisphere's; the dome's silhouette is. With the rim at full weight the cap's axis
    /// settles sooner but follows the rim into wrong orientations from poor starts: on m1_lhip
    /// and m4_rhip at levels 3-4 (20 runs each), 4 and 2 runs ended over 1.5 mm MAE with weight
    /// 1, 8 and 1 with 0.3, none with 0.1.
    pub similarity_rim_weight: f64,
    /// Model contours from alpha shapes (default) or rasterised silhouettes.
    pub contour_source: ContourSource,
    /// Refine per-view pose corrections with the deformation (default off).
    pub pose: Option<PoseParams>,
    /// Stage 0: place the template on the sphere fitted to the outlines' limbs (default on);
    /// the start's axis is kept. See `solve::limb_sphere`. Not used with `pose`: the limbs of
    /// views with wrong poses do not meet on one sphere.
    pub limb_start: bool,
    /// Noise floor of the limb fit, mm at the object (default 0.5).
    pub limb_scale_mm: f64,
    /// Stage B rounds both orientations get when stage A cannot choose between the start's and
    /// the mirrored one (0: keep the start's; default 1; the ICP baselines' rounds are single
    /// iterations).
    pub orientation_rounds: usize,
    /// Similarity stage turns the template about its sphere centre only (default on with
    /// `limb_start`): the limb fit has fixed centre and size.
    pub similarity_rotation_only: bool,
    /// With the sphere known, also probe the axis mirrored through the first view's image plane,
    /// and take it when it reprojects clearly better (default on).
    pub mirrored_start: bool,
    /// Weight per vertex of the sphere prior in the deformation (0 = off; see
    /// `solve::SpherePrior`).
    pub sphere_prior: f64,
    /// About this many vertices (every k-th) carry the sphere prior, weighted k-fold
    /// (default 600).
    pub sphere_prior_vertices: usize,
    /// Coarse-to-fine stage B: the graph has this many nodes in every correspondence round but
    /// the last scheduled one, which uses `graph.nodes` (default None: `graph.nodes`
    /// throughout). For the ICP baselines, whose rounds are single iterations that stop once
    /// the surface settles, that is every round but the 20th. Full studies with 50 (seed 1,
    /// the eight shared acetabula, srvf): mean MAE 0.640 mm against 0.694, cup within 1 mm in
    /// 269 of 400 runs against 282 (within 1.5 mm 340 against 333; cup RMS error 1.13 mm
    /// both ways). It stays off because the cup is the clinical answer.
    pub coarse_graph_nodes: Option<usize>,
    /// SRVF samples per curve during the similarity stage (default 100; the deformation uses
    /// `correspond.srvf.samples`).
    pub similarity_srvf_samples: usize,
    /// Closed-curve seeds refined by full DP during the similarity stage (default 2; see
    /// `SrvfParams::seed_candidates`).
    pub similarity_seed_candidates: usize,
}

impl Default for ReconParams {
    fn default() -> Self {
        ReconParams {
            method: Method::Srvf,
            template_vertices: 2500,
            template_polar_deg: 90.0,
            correspond: CorrespondParams::default(),
            graph: GraphParams::default(),
            weights: EdWeights::default(),
            lm: LmParams::default(),
            similarity_rounds: 10,
            similarity_tol_mm: 0.5,
            correspondence_updates: 3,
            icp_iterations: 20,
            icp_tol_mm: 0.02,
            catalogue: CupCatalogue::default(),
            robust: true,
            similarity_rim_weight: 0.1,
            contour_source: ContourSource::AlphaShape,
            pose: None,
            limb_start: true,
            limb_scale_mm: 0.5,
            similarity_rotation_only: true,
            mirrored_start: true,
            orientation_rounds: 1,
            sphere_prior: 0.3,
            sphere_prior_vertices: 600,
            coarse_graph_nodes: None,
            similarity_srvf_samples: 100,
            similarity_seed_candidates: 2,
        }
    }
}

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
    /// reprojection RMS after `orientation_rounds`; the lowest went on.
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

fn contours(
    mesh: &Mesh,
    cams: &[Camera],
    prm: &ReconParams,
    kernels: Kernels,
) -> Result<Vec<ModelContour>, ReconError> {
    Ok(kernels.contours(mesh, cams, prm.contour_source)?)
}

fn all_correspondences(
    mesh: &Mesh,
    cams: &[Camera],
    observed: &[Vec<Curve>],
    prm: &ReconParams,
    kernels: Kernels,
) -> Result<Vec<Observation>, ReconError> {
    let model = contours(mesh, cams, prm, kernels)?;
    let mut out = Vec::new();
    for (view, curves) in observed.iter().enumerate() {
        for (ci, curve) in curves.iter().enumerate() {
            let o = correspond(prm.method, view, &model[view], curve, &prm.correspond).map_err(
                |source| ReconError::Correspond {
                    view,
                    contour: ci,
                    source,
                },
            )?;
            out.extend(o);
        }
    }
    Ok(out)
}

/// Cauchy weights w = 1 / (1 + (r / c)^2) on the current reprojection residuals, c = 2 robust SDs
/// (1.4826 * median), so that contour parts the template cannot follow (a notch, a shallow rim)
/// pull less than the parts it can.
fn robust_weights(mesh: &Mesh, cams: &[Camera], obs: &mut [Observation]) {
    let r = residuals_px(mesh, cams, obs);
    let mut s = r.clone();
    s.sort_by(f64::total_cmp);
    let c = 2.0 * 1.4826 * s.get(s.len() / 2).copied().unwrap_or(1.0).max(0.5);
    for (o, r) in obs.iter_mut().zip(r) {
        o.weight = if r.is_finite() {
            1.0 / (1.0 + (r / c).powi(2))
        } else {
            0.0
        };
    }
}

/// Reprojection residual of each correspondence in pixels (infinite behind the source).
fn residuals_px(mesh: &Mesh, cams: &[Camera], obs: &[Observation]) -> Vec<f64> {
    obs.iter()
        .map(|o| {
            cams[o.view]
                .project(&mesh.vertices[o.vertex as usize])
                .map(|p| (p - o.target).norm())
                .unwrap_or(f64::INFINITY)
        })
        .collect()
}

fn rms_px(mesh: &Mesh, cams: &[Camera], obs: &[Observation]) -> f64 {
    let s: f64 = residuals_px(mesh, cams, obs).iter().map(|r| r * r).sum();
    (s / obs.len().max(1) as f64).sqrt()
}

fn check_finite(mesh: &Mesh) -> Result<(), ReconError> {
    if let Some(i) = mesh
        .vertices
        .iter()
        .position(|v| !v.coords.iter().all(|c| c.is_finite()))
    {
        return Err(ReconError::Diverged {
            what: format!("vertex {i} is not finite"),
        });
    }
    Ok(())
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
    if cams.len() != observed.len() {
        return Err(ReconError::Mismatch {
            views: cams.len(),
            observed: observed.len(),
        });
    }
    let unit = spherical_cap(
        1.0,
        prm.template_vertices,
        prm.template_polar_deg.to_radians(),
    );
    let initial = init.place(&unit);
    let mut log = SolveLog::default();
    let mut start = init.clone();
    // The limb sphere needs the views' poses as given; with pose refinement it is left out.
    if prm.limb_start && prm.pose.is_none() {
        if let Ok(ls) = limb_sphere(cams, observed, prm.limb_scale_mm) {
            start.center = ls.center;
            start.radius = ls.radius;
            log.limb_sphere = Some([ls.center.x, ls.center.y, ls.center.z, ls.radius]);
        }
    }
    let rotation_only = prm.similarity_rotation_only && log.limb_sphere.is_some();
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
    // (see `orientation_rounds`).
    // The similarity stage fixes only a handful of parameters: coarser SRVF curves do.
    let mut coarse = prm.clone();
    let srvf = &mut coarse.correspond.srvf;
    srvf.samples = srvf.samples.min(prm.similarity_srvf_samples.max(16));
    srvf.seed_candidates = srvf
        .seed_candidates
        .min(prm.similarity_seed_candidates.max(1));
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
        prm.similarity_rounds,
        &mut log,
    )?;
    // The mirrored orientation when the outlines leave it open: carried through stage B beside
    // the start's (see `orientation_rounds`).
    let mut rivals: Vec<(&'static str, Mesh, Placement)> = Vec::new();
    if let Some(axis) = mirrored_axis(&start, cams).filter(|_| rotation_only && prm.mirrored_start)
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
        let open = !clear && prm.orientation_rounds > 0 && probe.score < best.score / MIRROR_SWITCH;
        if clear || open {
            let settled = stage(probe.mesh, probe.placement, prm.similarity_rounds, &mut log)?;
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
    let pose_center = centroid(&mesh.vertices);
    let mut pose_x = vec![0.0; 6 * cams.len()];
    let mut cams_now: Vec<Camera> = cams.to_vec();
    if let Some(pp) = &prm.pose {
        for _ in 0..prm.similarity_rounds {
            let mut obs = weighted_correspondences(
                &mesh,
                &cams_now,
                observed,
                prm,
                kernels,
                "pose refinement",
            )?;
            for o in obs.iter_mut().filter(|o| on_rim[o.vertex as usize]) {
                o.weight *= prm.similarity_rim_weight;
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
            if shift < prm.similarity_tol_mm && pose_step < 1e-4 {
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
        let k = prm.orientation_rounds.min(ctx.rounds);
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
    let surface_sphere = fit_sphere_robust(&mesh.vertices)?;
    let sphere = observed_part_sphere(&mesh, &obs).unwrap_or(surface_sphere);
    let cup = prm.catalogue.nearest(sphere.diameter());
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

/// What every stage-B solve of one reconstruction shares.
struct StageB<'a> {
    cams: &'a [Camera],
    observed: &'a [Vec<Curve>],
    prm: &'a ReconParams,
    kernels: Kernels<'a>,
    pose_center: Point3<f64>,
    /// Correspondence rounds in all, and the solver settings of each round's solve.
    rounds: usize,
    lm: LmParams,
}

impl<'a> StageB<'a> {
    fn new(
        cams: &'a [Camera],
        observed: &'a [Vec<Curve>],
        prm: &'a ReconParams,
        kernels: Kernels<'a>,
        pose_center: Point3<f64>,
    ) -> Self {
        let (rounds, lm) = match prm.method {
            Method::Srvf => (prm.correspondence_updates.max(1), prm.lm.clone()),
            Method::Icp | Method::IcpNormvec => (
                prm.icp_iterations.max(1),
                LmParams {
                    max_iterations: 1,
                    ..prm.lm.clone()
                },
            ),
        };
        StageB {
            cams,
            observed,
            prm,
            kernels,
            pose_center,
            rounds,
            lm,
        }
    }
}

/// One surface going through stage B: its shape, views and what its solves carry over.
struct Deformation {
    mesh: Mesh,
    /// The last round's correspondences.
    obs: Vec<Observation>,
    /// The sphere prior's sphere: starts as the template's, carried from solve to solve.
    prior_sphere: Option<(Point3<f64>, f64)>,
    symbolic: SymbolicCache,
    converged: bool,
    /// ICP stopped: an iteration moved the surface by less than `icp_tol_mm`.
    settled: bool,
    rounds: usize,
    gn_iterations: usize,
    cams_now: Vec<Camera>,
    pose_x: Vec<f64>,
}

impl Deformation {
    fn new(mesh: Mesh, placement: &Placement, cams_now: Vec<Camera>, pose_x: Vec<f64>) -> Self {
        Deformation {
            mesh,
            obs: Vec::new(),
            prior_sphere: Some((placement.center, placement.radius)),
            symbolic: SymbolicCache::default(),
            converged: true,
            settled: false,
            rounds: 0,
            gn_iterations: 0,
            cams_now,
            pose_x,
        }
    }

    /// Reprojection RMS (px) of the last round's correspondences.
    fn rms_px(&self) -> f64 {
        rms_px(&self.mesh, &self.cams_now, &self.obs)
    }

    /// Run rounds until `upto` have been run in all (or ICP has settled).
    fn advance(&mut self, b: &StageB<'_>, upto: usize) -> Result<(), ReconError> {
        let prm = b.prm;
        while self.rounds < upto && !self.settled {
            self.obs = weighted_correspondences(
                &self.mesh,
                &self.cams_now,
                b.observed,
                prm,
                b.kernels,
                "deformation",
            )?;
            if let Some(pp) = &prm.pose {
                // The views' corrections first, on these correspondences and the current
                // shape; then the shape with the corrected views: both lower the one joint
                // energy.
                self.gn_iterations += refine_poses(
                    &self.mesh,
                    &b.pose_center,
                    b.cams,
                    &self.obs,
                    pp,
                    prm,
                    &mut self.pose_x,
                    &mut self.cams_now,
                )?;
            }
            let coarse;
            let graph = match prm.coarse_graph_nodes {
                Some(nodes) if self.rounds + 1 < b.rounds => {
                    coarse = GraphParams {
                        nodes,
                        ..prm.graph.clone()
                    };
                    &coarse
                }
                _ => &prm.graph,
            };
            let (deformed, info) = ed_solve(
                &self.mesh,
                graph,
                &self.cams_now,
                &self.obs,
                prm,
                &b.lm,
                b.kernels,
                "deformation",
                &mut self.prior_sphere,
                &mut self.symbolic,
            )?;
            let moved = rms_motion(&self.mesh, &deformed);
            self.mesh = deformed;
            self.rounds += 1;
            self.gn_iterations += info.iterations;
            self.converged = info.converged || prm.method != Method::Srvf;
            self.settled = prm.method != Method::Srvf && moved < prm.icp_tol_mm;
        }
        Ok(())
    }
}

/// The mirrored start replaces the given one when its score is below this fraction of the given
/// one's, and is dropped when above its inverse; in between both go on to stage B. On the shared
/// acetabula a wrong orientation scores about twice the right one where the cap fits the
/// acetabulum, while on m1_rhip the two mirror images score within about 15 % of each other
/// whichever is right.
const MIRROR_SWITCH: f64 = 0.7;

/// Similarity rounds the mirrored start gets before it is compared.
const MIRROR_PROBE_ROUNDS: usize = 4;

/// What one run of stage A ended with.
struct StageA {
    mesh: Mesh,
    placement: Placement,
    rounds: usize,
    iterations: usize,
    /// Median reprojection residual (px) of the last round's correspondences: ranks starts.
    score: f64,
}

/// LM settings of one similarity solve.
fn similarity_lm(prm: &ReconParams) -> LmParams {
    LmParams {
        max_iterations: 10,
        ..prm.lm.clone()
    }
}

/// The axis of `start` mirrored through the first view's image plane, when it differs.
fn mirrored_axis(start: &Placement, cams: &[Camera]) -> Option<nalgebra::Unit<Vector3<f64>>> {
    let d = cams.first()?.r.matrix().row(2).transpose();
    let a = start.axis.into_inner();
    nalgebra::Unit::try_new(a - 2.0 * a.dot(&d) * d, 1e-9)
        .filter(|m| (m.into_inner() - a).norm() > 1e-3)
}

/// Stage A from `mesh` (the template at `placement`): similarity (or rotation about `about`)
/// solves on correspondences recomputed each round until the cap settles.
#[allow(clippy::too_many_arguments)]
fn similarity_stage(
    mut mesh: Mesh,
    cams: &[Camera],
    observed: &[Vec<Curve>],
    prm: &ReconParams,
    kernels: Kernels,
    on_rim: &[bool],
    about: Option<Point3<f64>>,
    max_rounds: usize,
    mut placement: Placement,
) -> Result<StageA, ReconError> {
    let sim_lm = similarity_lm(prm);
    let (mut rounds, mut iterations) = (0, 0);
    let mut last = Vec::new();
    for _ in 0..max_rounds {
        let mut obs = weighted_correspondences(&mesh, cams, observed, prm, kernels, "similarity")?;
        for o in obs.iter_mut().filter(|o| on_rim[o.vertex as usize]) {
            o.weight *= prm.similarity_rim_weight;
        }
        let (moved, shift, info) =
            similarity_step(&mesh, cams, &obs, prm, &sim_lm, about, &mut placement)?;
        mesh = moved;
        rounds += 1;
        iterations += info.iterations;
        last = obs;
        if shift < prm.similarity_tol_mm {
            break;
        }
    }
    let mut r = residuals_px(&mesh, cams, &last);
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

/// Fewest distinct observed vertices the cup sphere is fitted to.
const MIN_SPHERE_VERTICES: usize = 30;

/// Robust sphere fit to the reconstructed vertices that the correspondences hold to the outlines
/// (robust weight above one half). Away from the outlines the surface is the template's
/// interpolation, which the X-rays never see; there the deformation's smoothing, not the patient,
/// decides the shape, and a whole-surface fit follows it. None when too few such vertices.
pub fn observed_part_sphere(mesh: &Mesh, obs: &[Observation]) -> Option<Sphere> {
    let mut ids: Vec<u32> = obs
        .iter()
        .filter(|o| o.weight > 0.5)
        .map(|o| o.vertex)
        .filter(|&v| (v as usize) < mesh.vertex_count())
        .collect();
    ids.sort_unstable();
    ids.dedup();
    if ids.len() < MIN_SPHERE_VERTICES {
        return None;
    }
    let pts: Vec<Point3<f64>> = ids.iter().map(|&v| mesh.vertices[v as usize]).collect();
    fit_sphere_robust(&pts)
        .ok()
        .filter(|s| s.radius.is_finite())
}

/// RMS distance between two poses of the same mesh's vertices.
fn rms_motion(a: &Mesh, b: &Mesh) -> f64 {
    let n = a.vertex_count().max(1) as f64;
    (a.vertices
        .iter()
        .zip(&b.vertices)
        .map(|(p, q)| (p - q).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt()
}

/// Fewest correspondences a solve accepts.
const MIN_CORRESPONDENCES: usize = 12;

/// Correspondences in every view with their robust weights; too few is an error of `stage`.
fn weighted_correspondences(
    mesh: &Mesh,
    cams: &[Camera],
    observed: &[Vec<Curve>],
    prm: &ReconParams,
    kernels: Kernels,
    stage: &'static str,
) -> Result<Vec<Observation>, ReconError> {
    let mut obs = all_correspondences(mesh, cams, observed, prm, kernels)?;
    if prm.robust {
        robust_weights(mesh, cams, &mut obs);
    }
    if obs.len() < MIN_CORRESPONDENCES {
        return Err(ReconError::TooFewCorrespondences {
            stage,
            count: obs.len(),
        });
    }
    Ok(obs)
}

/// One ED solve on fixed correspondences, a graph with `graph`'s settings built on `mesh`: the
/// deformed mesh.
#[allow(clippy::too_many_arguments)]
fn ed_solve(
    mesh: &Mesh,
    graph: &GraphParams,
    cams: &[Camera],
    obs: &[Observation],
    prm: &ReconParams,
    lm: &LmParams,
    kernels: Kernels,
    stage: &'static str,
    sphere: &mut Option<(Point3<f64>, f64)>,
    symbolic: &mut SymbolicCache,
) -> Result<(Mesh, LmInfo), ReconError> {
    let graph = DeformationGraph::new(mesh, graph);
    let mut problem = EdProblem::new(&graph, cams, obs, prm.weights.clone());
    if prm.sphere_prior > 0.0 && sphere.is_none() {
        *sphere = fit_sphere_robust(&mesh.vertices)
            .ok()
            .map(|s| (s.center_point(), s.radius));
    }
    if prm.sphere_prior > 0.0 && sphere.is_some() {
        // Every k-th vertex, weighted k-fold: the same energy at a fraction of the rows.
        let n = mesh.vertex_count();
        let k = n.div_ceil(prm.sphere_prior_vertices.max(1)).max(1);
        problem.sphere = Some(SpherePrior {
            weight: prm.sphere_prior * k as f64,
            vertices: (0..n as u32).step_by(k).collect(),
        });
    }
    let at = sphere.unwrap_or((Point3::origin(), 0.0));
    let (x, info) = levenberg_marquardt_cached(&problem, problem.start(at), lm, symbolic)
        .map_err(|source| ReconError::Solve { stage, source })?;
    let nodes = graph.node_count() * crate::solve::NODE_PARAMS;
    if problem.sphere.is_some() {
        let b = &x[nodes..];
        *sphere = Some((Point3::new(b[0], b[1], b[2]), b[3]));
    }
    let out = mesh.with_vertices(kernels.deform(&graph, &x[..nodes])?);
    check_finite(&out)?;
    Ok((out, info))
}

/// One similarity solve on fixed correspondences: the moved mesh, and how far the cap moved (mm),
/// measured on its placement (`placement` is moved along): centre shift + radius change + the
/// axis's turn times the radius. Vertex motion would count turns about the cap's own axis, which
/// change nothing and which the correspondences leave free.
fn similarity_step(
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

/// One pose solve on fixed correspondences and shape; updates the corrections and the cameras.
#[allow(clippy::too_many_arguments)]
fn refine_poses(
    mesh: &Mesh,
    center: &Point3<f64>,
    cams: &[Camera],
    obs: &[Observation],
    pp: &PoseParams,
    prm: &ReconParams,
    pose_x: &mut Vec<f64>,
    cams_now: &mut Vec<Camera>,
) -> Result<usize, ReconError> {
    let pose = PoseProblem::new(
        &mesh.vertices,
        *center,
        cams,
        obs,
        pp,
        prm.weights.tangential,
    );
    let (x, info) = levenberg_marquardt(&pose, pose_x.clone(), &prm.lm).map_err(|source| {
        ReconError::Solve {
            stage: "pose refinement",
            source,
        }
    })?;
    if x.iter().any(|v| !v.is_finite()) {
        return Err(ReconError::Diverged {
            what: "a pose correction is not finite".into(),
        });
    }
    *pose_x = x;
    *cams_now = (0..cams.len())
        .map(|k| corrected_camera(&cams[k], center, &pose_x[6 * k..6 * k + 6]))
        .collect();
    Ok(info.iterations)
}

/// Centroid of a point set.
pub fn centroid(p: &[Point3<f64>]) -> Point3<f64> {
    Point3::from(p.iter().map(|v| v.coords).sum::<Vector3<f64>>() / p.len().max(1) as f64)
}

/// One more ED round from an already reconstructed mesh: correspondences recomputed once against
/// `observed`, each observation's weight multiplied by `reweight` (the bootstrap's draws), the
/// graph rebuilt on `mesh` and solved. Used to measure how the result moves when the inputs are
/// resampled; returns the new vertices.
pub fn resolve_from(
    mesh: &Mesh,
    cams: &[Camera],
    observed: &[Vec<Curve>],
    prm: &ReconParams,
    kernels: Kernels,
    reweight: &mut dyn FnMut(usize) -> f64,
) -> Result<Mesh, ReconError> {
    let mut obs = weighted_correspondences(mesh, cams, observed, prm, kernels, "resampling")?;
    for (k, o) in obs.iter_mut().enumerate() {
        o.weight *= reweight(k);
    }
    let mut sphere = None;
    Ok(ed_solve(
        mesh,
        &prm.graph,
        cams,
        &obs,
        prm,
        &prm.lm,
        kernels,
        "resampling",
        &mut sphere,
        &mut SymbolicCache::default(),
    )?
    .0)
}
