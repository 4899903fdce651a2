//! Stage 4: 2D-3D correspondences between an observed contour and the model contour of the same
//! view: SRVF elastic registration (ours), or the ICP and ICP-NormVec baselines.

mod icp;
mod outliers;
pub mod srvf;

pub use icp::{icp_matches, icp_normvec_matches};
pub use outliers::{mad_inliers, similarity_residuals};

use crate::contours::{resample_closed, resample_open, Curve, ModelContour};
use crate::solve::Observation;
use srvf::{CurveKind, SrvfError, SrvfParams};

/// How correspondences are found.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// SRVF elastic registration of the whole contours (the method).
    Srvf,
    /// Closest Euclidean point on the projected model contour.
    Icp,
    /// Nearest neighbour with a contour-normal angle test for outlier rejection.
    IcpNormvec,
}

impl Method {
    pub fn name(&self) -> &'static str {
        match self {
            Method::Srvf => "srvf",
            Method::Icp => "icp",
            Method::IcpNormvec => "icp-normvec",
        }
    }
}

/// Correspondence parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct CorrespondParams {
    pub srvf: SrvfParams,
    /// Outliers: aligned residual above median + k * 1.4826 * MAD (default k = 3).
    pub outlier_k: f64,
    /// ICP-NormVec: largest angle between contour normals, degrees (default 30).
    pub normal_angle_deg: f64,
}

impl Default for CorrespondParams {
    fn default() -> Self {
        CorrespondParams {
            srvf: SrvfParams::default(),
            outlier_k: 3.0,
            normal_angle_deg: 30.0,
        }
    }
}

/// Correspondences in one view.
pub fn correspond(
    method: Method,
    view: usize,
    model: &ModelContour,
    observed: &Curve,
    prm: &CorrespondParams,
) -> Result<Vec<Observation>, SrvfError> {
    let obs_pts = observed.points.as_slice();
    let (targets, model_pos): (
        Vec<nalgebra::Point2<f64>>,
        Vec<Option<(nalgebra::Point2<f64>, usize)>>,
    ) = match method {
        Method::Srvf => {
            let kind = if observed.closed {
                CurveKind::Closed
            } else {
                CurveKind::Partial
            };
            let al = srvf::align(obs_pts, &model.points, kind, &prm.srvf)?;
            let n = model.points.len();
            let pos = al
                .b_points
                .iter()
                .zip(&al.b_index)
                .map(|(p, idx)| Some((*p, idx.round() as usize % n)))
                .collect();
            (al.a_points, pos)
        }
        Method::Icp | Method::IcpNormvec => {
            let t = prm.srvf.samples.max(8);
            let samples = if observed.closed {
                resample_closed(obs_pts, t).0
            } else {
                resample_open(obs_pts, t).0
            };
            let pos = if method == Method::Icp {
                icp_matches(&samples, observed.closed, &model.points)
            } else {
                icp_normvec_matches(
                    &samples,
                    observed.closed,
                    &model.points,
                    prm.normal_angle_deg,
                )
            };
            (samples, pos)
        }
    };
    let pairs: Vec<(nalgebra::Point2<f64>, nalgebra::Point2<f64>, usize)> = targets
        .iter()
        .zip(&model_pos)
        .filter_map(|(t, m)| m.map(|(p, k)| (*t, p, k)))
        .collect();
    let residuals =
        similarity_residuals(&pairs.iter().map(|(t, p, _)| (*p, *t)).collect::<Vec<_>>());
    let keep = mad_inliers(&residuals, prm.outlier_k);
    Ok(pairs
        .iter()
        .zip(keep)
        .filter(|(_, k)| *k)
        .map(|((t, _, k), _)| Observation {
            view,
            vertex: model.vertex_ids[*k],
            target: *t,
            weight: 1.0,
        })
        .collect())
}
