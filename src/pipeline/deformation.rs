//! Stage B: the embedded deformation graph with its sphere prior, solved on correspondences that
//! stay fixed until the deformation settles and are then recomputed.

use super::correspondences::{check_finite, rms_motion, rms_px, weighted_correspondences};
use super::placement::refine_poses;
use super::{ReconError, ReconParams};
use crate::correspond::Method;
use crate::correspond::Observation;
use crate::engine::Kernels;
use crate::geom::fit_sphere_robust;
use crate::geom::Curve;
use crate::geom::Mesh;
use crate::solve::SpherePrior;
use crate::solve::{
    levenberg_marquardt_cached, DeformationGraph, EdProblem, GraphParams, LmInfo, LmParams,
    SymbolicCache,
};
use crate::template::Placement;
use crate::views::Camera;
use nalgebra::Point3;

/// What every stage-B solve of one reconstruction shares.
pub(super) struct StageB<'a> {
    pub(super) cams: &'a [Camera],
    pub(super) observed: &'a [Vec<Curve>],
    pub(super) prm: &'a ReconParams,
    pub(super) kernels: Kernels<'a>,
    pub(super) pose_center: Point3<f64>,
    /// Correspondence rounds in all, and the solver settings of each round's solve.
    pub(super) rounds: usize,
    pub(super) lm: LmParams,
}

impl<'a> StageB<'a> {
    pub(super) fn new(
        cams: &'a [Camera],
        observed: &'a [Vec<Curve>],
        prm: &'a ReconParams,
        kernels: Kernels<'a>,
        pose_center: Point3<f64>,
    ) -> Self {
        let (rounds, lm) = match prm.method {
            Method::Srvf => (
                prm.deformation.correspondence_updates.max(1),
                prm.lm.clone(),
            ),
            Method::Icp | Method::IcpNormvec => (
                prm.deformation.icp_iterations.max(1),
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
pub(super) struct Deformation {
    pub(super) mesh: Mesh,
    /// The last round's correspondences.
    pub(super) obs: Vec<Observation>,
    /// The sphere prior's sphere: starts as the template's, carried from solve to solve.
    pub(super) prior_sphere: Option<(Point3<f64>, f64)>,
    pub(super) symbolic: SymbolicCache,
    pub(super) converged: bool,
    /// ICP stopped: an iteration moved the surface by less than `icp_tol_mm`.
    pub(super) settled: bool,
    pub(super) rounds: usize,
    pub(super) gn_iterations: usize,
    pub(super) cams_now: Vec<Camera>,
    pub(super) pose_x: Vec<f64>,
}

impl Deformation {
    pub(super) fn new(
        mesh: Mesh,
        placement: &Placement,
        cams_now: Vec<Camera>,
        pose_x: Vec<f64>,
    ) -> Self {
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
    pub(super) fn rms_px(&self) -> f64 {
        rms_px(&self.mesh, &self.cams_now, &self.obs)
    }

    /// Run rounds until `upto` have been run in all (or ICP has settled).
    pub(super) fn advance(&mut self, b: &StageB<'_>, upto: usize) -> Result<(), ReconError> {
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
            let graph = match prm.deformation.coarse_graph_nodes {
                Some(nodes) if self.rounds + 1 < b.rounds => {
                    coarse = GraphParams {
                        nodes,
                        ..prm.deformation.graph.clone()
                    };
                    &coarse
                }
                _ => &prm.deformation.graph,
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
            self.settled = prm.method != Method::Srvf && moved < prm.deformation.icp_tol_mm;
        }
        Ok(())
    }
}

/// One ED solve on fixed correspondences, a graph with `graph`'s settings built on `mesh`: the
/// deformed mesh.
#[allow(clippy::too_many_arguments)]
pub(super) fn ed_solve(
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
    if prm.deformation.sphere_prior > 0.0 && sphere.is_none() {
        *sphere = fit_sphere_robust(&mesh.vertices)
            .ok()
            .map(|s| (s.center_point(), s.radius));
    }
    if prm.deformation.sphere_prior > 0.0 && sphere.is_some() {
        // Every k-th vertex, weighted k-fold: the same energy at a fraction of the rows.
        let n = mesh.vertex_count();
        let k = n
            .div_ceil(prm.deformation.sphere_prior_vertices.max(1))
            .max(1);
        problem.sphere = Some(SpherePrior {
            weight: prm.deformation.sphere_prior * k as f64,
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

/// One more ED round from an already reconstructed mesh: correspondences recomputed once against
/// `observed`, each observation's weight multiplied by `reweight` (the bootstrap's draws), the
/// graph rebuilt on `mesh` and solved. Used to measure how the result moves when the inputs are
/// resampled. Returns the new mesh and the round's correspondences with their robust weights
/// (without the bootstrap's factors), as `Reconstruction::observations` are kept, so that the
/// cup estimator (`cup_spheres`) sees the resample as it sees the result.
pub fn resolve_from(
    mesh: &Mesh,
    cams: &[Camera],
    observed: &[Vec<Curve>],
    prm: &ReconParams,
    kernels: Kernels,
    reweight: &mut dyn FnMut(usize) -> f64,
) -> Result<(Mesh, Vec<Observation>), ReconError> {
    let obs = weighted_correspondences(mesh, cams, observed, prm, kernels, "resampling")?;
    let mut drawn = obs.clone();
    for (k, o) in drawn.iter_mut().enumerate() {
        o.weight *= reweight(k);
    }
    let mut sphere = None;
    let (out, _) = ed_solve(
        mesh,
        &prm.deformation.graph,
        cams,
        &drawn,
        prm,
        &prm.lm,
        kernels,
        "resampling",
        &mut sphere,
        &mut SymbolicCache::default(),
    )?;
    Ok((out, obs))
}
