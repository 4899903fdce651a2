//! The reconstruction's settings and their defaults.

use super::{GuardParams, ReconError, RimPairs};
use crate::contours::ContourSource;
use crate::correspond::{CorrespondParams, Method};
use crate::report::CupCatalogue;
use crate::solve::{EdWeights, GraphParams, LmParams, PoseParams};

/// Everything that tunes a reconstruction, nested per stage, with documented defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct ReconParams {
    /// How correspondences are found (default SRVF).
    pub method: Method,
    /// Stage 3: model contours from alpha shapes (default) or rasterised silhouettes.
    pub contour_source: ContourSource,
    /// Stage 4: the correspondence settings of every method.
    pub correspond: CorrespondParams,
    /// Cauchy robust weights on the reprojection residuals of the ICP baselines' pairs (default
    /// on).
    pub robust: bool,
    /// The same for SRVF's pairs (default off, and on in the paper's protocol): they would
    /// down-weight exactly the stretches where the outline departs most from the model's shape
    /// (see `CorrespondParams::srvf_outlier_k`).
    pub robust_srvf: bool,
    /// The energy's weights; `weights.tangential` is the along-outline weight of the ICP
    /// baselines' pairs (nearest model vertices: along the outline they say little; default
    /// 0.1). The similarity stage and the pose refinement use the along-outline weight too
    /// (`ReconParams::tangential`).
    pub weights: EdWeights,
    /// The along-outline weight of SRVF's pairs, point-to-point correspondences laid along the
    /// whole outline (default 0.3: docs/population.md, "How much the pairs hold along the
    /// outline": the bone-side cups' RMS 1.10-1.14 -> 0.95-0.98 mm against 0.1).
    pub tangential_srvf: f64,
    /// SRVF's pairs that the rim makes (an observed point whose ray passes well inside the
    /// surface's sphere) on model vertices away from the model's border weigh less (default on:
    /// `RimPairs::default()`; None: every pair as the alignment gives it). The template is wider
    /// than the acetabulum, and those pairs crush the surplus onto the outline
    /// (docs/population.md, "Pairs the rim makes": the cartilage shells' cup RMS 1.22 / 1.19 ->
    /// 0.97 / 0.96 mm at seeds 7 / 9, the bone-side acetabula's unchanged). Not for the ICP
    /// baselines' pairs, whose cups it worsens (a tenth of the weight: atlas RMS 1.12 -> 1.33
    /// mm for ICP).
    pub rim_pairs: Option<RimPairs>,
    /// The Levenberg-Marquardt settings of every solve.
    pub lm: LmParams,
    /// Stages 0 and A: the template placed on the limb sphere and turned as a rigid cap.
    pub placement: PlacementParams,
    /// Refine per-view pose corrections with the deformation (default off).
    pub pose: Option<PoseParams>,
    /// Stage B: the embedded deformation graph.
    pub deformation: DeformationParams,
    /// The cup: its catalogue.
    pub cup: CupParams,
    /// The guards a result must pass, and the fallbacks tried when it does not (default on;
    /// None returns any result as it stands).
    pub guards: Option<GuardParams>,
}

/// Stage 0 (the limb sphere) and stage A (the rigid cap turned onto the outlines).
#[derive(Clone, Debug, PartialEq)]
pub struct PlacementParams {
    /// Place the template on the sphere fitted to the outlines' limbs (default on); the start's
    /// axis is kept. See `solve::limb_sphere`. Not used with `pose`: the limbs of views with
    /// wrong poses do not meet on one sphere.
    pub limb_start: bool,
    /// Noise floor of the limb fit, mm at the object (default 0.5).
    pub limb_scale_mm: f64,
    /// Correspondence rounds at most (default 10); stops when a round moves the cap by less
    /// than `tol_mm` (default 0.5 mm: centre shift + radius change + axis turn times the
    /// radius).
    pub rounds: usize,
    /// See `rounds`.
    pub tol_mm: f64,
    /// Damp the rounds where they turn back (default on): each round whose move points
    /// against the last one's halves the share of the solved move taken from then on, so rounds
    /// caught between two caps settle between them instead of running out (see
    /// `pipeline::placement::Damping`).
    pub damped: bool,
    /// Weight of correspondences on the template's rim (default 0.1). A real acetabulum is
    /// shallower than a hemisphere and notched, so its rim outline is not the hemisphere's; the
    /// dome's silhouette is. With the rim at full weight the cap's axis settles sooner but
    /// follows the rim into wrong orientations from poor starts: on m1_lhip and m4_rhip at
    /// levels 3-4 (20 runs each), 4 and 2 runs ended over 1.5 mm MAE with weight 1, 8 and 1
    /// with 0.3, none with 0.1.
    pub rim_weight: f64,
    /// Turn the template about its sphere centre only (default on with `limb_start`): the limb
    /// fit has fixed centre and size.
    pub rotation_only: bool,
    /// With the sphere known, also probe the axis mirrored through the first view's image
    /// plane, and take it when it reprojects clearly better (default on).
    pub mirrored_start: bool,
    /// SRVF samples per curve (default 100; the deformation uses `correspond.srvf.samples`).
    pub srvf_samples: usize,
    /// Closed-curve seeds refined by full DP (default 2; see `SrvfParams::seed_candidates`).
    pub seed_candidates: usize,
    /// Restarts: when a result's model outlines lie farther than this from the observed ones
    /// (`pipeline::outline_distance_px`, an RMS in pixels), the method is run again from
    /// `restart_tilts` starts whose axis is the given one tilted by `restart_tilt_deg`, and the
    /// result whose outlines lie nearest is kept (see `pipeline::reconstruct`). Infinite: never.
    /// With pose refinement (`ReconParams::pose`) the trigger is `REFINED_RESTART_SHARE` of this:
    /// views free to move meet their outlines at least as closely, and a wrong turn of the cap
    /// they cannot undo leaves 3-4 px (docs/population.md, "Restarts with the poses refined").
    pub restart_above_px: f64,
    /// Restarts too when more than this share of the result's triangles face its cup sphere's
    /// centre (`pipeline::folded_share`; default 0.02), whatever its outline distance: a
    /// result folded over at its rim. Of the srvf results from the given starts on the 47
    /// shared acetabula (levels 1, 3, 5 x 3 runs, seed 7), 359 of 423 have no such triangle and
    /// 60 fewer than 2 %; the other four (2.2-7.8 %) include one whose outlines lie 2.4 px off
    /// and whose surface is 1.5 mm off (0.90 mm after the restart). The guards refuse a result
    /// above `GuardParams::max_folded` (10 %). Infinite: never.
    pub restart_above_folded: f64,
    /// How many tilted starts a restart tries (0 to 4: tilts about two perpendicular directions,
    /// each way).
    pub restart_tilts: usize,
    /// How far a restart's start is tilted from the given axis, degrees.
    pub restart_tilt_deg: f64,
    /// Where the method fails outright from the given start and stage 0 did not start it on the
    /// limb sphere (with `pose`, or without `limb_start`), run it again from the given axis on
    /// the limb sphere (default on; `pipeline::Reconstruction`'s log says so).
    pub limb_restart: bool,
}

/// With pose refinement the restarts' trigger is this share of `restart_above_px` (3 px of the
/// default 4).
pub const REFINED_RESTART_SHARE: f64 = 0.75;

impl PlacementParams {
    /// The outline distance (px) above which a result restarts: `restart_above_px`, or with pose
    /// refinement (`refined`) `REFINED_RESTART_SHARE` of it.
    pub fn restart_trigger_px(&self, refined: bool) -> f64 {
        if refined {
            REFINED_RESTART_SHARE * self.restart_above_px
        } else {
            self.restart_above_px
        }
    }
}

impl Default for PlacementParams {
    fn default() -> Self {
        PlacementParams {
            limb_start: true,
            limb_scale_mm: 0.5,
            rounds: 10,
            tol_mm: 0.5,
            damped: true,
            rim_weight: 0.1,
            rotation_only: true,
            mirrored_start: true,
            restart_above_px: 4.0,
            restart_above_folded: 0.02,
            restart_tilts: 4,
            restart_tilt_deg: 25.0,
            limb_restart: true,
            srvf_samples: 100,
            seed_candidates: 2,
        }
    }
}

/// Stage B: the embedded deformation graph with its sphere prior.
#[derive(Clone, Debug, PartialEq)]
pub struct DeformationParams {
    /// The graph's settings.
    pub graph: GraphParams,
    /// For SRVF: correspondence computations (default 3; each followed by GN until the
    /// deformation settles, the graph rebuilt on the latest shape).
    pub correspondence_updates: usize,
    /// For SRVF without pose refinement: stage B ends early after a round, from the second on,
    /// that moved the surface by less than this RMS over its vertices, mm (default 0: every
    /// round of `correspondence_updates` runs). At 1.0 mm the 47 shared acetabula's srvf MAE
    /// falls (the atlas's by 0.006 mm) and one fewer is over issue 16's parity bar, but on 31
    /// acetabula mixed from the atlas, which no setting was chosen on, the MAE stays and the
    /// cup's error grows by 0.03 mm a run (exact size 72 to 68 %, 42 to 39 %): not the
    /// default (docs/population.md, "Stage B's rounds ended where they settle").
    pub settled_round_mm: f64,
    /// For SRVF: each correspondence round's solve stops when an accepted step lowers the
    /// energy by less than this fraction (default 1e-3; `lm.rel_tol`, 1e-5, stays the stop of
    /// every other solve). The 47-mesh sweep's runs end after 112 solver iterations on average
    /// instead of 121, and the issue-18 study takes about 0.92x the time (docs/gpu.md).
    /// Measured against 1e-5 on the 47-mesh srvf sweeps (seeds 7 and 9, paired run by run;
    /// docs/population.md, "Both outlines entered at their leftmost point"): the MAE changes
    /// by at most 0.003 mm in either population (SE 0.001-0.003), the cup's absolute error by
    /// at most 0.03 mm (SE 0.01-0.02).
    pub round_rel_tol: f64,
    /// For the ICP baselines: correspondences recomputed every GN iteration, this many times at
    /// most (default 20) ...
    pub icp_iterations: usize,
    /// ... or until an iteration moves the surface by less than this RMS (default 0.02 mm).
    pub icp_tol_mm: f64,
    /// Rounds both orientations get when stage A does not drop the mirrored one (it may lead,
    /// but a rigid cap's score is not the last word: see `pipeline::place`); 0: the one stage
    /// A ranks first goes on alone (default 1; the ICP baselines' rounds are single
    /// iterations).
    pub orientation_rounds: usize,
    /// Weight per vertex of the sphere prior (0 = off; default 0.3; see `solve::SpherePrior`).
    pub sphere_prior: f64,
    /// About this many vertices (every k-th) carry the sphere prior, weighted k-fold
    /// (default 600).
    pub sphere_prior_vertices: usize,
    /// A learned population shape around the sphere prior's sphere (`prior::ShapePrior`; None:
    /// the bare sphere, the default). Only with `sphere_prior` above 0.
    pub shape_prior: Option<std::sync::Arc<crate::prior::ShapePrior>>,
    /// Coarse-to-fine: the graph has this many nodes in every correspondence round but the
    /// last scheduled one, which uses `graph.nodes` (default None: `graph.nodes` throughout).
    /// For the ICP baselines, whose rounds are single iterations that stop once the surface
    /// settles, that is every round but the 20th. Full studies with 50 (seed 1, the eight
    /// shared acetabula, srvf): mean MAE 0.640 mm against 0.694, cup within 1 mm in 269 of 400
    /// runs against 282 (within 1.5 mm 340 against 333; cup RMS error 1.13 mm both ways). It
    /// stays off because the cup is the clinical answer.
    pub coarse_graph_nodes: Option<usize>,
}

impl Default for DeformationParams {
    fn default() -> Self {
        DeformationParams {
            graph: GraphParams::default(),
            correspondence_updates: 3,
            settled_round_mm: 0.0,
            round_rel_tol: 1e-3,
            icp_iterations: 20,
            icp_tol_mm: 0.02,
            orientation_rounds: 1,
            sphere_prior: 0.3,
            sphere_prior_vertices: 600,
            shape_prior: None,
            coarse_graph_nodes: None,
        }
    }
}

/// The cup.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct CupParams {
    /// The catalogue the nearest size is chosen from (default 40-70 mm in 2 mm steps).
    pub catalogue: CupCatalogue,
    /// Which part of the result the cup sphere is fitted to (default: the observed part).
    pub estimator: CupEstimator,
    /// The estimator's bias, mm: subtracted from the fitted diameter (default 0). Learned with
    /// the calibration from studies on acetabula whose cup is known (`CupCalibration::bias_mm`).
    pub bias_mm: f64,
    /// The share of the fitted diameter's departure from `shrink_to_mm` taken off (0 to
    /// `MAX_SHRINK`; default 0, none): a learned pull toward the training acetabula's cups for
    /// estimates noisier than the population's spread (`CupCalibration::shrink`).
    pub shrink: f64,
    /// The diameter the shrink pulls toward, mm: the training runs' mean fitted diameter (their
    /// mean estimate, so that the bias stays their mean error).
    pub shrink_to_mm: f64,
    /// The result's depth offset, mm (default 0, none): the reconstruction, and the cup with it,
    /// moved this far along its depth axis (`depth_axis`: the views' mean direction, toward the
    /// side the opening faces), where the views do not watch and the template's shape sets the
    /// depth. Learned with the calibration (`CupCalibration::depth_mm`).
    pub depth_mm: f64,
}

/// The largest shrink a cup may be given: a cup that keeps less than a tenth of what its fit says
/// would be the training population's mean, not a measurement.
pub const MAX_SHRINK: f64 = 0.9;

impl CupParams {
    /// The cup diameter reported for a fitted diameter `fitted`: less the bias, and less the
    /// shrink's share of its departure from `shrink_to_mm`.
    pub fn corrected(&self, fitted: f64) -> f64 {
        fitted - self.bias_mm - self.shrink * (fitted - self.shrink_to_mm)
    }

    /// The fitted diameter behind a `corrected` one (the correction undone; a shrink below 1
    /// keeps it one to one).
    pub fn uncorrected(&self, corrected: f64) -> f64 {
        (corrected + self.bias_mm - self.shrink * self.shrink_to_mm) / (1.0 - self.shrink)
    }

    /// The first correction field that cannot be used (field, value, what it must be).
    pub fn invalid_correction(&self) -> Option<(&'static str, f64, &'static str)> {
        if !(self.bias_mm.is_finite() && self.bias_mm.abs() <= 10.0) {
            return Some(("bias_mm", self.bias_mm, "finite, within +-10 mm"));
        }
        if !(self.shrink.is_finite() && (0.0..=MAX_SHRINK).contains(&self.shrink)) {
            return Some(("shrink", self.shrink, "finite, 0 to 0.9"));
        }
        if !(self.shrink_to_mm.is_finite() && (0.0..=200.0).contains(&self.shrink_to_mm)) {
            return Some(("shrink_to_mm", self.shrink_to_mm, "finite, 0 to 200 mm"));
        }
        if !(self.depth_mm.is_finite() && self.depth_mm.abs() <= MAX_DEPTH_MM) {
            return Some(("depth_mm", self.depth_mm, "finite, within +-5 mm"));
        }
        // A shrink pulls toward a cup: toward 0 mm (a file that leaves the field out) every cup
        // would be cut by the shrink's share.
        if self.shrink > 0.0 && !(20.0..=100.0).contains(&self.shrink_to_mm) {
            return Some((
                "shrink_to_mm",
                self.shrink_to_mm,
                "a cup diameter, 20 to 100 mm, where shrink > 0",
            ));
        }
        None
    }
}

/// The largest depth offset a calibration may give (`CupParams::depth_mm`): beyond it the
/// offset would be a guess at the acetabulum, not a correction of where the result sits.
pub const MAX_DEPTH_MM: f64 = 5.0;

/// Which part of the reconstructed surface the cup sphere is fitted to.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CupEstimator {
    /// The vertices the last correspondences tie to the outlines (`observed_part_sphere`).
    #[default]
    ObservedPart,
    /// The vertices in the region most of the population prior's training acetabula cover
    /// (`prior_region_sphere`); needs `deformation.shape_prior`.
    PriorRegion,
}

impl CupEstimator {
    /// Every estimator, in the order the command line lists them.
    pub const ALL: [CupEstimator; 2] = [CupEstimator::ObservedPart, CupEstimator::PriorRegion];

    /// Its name on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            CupEstimator::ObservedPart => "observed-part",
            CupEstimator::PriorRegion => "prior-region",
        }
    }

    /// The estimator of a name (`name`), None when there is none.
    pub fn parse(name: &str) -> Option<CupEstimator> {
        Self::ALL.into_iter().find(|e| e.name() == name)
    }
}

impl Default for ReconParams {
    fn default() -> Self {
        ReconParams {
            method: Method::Srvf,
            contour_source: ContourSource::AlphaShape,
            correspond: CorrespondParams::default(),
            robust: true,
            robust_srvf: false,
            weights: EdWeights::default(),
            tangential_srvf: 0.3,
            rim_pairs: Some(RimPairs::default()),
            lm: LmParams::default(),
            placement: PlacementParams::default(),
            pose: None,
            deformation: DeformationParams::default(),
            cup: CupParams::default(),
            guards: Some(GuardParams::default()),
        }
    }
}

/// Largest energy weight `ReconParams::validate` takes (see there).
pub const MAX_WEIGHT: f64 = 1e6;

/// `ReconParams::validate`'s error: the field, its value as printed, what it must be.
fn bad(field: &'static str, value: impl ToString, expected: &'static str) -> ReconError {
    ReconError::Param {
        field,
        value: crate::io::shown(&value.to_string()),
        expected,
    }
}

impl ReconParams {
    /// The along-outline weight of this method's pairs in every solve that fits them (stage A,
    /// stage B, the pose refinement): `tangential_srvf` for SRVF's, `weights.tangential`
    /// for the ICP baselines'.
    pub fn tangential(&self) -> f64 {
        match self.method {
            Method::Srvf => self.tangential_srvf,
            Method::Icp | Method::IcpNormvec => self.weights.tangential,
        }
    }

    /// Check the settings a reconstruction cannot run with: a non-finite or negative weight,
    /// tolerance or scale, a normal-angle test that is not an angle. `reconstruct` calls it
    /// first; the error names the field and its value. (The standard template's settings are
    /// checked by `Template::cap`.)
    pub fn validate(&self) -> Result<(), ReconError> {
        self.check_weights_and_tolerances()?;
        self.check_cup()?;
        self.check_restarts()?;
        self.check_pairs()
    }

    /// The energy's weights, the solver's and rounds' tolerances, the outlier rules and the
    /// pose refinement's settings.
    fn check_weights_and_tolerances(&self) -> Result<(), ReconError> {
        let non_negative = [
            ("weights.rot", self.weights.rot),
            ("weights.reg", self.weights.reg),
            ("weights.obs", self.weights.obs),
            ("weights.tangential", self.weights.tangential),
            ("tangential_srvf", self.tangential_srvf),
            ("deformation.sphere_prior", self.deformation.sphere_prior),
            ("placement.rim_weight", self.placement.rim_weight),
            ("placement.tol_mm", self.placement.tol_mm),
            ("deformation.icp_tol_mm", self.deformation.icp_tol_mm),
            ("placement.limb_scale_mm", self.placement.limb_scale_mm),
            ("lm.rel_tol", self.lm.rel_tol),
            ("deformation.round_rel_tol", self.deformation.round_rel_tol),
            (
                "deformation.settled_round_mm",
                self.deformation.settled_round_mm,
            ),
            ("correspond.srvf.anchor", self.correspond.srvf.anchor),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(field, v, "finite and >= 0"));
            }
        }
        // The energy's weights (published 1, 10, 100): beyond MAX_WEIGHT a solve loses its
        // precision (w_obs = 1e300 drove the surface behind the camera), and without the
        // outlines' weight the result is the start, whatever the X-rays show.
        for (field, v) in [
            ("weights.rot", self.weights.rot),
            ("weights.reg", self.weights.reg),
            ("weights.obs", self.weights.obs),
        ] {
            if v > MAX_WEIGHT {
                return Err(bad(
                    field,
                    v,
                    "at most 1e6 (the published weights: 1, 10, 100)",
                ));
            }
        }
        if self.weights.obs <= 0.0 {
            return Err(bad(
                "weights.obs",
                self.weights.obs,
                "> 0: with no weight on the outlines the result is the start",
            ));
        }
        for (field, v) in [
            ("lm.lambda0", self.lm.lambda0),
            ("lm.max_lambda", self.lm.max_lambda),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(field, v, "finite and > 0"));
            }
        }
        for (field, k) in [
            ("correspond.outlier_k", Some(self.correspond.outlier_k)),
            ("correspond.srvf_outlier_k", self.correspond.srvf_outlier_k),
        ] {
            if let Some(k) = k.filter(|k| !k.is_finite()) {
                return Err(bad(field, k, "finite"));
            }
        }
        if let Some((field, v)) = self.pose.as_ref().and_then(PoseParams::invalid) {
            return Err(bad(field, v, "finite and > 0"));
        }
        Ok(())
    }

    /// The cup's corrections, catalogue and estimator (the prior-region cup needs a prior).
    fn check_cup(&self) -> Result<(), ReconError> {
        if let Some((field, v, expected)) = self.cup.invalid_correction() {
            let field = match field {
                "bias_mm" => "cup.bias_mm",
                "shrink" => "cup.shrink",
                "depth_mm" => "cup.depth_mm",
                _ => "cup.shrink_to_mm",
            };
            return Err(bad(field, v, expected));
        }
        if !self.cup.catalogue.is_well_formed() {
            return Err(bad(
                "cup.catalogue.sizes_mm",
                format!("{:?}", self.cup.catalogue.sizes_mm),
                "at least one size, each finite and > 0 mm, ascending without repeats (CupCatalogue::parse makes one)",
            ));
        }
        if self.cup.estimator == CupEstimator::PriorRegion
            && (self.deformation.shape_prior.is_none() || self.deformation.sphere_prior <= 0.0)
        {
            return Err(bad(
                "cup.estimator",
                self.cup.estimator.name(),
                "observed-part unless a shape prior is used (deformation.shape_prior and sphere_prior > 0)",
            ));
        }
        Ok(())
    }

    /// The restarts' triggers, number and tilt.
    fn check_restarts(&self) -> Result<(), ReconError> {
        let restart = &self.placement;
        if !(restart.restart_above_px > 0.0) {
            return Err(bad(
                "placement.restart_above_px",
                restart.restart_above_px,
                "> 0 pixels (infinite: no restarts)",
            ));
        }
        if !(restart.restart_above_folded > 0.0) {
            return Err(bad(
                "placement.restart_above_folded",
                restart.restart_above_folded,
                "> 0, a share of the triangles (infinite: never)",
            ));
        }
        if restart.restart_tilts > 4 {
            return Err(bad(
                "placement.restart_tilts",
                restart.restart_tilts,
                "0 to 4",
            ));
        }
        let tilt = restart.restart_tilt_deg;
        if !(tilt > 0.0 && tilt < 180.0) {
            return Err(bad(
                "placement.restart_tilt_deg",
                tilt,
                "in (0, 180) degrees",
            ));
        }
        Ok(())
    }

    /// SRVF's rim pairs and the ICP baselines' normal-angle test.
    fn check_pairs(&self) -> Result<(), ReconError> {
        if let Some(rp) = &self.rim_pairs {
            if !(rp.within > 0.0 && rp.within <= 1.0) {
                return Err(bad(
                    "rim_pairs.within",
                    rp.within,
                    "in (0, 1], a share of the sphere's radius",
                ));
            }
            if !(rp.weight >= 0.0 && rp.weight <= 0.5) {
                return Err(bad(
                    "rim_pairs.weight",
                    rp.weight,
                    "in [0, 0.5] (the observed-part cup leaves a pair of weight 0.5 or less out)",
                ));
            }
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

    /// The restarts fire above 4 px, and above 3 px with the poses refined; a trigger set to
    /// infinity (no restarts) stays infinite either way (the companion).
    #[test]
    fn restarts_fire_sooner_with_the_poses_refined() {
        let p = PlacementParams::default();
        assert_eq!(p.restart_trigger_px(false), 4.0);
        assert_eq!(p.restart_trigger_px(true), 3.0);
        let never = PlacementParams {
            restart_above_px: f64::INFINITY,
            ..p
        };
        assert!(never.restart_trigger_px(true).is_infinite());
        assert!(never.restart_trigger_px(false).is_infinite());
    }

    #[test]
    fn the_defaults_pass_and_each_unusable_setting_is_named() {
        assert!(ReconParams::default().validate().is_ok());
        type Set = Box<dyn Fn(&mut ReconParams)>;
        let cases: Vec<(&str, Set)> = vec![
            (
                "placement.limb_scale_mm",
                Box::new(|p| p.placement.limb_scale_mm = f64::NAN),
            ),
            (
                "placement.limb_scale_mm",
                Box::new(|p| p.placement.limb_scale_mm = -1.0),
            ),
            ("weights.obs", Box::new(|p| p.weights.obs = f64::NAN)),
            ("weights.obs", Box::new(|p| p.weights.obs = 0.0)),
            ("weights.obs", Box::new(|p| p.weights.obs = 1e300)),
            (
                "cup.catalogue.sizes_mm",
                Box::new(|p| p.cup.catalogue.sizes_mm.clear()),
            ),
            (
                "cup.catalogue.sizes_mm",
                Box::new(|p| p.cup.catalogue.sizes_mm = vec![f64::NAN]),
            ),
            (
                "cup.catalogue.sizes_mm",
                Box::new(|p| p.cup.catalogue.sizes_mm = vec![52.0, 50.0]),
            ),
            ("weights.rot", Box::new(|p| p.weights.rot = 2e6)),
            (
                "placement.restart_above_px",
                Box::new(|p| p.placement.restart_above_px = f64::NAN),
            ),
            (
                "placement.restart_above_px",
                Box::new(|p| p.placement.restart_above_px = 0.0),
            ),
            (
                "placement.restart_above_folded",
                Box::new(|p| p.placement.restart_above_folded = f64::NAN),
            ),
            (
                "placement.restart_above_folded",
                Box::new(|p| p.placement.restart_above_folded = 0.0),
            ),
            (
                "placement.restart_tilts",
                Box::new(|p| p.placement.restart_tilts = 5),
            ),
            (
                "placement.restart_tilt_deg",
                Box::new(|p| p.placement.restart_tilt_deg = f64::INFINITY),
            ),
            (
                "correspond.srvf.anchor",
                Box::new(|p| p.correspond.srvf.anchor = -1.0),
            ),
            ("weights.reg", Box::new(|p| p.weights.reg = f64::INFINITY)),
            (
                "deformation.sphere_prior",
                Box::new(|p| p.deformation.sphere_prior = -0.1),
            ),
            ("lm.lambda0", Box::new(|p| p.lm.lambda0 = 0.0)),
            (
                "deformation.round_rel_tol",
                Box::new(|p| p.deformation.round_rel_tol = f64::NAN),
            ),
            (
                "deformation.settled_round_mm",
                Box::new(|p| p.deformation.settled_round_mm = -1.0),
            ),
            ("cup.bias_mm", Box::new(|p| p.cup.bias_mm = f64::NAN)),
            ("cup.bias_mm", Box::new(|p| p.cup.bias_mm = 12.0)),
            ("cup.depth_mm", Box::new(|p| p.cup.depth_mm = f64::NAN)),
            ("cup.depth_mm", Box::new(|p| p.cup.depth_mm = -5.5)),
            ("cup.shrink", Box::new(|p| p.cup.shrink = 0.95)),
            ("cup.shrink", Box::new(|p| p.cup.shrink = -0.1)),
            (
                "cup.shrink_to_mm",
                Box::new(|p| p.cup.shrink_to_mm = f64::NAN),
            ),
            (
                "cup.shrink_to_mm",
                Box::new(|p| {
                    p.cup.shrink = 0.3;
                    p.cup.shrink_to_mm = 0.0;
                }),
            ),
            (
                "cup.estimator",
                Box::new(|p| p.cup.estimator = CupEstimator::PriorRegion),
            ),
            (
                "correspond.normal_angle_deg",
                Box::new(|p| p.correspond.normal_angle_deg = 0.0),
            ),
            (
                "rim_pairs.within",
                Box::new(|p| p.rim_pairs.as_mut().unwrap().within = 0.0),
            ),
            (
                "rim_pairs.within",
                Box::new(|p| p.rim_pairs.as_mut().unwrap().within = f64::NAN),
            ),
            (
                "rim_pairs.weight",
                Box::new(|p| p.rim_pairs.as_mut().unwrap().weight = 0.6),
            ),
            (
                "rim_pairs.weight",
                Box::new(|p| p.rim_pairs.as_mut().unwrap().weight = -0.1),
            ),
            (
                "correspond.outlier_k",
                Box::new(|p| p.correspond.outlier_k = f64::NAN),
            ),
            (
                "correspond.srvf_outlier_k",
                Box::new(|p| p.correspond.srvf_outlier_k = Some(f64::INFINITY)),
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
        let mut edge = ReconParams::default();
        edge.placement.limb_scale_mm = 0.0;
        edge.deformation.sphere_prior = 0.0;
        edge.correspond.srvf.anchor = 0.0;
        edge.placement.restart_above_px = f64::INFINITY;
        edge.placement.restart_tilts = 4;
        (edge.weights.rot, edge.weights.reg) = (0.0, MAX_WEIGHT);
        edge.weights.obs = MAX_WEIGHT;
        edge.rim_pairs = Some(RimPairs {
            within: 1.0,
            weight: 0.5,
            border_rings: 0,
        });
        assert!(edge.validate().is_ok());
        edge.rim_pairs = None;
        assert!(edge.validate().is_ok());
    }
}
