//! Model contours, correspondences with their robust weights, and reprojection residuals: what
//! every stage's solves work on.

use super::{ReconError, ReconParams};
use crate::contours::ModelContour;
use crate::correspond::{correspond_on, Method, Observation};
use crate::engine::Kernels;
use crate::geom::{Curve, Mesh};
use crate::views::Camera;

/// What every stage of one reconstruction reads: the views as given, the observed outlines, the
/// settings and the kernels.
#[derive(Clone, Copy)]
pub(super) struct Ctx<'a> {
    pub(super) cams: &'a [Camera],
    pub(super) observed: &'a [Vec<Curve>],
    pub(super) prm: &'a ReconParams,
    pub(super) kernels: Kernels<'a>,
}

impl Ctx<'_> {
    /// The model contour of `mesh` in each of `cams`, entered at its leftmost point as the
    /// observed outlines are (`Curve::entered`): the two closed curves the
    /// correspondences align start at matching places.
    pub(super) fn contours(
        &self,
        mesh: &Mesh,
        cams: &[Camera],
    ) -> Result<Vec<ModelContour>, ReconError> {
        let mut contours = self.kernels.contours(mesh, cams, self.prm.contour_source)?;
        for c in &mut contours {
            c.start_at(crate::geom::fixed_start(&c.points));
        }
        Ok(contours)
    }

    /// Correspondences of the model contours `model` (one per view) with every observed
    /// outline.
    fn all_correspondences(&self, model: &[ModelContour]) -> Result<Vec<Observation>, ReconError> {
        let prm = self.prm;
        let view_pairs = |view: usize, curves: &Vec<Curve>| {
            let mut out = Vec::new();
            for (ci, curve) in curves.iter().enumerate() {
                let o = correspond_on(
                    prm.method,
                    view,
                    &model[view],
                    curve,
                    &prm.correspond,
                    self.kernels.dp(),
                )
                .map_err(|source| ReconError::Correspond {
                    view,
                    contour: ci,
                    source,
                })?;
                out.extend(o);
            }
            Ok::<_, ReconError>(out)
        };
        // The views are independent (the same pairs, in view order, the first error in view
        // order).
        let per_view = self.kernels.map_parts(self.observed, view_pairs);
        let mut out = Vec::new();
        for pairs in per_view {
            out.extend(pairs?);
        }
        Ok(out)
    }

    /// Correspondences in every view with their robust weights; too few is an error of
    /// `stage`.
    pub(super) fn correspondences(
        &self,
        mesh: &Mesh,
        cams: &[Camera],
        stage: &'static str,
    ) -> Result<Vec<Observation>, ReconError> {
        self.correspondences_to(&self.contours(mesh, cams)?, mesh, cams, stage)
    }

    /// `correspondences` with the model contours of `mesh` in `cams` given (`contours`), for
    /// callers that pair one surface with many outlines (the cup's resamples).
    pub(super) fn correspondences_to(
        &self,
        model: &[ModelContour],
        mesh: &Mesh,
        cams: &[Camera],
        stage: &'static str,
    ) -> Result<Vec<Observation>, ReconError> {
        let mut obs = self.all_correspondences(model)?;
        let robust = match self.prm.method {
            Method::Srvf => self.prm.robust_srvf,
            Method::Icp | Method::IcpNormvec => self.prm.robust,
        };
        if robust {
            robust_weights(mesh, cams, &mut obs);
        }
        // SRVF's pairs alone: the baselines' nearest-vertex pairs would lose their hold on the
        // outline (docs/population.md, "Pairs the rim makes").
        if let (Method::Srvf, Some(rp)) = (self.prm.method, &self.prm.rim_pairs) {
            super::rim_pairs::weigh(mesh, cams, &mut obs, rp);
        }
        if obs.len() < MIN_CORRESPONDENCES {
            return Err(ReconError::TooFewCorrespondences {
                stage,
                count: obs.len(),
            });
        }
        Ok(obs)
    }
}

/// Cauchy weights w = 1 / (1 + (r / c)^2) on the current reprojection residuals, c = 2 robust SDs
/// (1.4826 * median), so that nearest-point pairs far off (the ICP baselines' guesses where the
/// model outline is far from the observed one) pull less than the near ones. Not for SRVF's
/// pairs by default (`ReconParams::robust_srvf`).
pub(super) fn robust_weights(mesh: &Mesh, cams: &[Camera], obs: &mut [Observation]) {
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
pub(super) fn residuals_px(mesh: &Mesh, cams: &[Camera], obs: &[Observation]) -> Vec<f64> {
    obs.iter()
        .map(|o| {
            cams[o.view]
                .project(&mesh.vertices[o.vertex as usize])
                .map(|p| (p - o.target).norm())
                .unwrap_or(f64::INFINITY)
        })
        .collect()
}

pub(super) fn rms_px(mesh: &Mesh, cams: &[Camera], obs: &[Observation]) -> f64 {
    let s: f64 = residuals_px(mesh, cams, obs).iter().map(|r| r * r).sum();
    (s / obs.len().max(1) as f64).sqrt()
}

pub(super) fn check_finite(mesh: &Mesh) -> Result<(), ReconError> {
    if let Some(i) = mesh
        .vertices
        .iter()
        .position(|v| !v.coords.iter().all(|c| c.is_finite()))
    {
        return Err(ReconError::NonFiniteVertex { vertex: i });
    }
    Ok(())
}

/// RMS distance between two poses of the same mesh's vertices.
pub(super) fn rms_motion(a: &Mesh, b: &Mesh) -> f64 {
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
pub(super) const MIN_CORRESPONDENCES: usize = 12;
