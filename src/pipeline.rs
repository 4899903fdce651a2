//! The whole method, stage after stage: place the template, then alternate model contours ->
//! correspondences -> solve, first for a similarity, then for the deformation graph, and fit the
//! cup sphere to the result.

use crate::backend::{ContourSource, KernelError, Kernels};
use crate::contours::{Curve, ModelContour};
use crate::correspond::srvf::SrvfError;
use crate::correspond::{correspond, CorrespondParams, Method};
use crate::mesh::Mesh;
use crate::report::{fit_sphere_robust, CupCatalogue, CupSize, Sphere, SphereFitError};
use crate::solve::{
    apply_similarity, corrected_camera, levenberg_marquardt, DeformationGraph, EdProblem,
    EdWeights, GraphParams, LmInfo, LmParams, Observation, PoseParams, PoseProblem,
    SimilarityProblem, SolveError,
};
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
    /// Similarity stage: correspondence rounds at most (default 15); stops when a round moves
    /// the template by less than `similarity_tol_mm` (default 0.05 mm RMS).
    pub similarity_rounds: usize,
    pub similarity_tol_mm: f64,
    /// ED stage for SRVF: correspondence computations (default 3; each followed by GN until the
    /// deformation settles, the graph rebuilt on the latest shape).
    pub correspondence_updates: usize,
    /// ED stage for the ICP baselines: correspondences recomputed every GN iteration, this many
    /// times at most (default 20).
    pub icp_iterations: usize,
    pub catalogue: CupCatalogue,
    /// Cauchy robust weights on the reprojection residuals (default on).
    pub robust: bool,
    /// Weight of correspondences on the template's rim during the similarity stage (default
    /// 0.1). A real acetabulum is shallower than a hemisphere and notched, so its rim outline is
    /// not the hemisphere's; the dome's silhouette (a sphere's limb) fixes centre and size.
    pub similarity_rim_weight: f64,
    /// Model contours from alpha shapes (default) or rasterised silhouettes.
    pub contour_source: ContourSource,
    /// Refine per-view pose corrections with the deformation (default off).
    pub pose: Option<PoseParams>,
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
            similarity_rounds: 15,
            similarity_tol_mm: 0.05,
            correspondence_updates: 3,
            icp_iterations: 20,
            catalogue: CupCatalogue::default(),
            robust: true,
            similarity_rim_weight: 0.1,
            contour_source: ContourSource::AlphaShape,
            pose: None,
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
}

/// The result.
#[derive(Clone, Debug)]
pub struct Reconstruction {
    pub mesh: Mesh,
    pub initial: Mesh,
    pub sphere: Sphere,
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
    let initial = init.place(&spherical_cap(
        1.0,
        prm.template_vertices,
        prm.template_polar_deg.to_radians(),
    ));
    let mut mesh = initial.clone();
    let mut log = SolveLog::default();

    // Stage A: similarity, correspondences recomputed each round.
    let sim_lm = LmParams {
        max_iterations: 10,
        ..prm.lm.clone()
    };
    let mut on_rim = vec![false; mesh.vertex_count()];
    for [a, b] in mesh.boundary_edges() {
        on_rim[a as usize] = true;
        on_rim[b as usize] = true;
    }
    for _ in 0..prm.similarity_rounds {
        let mut obs = weighted_correspondences(&mesh, cams, observed, prm, kernels, "similarity")?;
        for o in obs.iter_mut().filter(|o| on_rim[o.vertex as usize]) {
            o.weight *= prm.similarity_rim_weight;
        }
        let (moved, shift, info) = similarity_step(&mesh, cams, &obs, prm, &sim_lm)?;
        mesh = moved;
        log.similarity_rounds += 1;
        log.gn_iterations += info.iterations;
        if shift < prm.similarity_tol_mm {
            break;
        }
    }

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
            let (moved, shift, info) = similarity_step(&mesh, &cams_now, &obs, prm, &sim_lm)?;
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
    let mut obs = Vec::new();
    let mut converged = true;
    for _ in 0..rounds {
        obs = weighted_correspondences(&mesh, &cams_now, observed, prm, kernels, "deformation")?;
        if let Some(pp) = &prm.pose {
            // The views' corrections first, on these correspondences and the current shape;
            // then the shape with the corrected views: both lower the one joint energy.
            log.gn_iterations += refine_poses(
                &mesh,
                &pose_center,
                cams,
                &obs,
                pp,
                prm,
                &mut pose_x,
                &mut cams_now,
            )?;
        }
        let (deformed, info) = ed_solve(&mesh, &cams_now, &obs, prm, &lm, kernels, "deformation")?;
        mesh = deformed;
        log.correspondence_updates += 1;
        log.gn_iterations += info.iterations;
        converged = info.converged || prm.method != Method::Srvf;
    }
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
    let sphere = fit_sphere_robust(&mesh.vertices)?;
    let cup = prm.catalogue.nearest(sphere.diameter());
    Ok(Reconstruction {
        initial_contours: contours(&initial, cams, prm, kernels)?,
        final_contours: contours(&mesh, &cams_now, prm, kernels)?,
        mesh,
        initial,
        sphere,
        cup,
        log,
        observations: obs,
        cameras: cams_now,
    })
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

/// One ED solve on fixed correspondences, the graph built on `mesh`: the deformed mesh.
fn ed_solve(
    mesh: &Mesh,
    cams: &[Camera],
    obs: &[Observation],
    prm: &ReconParams,
    lm: &LmParams,
    kernels: Kernels,
    stage: &'static str,
) -> Result<(Mesh, LmInfo), ReconError> {
    let graph = DeformationGraph::new(mesh, &prm.graph);
    let problem = EdProblem::new(&graph, cams, obs, prm.weights.clone());
    let (x, info) = levenberg_marquardt(&problem, graph.identity(), lm)
        .map_err(|source| ReconError::Solve { stage, source })?;
    let out = mesh.with_vertices(kernels.deform(&graph, &x)?);
    check_finite(&out)?;
    Ok((out, info))
}

/// One similarity solve on fixed correspondences: the moved mesh and its RMS shift (mm).
fn similarity_step(
    mesh: &Mesh,
    cams: &[Camera],
    obs: &[Observation],
    prm: &ReconParams,
    lm: &LmParams,
) -> Result<(Mesh, f64, LmInfo), ReconError> {
    let mut problem = SimilarityProblem::new(&mesh.vertices, cams, obs);
    problem.tangential = prm.weights.tangential;
    let (x, info) =
        levenberg_marquardt(&problem, vec![0.0; 7], lm).map_err(|source| ReconError::Solve {
            stage: "similarity",
            source,
        })?;
    let moved = apply_similarity(&x, &problem.center, &mesh.vertices);
    let shift = (moved
        .iter()
        .zip(&mesh.vertices)
        .map(|(a, b)| (a - b).norm_squared())
        .sum::<f64>()
        / moved.len().max(1) as f64)
        .sqrt();
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
    Ok(ed_solve(mesh, cams, &obs, prm, &prm.lm, kernels, "resampling")?.0)
}
