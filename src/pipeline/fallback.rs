//! Fallbacks: what `reconstruct` tries, in turn, when the method's result fails a guard, and
//! the settings each runs with.

use super::{GuardFailure, ReconParams, Reconstruction};

/// What `reconstruct` tries when the method's result fails a guard, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fallback {
    /// The same correspondences with a ten times stiffer graph (w_rot and w_reg x 10): a result
    /// that followed bad correspondences into a fold or a sheet cannot follow them as far.
    Rigid,
    /// SRVF correspondences without the position term (`SrvfParams::anchor` = 0; for SRVF with
    /// it): the term assumes the model contour starts near its outline, and from a start far
    /// off it pairs points that are near but do not correspond, where the shape distance alone
    /// still finds the right ones.
    ShapeOnly,
    /// ICP-NormVec correspondences from the same start (for SRVF and plain ICP; ICP-NormVec
    /// itself goes on to `Rigid`): closest points with a normal test cannot pull a vertex
    /// across the outline. A baseline that borrows it is only made harder to beat.
    IcpNormvec,
    /// The same method with the views' poses refined (`solve::PoseParams::default()`, as
    /// `--refine-poses`; for a run without it): where the result's outlines stay far from the
    /// annotations (`GuardFailure::Outlines`) no shape meets every view as its pose says, and
    /// a pose off by a few millimetres is the usual cause.
    RefinePoses,
}

/// The fallbacks, in the order they are tried after any guard but `Outlines` and `Rough` (see
/// `Fallback::order`).
pub const FALLBACKS: [Fallback; 4] = [
    Fallback::ShapeOnly,
    Fallback::IcpNormvec,
    Fallback::Rigid,
    Fallback::RefinePoses,
];

impl Fallback {
    /// The fallbacks in the order they are tried after `failure`: for outlines the result does
    /// not meet, the poses refined first (the other fallbacks change the correspondences or the
    /// graph, which cannot make views whose poses disagree agree); for a crumpled surface
    /// (`GuardFailure::Rough`, its outlines met) not the poses at all: refining them bends the
    /// views to annotations given to the wrong view (the phantom with two views' annotations
    /// swapped: the refinement turned a third view by 6 degrees and passed); for rims left open
    /// (`GuardFailure::OpenRims`) none: the annotations' gaps are the cause, which no other
    /// correspondences, graph or poses fill, and results the fallbacks bent past the guard were
    /// still off (docs/population.md, "Rims annotated over less of their length"); else
    /// `FALLBACKS`' order, the poses last.
    pub fn order(failure: &GuardFailure) -> Vec<Fallback> {
        let mut order = FALLBACKS.to_vec();
        match failure {
            // RefinePoses is FALLBACKS' last.
            GuardFailure::Outlines { .. } => order.rotate_right(1),
            GuardFailure::Rough { .. } => order.retain(|&f| f != Fallback::RefinePoses),
            GuardFailure::OpenRims { .. } => order.clear(),
            _ => {}
        }
        order
    }

    /// Its name in logs and tables.
    pub fn name(self) -> &'static str {
        match self {
            Fallback::RefinePoses => "refine-poses",
            Fallback::Rigid => "rigid",
            Fallback::ShapeOnly => "srvf-shape",
            Fallback::IcpNormvec => "icp-normvec",
        }
    }

    /// The settings it runs with, or None where it does not apply.
    pub fn params(self, prm: &ReconParams) -> Option<ReconParams> {
        let mut p = prm.clone();
        match self {
            Fallback::Rigid => {
                p.weights.rot *= 10.0;
                p.weights.reg *= 10.0;
            }
            Fallback::ShapeOnly => {
                if prm.method != crate::correspond::Method::Srvf
                    || prm.correspond.srvf.anchor <= 0.0
                {
                    return None;
                }
                p.correspond.srvf.anchor = 0.0;
            }
            Fallback::IcpNormvec => {
                if prm.method == crate::correspond::Method::IcpNormvec {
                    return None;
                }
                p.method = crate::correspond::Method::IcpNormvec;
            }
            Fallback::RefinePoses => {
                if prm.pose.is_some() {
                    return None;
                }
                p.pose = Some(crate::solve::PoseParams::default());
            }
        }
        Some(p)
    }
}

/// The settings `rec` was solved with: `prm`, or the fallback's settings when its log names one
/// (what its resamples must be solved with too; see `cup_report`).
pub fn params_used(rec: &Reconstruction, prm: &ReconParams) -> ReconParams {
    FALLBACKS
        .iter()
        .find(|f| rec.log.fallback == Some(f.name()))
        .and_then(|f| f.params(prm))
        .unwrap_or_else(|| prm.clone())
}
