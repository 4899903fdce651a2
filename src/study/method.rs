//! The study's methods: a correspondence method, run either through all of our stages or as
//! the seed paper ran it.

use crate::correspond::Method;
use crate::pipeline::ReconParams;

/// One method of the study. `Srvf`, `Icp` and `IcpNormvec` go through every stage of
/// `pipeline::reconstruct` (the limb-sphere placement, the similarity stage, the orientation
/// comparison and the deformation with its sphere prior), each stage on the method's own
/// correspondences. The `*Paper` methods follow the paper's protocol: the deformation graph
/// alone, solved from the perturbed template with the energy w_rot E_rot + w_reg E_reg +
/// w_obs E_obs and nothing else.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum StudyMethod {
    /// SRVF, through every stage.
    Srvf,
    /// ICP, through every stage.
    Icp,
    /// ICP-NormVec, through every stage.
    IcpNormvec,
    /// SRVF, the paper's protocol (the deformation alone).
    SrvfPaper,
    /// ICP, the paper's protocol.
    IcpPaper,
    /// ICP-NormVec, the paper's protocol.
    IcpNormvecPaper,
}

impl StudyMethod {
    /// Every method, in canonical order.
    pub const ALL: [StudyMethod; 6] = [
        StudyMethod::Srvf,
        StudyMethod::Icp,
        StudyMethod::IcpNormvec,
        StudyMethod::SrvfPaper,
        StudyMethod::IcpPaper,
        StudyMethod::IcpNormvecPaper,
    ];

    /// The name used on the command line and in runs.csv.
    pub fn name(self) -> &'static str {
        match self {
            StudyMethod::Srvf => "srvf",
            StudyMethod::Icp => "icp",
            StudyMethod::IcpNormvec => "icp-normvec",
            StudyMethod::SrvfPaper => "srvf-paper",
            StudyMethod::IcpPaper => "icp-paper",
            StudyMethod::IcpNormvecPaper => "icp-normvec-paper",
        }
    }

    /// The method called `name` (exactly, lower case).
    pub fn from_name(name: &str) -> Option<StudyMethod> {
        StudyMethod::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Its correspondences.
    pub fn correspondence(self) -> Method {
        match self {
            StudyMethod::Srvf | StudyMethod::SrvfPaper => Method::Srvf,
            StudyMethod::Icp | StudyMethod::IcpPaper => Method::Icp,
            StudyMethod::IcpNormvec | StudyMethod::IcpNormvecPaper => Method::IcpNormvec,
        }
    }

    /// Whether it follows the paper's protocol.
    pub fn paper(self) -> bool {
        matches!(
            self,
            StudyMethod::SrvfPaper | StudyMethod::IcpPaper | StudyMethod::IcpNormvecPaper
        )
    }

    /// The reconstruction settings of a run: `base` with this method's correspondences, and for
    /// the paper's protocol every stage before the deformation switched off, as well as the
    /// sphere prior, and SRVF's pairs treated as the baselines' (outlier rule, robust weights).
    pub fn params(self, base: &ReconParams) -> ReconParams {
        let mut p = ReconParams {
            method: self.correspondence(),
            ..base.clone()
        };
        if self.paper() {
            p.placement.limb_start = false;
            p.placement.rounds = 0;
            p.placement.mirrored_start = false;
            p.deformation.orientation_rounds = 0;
            p.deformation.sphere_prior = 0.0;
            // The paper rejects outliers among SRVF's pairs as among the baselines'.
            p.correspond.srvf_outlier_k = Some(p.correspond.outlier_k);
            p.robust_srvf = p.robust;
            // The paper's pairs are the alignment's, as published.
            p.rim_pairs = None;
        }
        p
    }
}

impl From<Method> for StudyMethod {
    fn from(m: Method) -> Self {
        match m {
            Method::Srvf => StudyMethod::Srvf,
            Method::Icp => StudyMethod::Icp,
            Method::IcpNormvec => StudyMethod::IcpNormvec,
        }
    }
}

impl serde::Serialize for StudyMethod {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> serde::Deserialize<'de> for StudyMethod {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        StudyMethod::from_name(&name).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "column \"method\": {name:?} is not a method (srvf, icp, icp-normvec, or one \
                     of them -paper)"
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_the_paper_protocol_leaves_only_the_deformation() {
        for m in StudyMethod::ALL {
            assert_eq!(StudyMethod::from_name(m.name()), Some(m));
            assert_eq!(
                StudyMethod::from(m.correspondence()).correspondence(),
                m.correspondence()
            );
        }
        assert_eq!(StudyMethod::from_name("ICP"), None);
        assert_eq!(StudyMethod::from_name("icp-papers"), None);
        let base = ReconParams::default();
        let ours = StudyMethod::Icp.params(&base);
        assert_eq!(
            ours,
            ReconParams {
                method: Method::Icp,
                ..base.clone()
            }
        );
        let paper = StudyMethod::IcpPaper.params(&base);
        assert_eq!(paper.method, Method::Icp);
        assert!(!paper.placement.limb_start && !paper.placement.mirrored_start);
        assert_eq!(
            (paper.placement.rounds, paper.deformation.orientation_rounds),
            (0, 0)
        );
        assert_eq!(paper.deformation.sphere_prior, 0.0);
        assert_eq!(paper.weights, base.weights);
        assert_eq!(paper.deformation.graph, base.deformation.graph);
    }
}
