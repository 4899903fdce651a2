//! Stage 4: 2D-3D correspondences between an observed contour and the model contour of the same
//! view: SRVF elastic registration (ours), or the ICP and ICP-NormVec baselines.

mod icp;
mod observation;
mod outliers;
pub mod srvf;

pub use icp::{curve_normals, icp_matches, icp_normvec_matches};
pub use observation::Observation;
pub use outliers::{mad_inliers, similarity_residuals};

use crate::geom::{resample_closed, resample_open, Curve};

use crate::contours::ModelContour;
use nalgebra::{Point2, Vector2};
use srvf::{CurveKind, SrvfError, SrvfParams};

/// How correspondences are found.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
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
    /// The method's name as the command line and the tables spell it.
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
    /// SRVF registration settings.
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

/// (observed point, model contour point, model contour index, observed normal).
type Pair = (Point2<f64>, Point2<f64>, usize, Vector2<f64>);

/// Every model contour vertex inside the matched part gets the observed point the alignment puts
/// against it: the map from A's samples to arc length along the model is monotone, so it is
/// inverted by interpolation. (Sampling the other way round lets the warp skip parts of the model
/// contour, which are then free to bulge out.)
fn aligned_targets(al: &srvf::Alignment, model: &ModelContour, closed: bool) -> Vec<Pair> {
    let t = al.a_points.len();
    let total = crate::geom::polyline_length(&model.points, true);
    if t < 2 || !(total > 0.0) {
        return Vec::new();
    }
    // Unwrapped model arc length of each observed sample (non-decreasing).
    let mut u = Vec::with_capacity(t);
    let mut order: Vec<usize> = (0..t).collect();
    if al.reversed {
        order.reverse(); // partial matches reported in A's order but aligned the other way
    }
    for &i in &order {
        let mut v = al.b_arclength[i];
        if let Some(&prev) = u.last() {
            while v < prev - 1e-9 {
                v += total;
            }
        }
        u.push(v);
    }
    let pts: Vec<Point2<f64>> = order.iter().map(|&i| al.a_points[i]).collect();
    let normals = curve_normals(&al.a_points, closed);
    let nrm: Vec<Vector2<f64>> = order.iter().map(|&i| normals[i]).collect();
    let (u0, ulast) = (u[0], u[t - 1]);
    let mut cum = 0.0;
    let n = model.points.len();
    let mut out = Vec::new();
    for k in 0..n {
        if k > 0 {
            cum += (model.points[k] - model.points[k - 1]).norm();
        }
        let s = u0 + (cum - u0).rem_euclid(total);
        let (a, b, f) = if s <= ulast {
            let i = u.partition_point(|&x| x <= s).clamp(1, t - 1);
            let span = u[i] - u[i - 1];
            (
                i - 1,
                i,
                if span > 0.0 {
                    (s - u[i - 1]) / span
                } else {
                    0.0
                },
            )
        } else if closed {
            let span = u0 + total - ulast;
            (t - 1, 0, if span > 0.0 { (s - ulast) / span } else { 0.0 })
        } else {
            continue; // outside the matched sub-arc
        };
        let f = f.clamp(0.0, 1.0);
        let target = pts[a] + (pts[b] - pts[a]) * f;
        let normal = (nrm[a] * (1.0 - f) + nrm[b] * f)
            .try_normalize(1e-9)
            .unwrap_or_else(Vector2::zeros);
        out.push((target, model.points[k], k, normal));
    }
    out
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
    let pairs: Vec<Pair> = match method {
        Method::Srvf => {
            let kind = if observed.closed {
                CurveKind::Closed
            } else {
                CurveKind::Partial
            };
            let al = srvf::align(obs_pts, &model.points, kind, &prm.srvf)?;
            aligned_targets(&al, model, observed.closed)
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
            let normals = curve_normals(&samples, observed.closed);
            samples
                .iter()
                .zip(&pos)
                .zip(&normals)
                .filter_map(|((t, m), n)| m.map(|(p, k)| (*t, p, k, *n)))
                .collect()
        }
    };
    let residuals = similarity_residuals(
        &pairs
            .iter()
            .map(|(t, p, _, _)| (*p, *t))
            .collect::<Vec<_>>(),
    );
    let keep = mad_inliers(&residuals, prm.outlier_k);
    Ok(pairs
        .iter()
        .zip(keep)
        .filter(|(_, k)| *k)
        .map(|((t, _, k, n), _)| Observation {
            view,
            vertex: model.vertex_ids[*k],
            target: *t,
            weight: 1.0,
            normal: *n,
        })
        .collect())
}
