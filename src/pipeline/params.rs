//! The reconstruction's settings and their defaults.

use super::ReconError;
use crate::contours::ContourSource;
use crate::correspond::{CorrespondParams, Method};
use crate::report::CupCatalogue;
use crate::solve::{EdWeights, GraphParams, LmParams, PoseParams};

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

/// Most template vertices a reconstruction takes (the default is 2,500).
pub const MAX_TEMPLATE_VERTICES: usize = 200_000;

impl ReconParams {
    /// Check the settings a reconstruction cannot run with: a non-finite or negative weight,
    /// tolerance or scale, a template cap that is not a cap (polar extent outside (0, 180)
    /// degrees), a template too large to build. `reconstruct` calls it first; the error names
    /// the field and its value.
    pub fn validate(&self) -> Result<(), ReconError> {
        fn bad(field: &'static str, value: impl ToString, expected: &'static str) -> ReconError {
            ReconError::Param {
                field,
                value: value.to_string(),
                expected,
            }
        }
        let non_negative = [
            ("weights.rot", self.weights.rot),
            ("weights.reg", self.weights.reg),
            ("weights.obs", self.weights.obs),
            ("weights.tangential", self.weights.tangential),
            ("sphere_prior", self.sphere_prior),
            ("similarity_rim_weight", self.similarity_rim_weight),
            ("similarity_tol_mm", self.similarity_tol_mm),
            ("icp_tol_mm", self.icp_tol_mm),
            ("limb_scale_mm", self.limb_scale_mm),
            ("lm.rel_tol", self.lm.rel_tol),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(field, v, "finite and >= 0"));
            }
        }
        for (field, v) in [
            ("lm.lambda0", self.lm.lambda0),
            ("lm.max_lambda", self.lm.max_lambda),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(field, v, "finite and > 0"));
            }
        }
        let polar = self.template_polar_deg;
        if !(polar > 0.0 && polar < 180.0) {
            return Err(bad("template_polar_deg", polar, "in (0, 180) degrees"));
        }
        if self.template_vertices > MAX_TEMPLATE_VERTICES {
            return Err(bad(
                "template_vertices",
                self.template_vertices,
                "at most 200,000",
            ));
        }
        if !self.correspond.outlier_k.is_finite() {
            return Err(bad(
                "correspond.outlier_k",
                self.correspond.outlier_k,
                "finite",
            ));
        }
        if let Some((field, v)) = self.pose.as_ref().and_then(PoseParams::invalid) {
            return Err(bad(field, v, "finite and > 0"));
        }
        let angle = self.correspond.normal_angle_deg;
        if !(angle > 0.0 && angle <= 180.0) {
            return Err(bad(
                "correspond.normal_angle_deg",
                angle,
                "in (0, 180] degrees",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_pass_and_each_unusable_setting_is_named() {
        assert!(ReconParams::default().validate().is_ok());
        type Set = Box<dyn Fn(&mut ReconParams)>;
        let cases: Vec<(&str, Set)> = vec![
            ("limb_scale_mm", Box::new(|p| p.limb_scale_mm = f64::NAN)),
            ("limb_scale_mm", Box::new(|p| p.limb_scale_mm = -1.0)),
            (
                "template_polar_deg",
                Box::new(|p| p.template_polar_deg = 360.0),
            ),
            (
                "template_polar_deg",
                Box::new(|p| p.template_polar_deg = 0.0),
            ),
            (
                "template_polar_deg",
                Box::new(|p| p.template_polar_deg = f64::NAN),
            ),
            (
                "template_vertices",
                Box::new(|p| p.template_vertices = usize::MAX),
            ),
            ("weights.obs", Box::new(|p| p.weights.obs = f64::NAN)),
            ("weights.reg", Box::new(|p| p.weights.reg = f64::INFINITY)),
            ("sphere_prior", Box::new(|p| p.sphere_prior = -0.1)),
            ("lm.lambda0", Box::new(|p| p.lm.lambda0 = 0.0)),
            (
                "correspond.normal_angle_deg",
                Box::new(|p| p.correspond.normal_angle_deg = 0.0),
            ),
            (
                "correspond.outlier_k",
                Box::new(|p| p.correspond.outlier_k = f64::NAN),
            ),
            (
                "pose.sigma_mm",
                Box::new(|p| {
                    p.pose = Some(PoseParams {
                        sigma_mm: f64::NAN,
                        ..Default::default()
                    })
                }),
            ),
        ];
        for (field, set) in cases {
            let mut p = ReconParams::default();
            set(&mut p);
            match p.validate() {
                Err(ReconError::Param { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: expected a Param error, got {other:?}"),
            }
        }
        // Companion: settings at the edges of what is allowed pass.
        let edge = ReconParams {
            template_polar_deg: 179.0,
            template_vertices: MAX_TEMPLATE_VERTICES,
            limb_scale_mm: 0.0,
            sphere_prior: 0.0,
            ..Default::default()
        };
        assert!(edge.validate().is_ok());
    }
}
