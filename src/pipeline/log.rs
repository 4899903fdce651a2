//! What the solver did (`SolveLog`: rounds, outline distances, restarts, fallbacks, pose
//! corrections), and the lines it has for the user about a result the views do not all agree on.

use super::fallback::Fallback;
use super::guards::{odd_view, view_label, GuardFailure};
use super::{cup, restart, ReconParams};
use nalgebra::Point3;

/// What the solver did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SolveLog {
    /// Stage A rounds (correspondences recomputed each).
    pub similarity_rounds: usize,
    /// Stage B correspondence rounds.
    pub correspondence_updates: usize,
    /// Gauss-Newton (LM) iterations over all solves.
    pub gn_iterations: usize,
    /// The last solve converged (for the ICP baselines: always).
    pub converged: bool,
    /// Final reprojection RMS over the last correspondences, pixels.
    pub reprojection_rms_px: f64,
    /// Correspondences of the last round.
    pub correspondences: usize,
    /// Per view, the fit's model outline against the observed one: RMS distance, pixels, both
    /// ways for a closed outline (`restart::outline_distance_px` of that view alone), measured
    /// before a calibration's depth offset moves the result (`depth_moved_mm`). A view far
    /// worse than the others has a wrong pose or annotation (`view_note`).
    pub outline_px_per_view: Vec<f64>,
    /// The same over all views at once (`restart::outline_distance_px`): how far the fit's
    /// outlines are from the annotations, whatever point each annotation starts at. What the
    /// restarts and the outline guard judge, and the uncertainty's contour noise
    /// (`UncertaintyParams::noise_px`, when not given).
    pub outline_px: f64,
    /// Per view, the share of the fit's model outline that runs along the annotation
    /// (`guards::annotated_shares`), before a depth offset moves the result: 1 where the
    /// annotation goes all the way round, less where it leaves part of the rim open.
    pub annotated_share_per_view: Vec<f64>,
    /// The largest of them: what the open-rims guard judges (`GuardParams::min_annotated_share`).
    pub annotated_share: f64,
    /// Per view, the size of the pose correction found (degrees, mm); empty without refinement.
    pub pose_corrections: Vec<[f64; 2]>,
    /// The sphere fitted to the outlines' limbs (centre x, y, z and radius, mm), when used.
    pub limb_sphere: Option<[f64; 4]>,
    /// The orientations stage B compared (none when stage A's was the only one), with their
    /// reprojection RMS after `deformation.orientation_rounds`; the lowest went on.
    pub orientations: Vec<OrientationTrial>,
    /// The restarts tried (see `PlacementParams::restart_above_px`): the given start's result
    /// first, then each tilted start's, with their outline distance (`outline_distance_px`, in
    /// `rms_px`); empty when the first result followed the outlines closely enough and passed
    /// the guards. The nearest that the guards pass was kept.
    pub restarts: Vec<OrientationTrial>,
    /// Which of `restarts` gave this result ("given" or a tilt); None when there were none.
    pub restart: Option<&'static str>,
    /// Why the tilted starts were tried; None when they were not.
    pub restart_cause: Option<RestartCause>,
    /// The fallback that gave this result ("srvf-shape", "icp-normvec", "rigid" or
    /// "refine-poses"; see `Fallback`), when the method as asked for did not pass the guards;
    /// None when it did.
    pub fallback: Option<&'static str>,
    /// What the method as asked for failed, when a fallback was taken.
    pub guard: Option<GuardFailure>,
    /// The sphere prior's sphere after the last solve (centre x, y, z and radius, mm): with a
    /// population prior (`DeformationParams::shape_prior`), the sphere the learned shape is
    /// laid around; None without the sphere prior.
    pub prior_sphere: Option<[f64; 4]>,
    /// The result's depth axis (`depth_axis`, x, y, z; length 1 where the opening clearly faces
    /// one side of the views, shorter as it turns across them); None where it has none.
    pub depth_axis: Option<[f64; 3]>,
    /// How far the result was moved along that axis (`CupParams::depth_mm`), mm; 0 when not.
    pub depth_moved_mm: f64,
}

/// A second view whose pose correction is this share of the largest or more moved "as far"
/// (`SolveLog::pose_note`).
const SHARED_CORRECTION: f64 = 0.5;

impl SolveLog {
    /// The population prior's region for the cup estimator: the prior of `prm` and the sphere
    /// prior's centre at the end of the solve; None without a prior.
    pub fn prior_region<'a>(&self, prm: &'a ReconParams) -> Option<cup::PriorRegion<'a>> {
        let prior = prm.deformation.shape_prior.as_deref()?;
        let [x, y, z, _] = self.prior_sphere?;
        Some((prior, Point3::new(x, y, z)))
    }

    /// A line for the user when one view's outline is met much worse than the others' (more
    /// than `VIEW_NOTE_MIN_PX` and `VIEW_NOTE_RATIO` times the worst of the rest): the views do
    /// not agree on one shape, and the usual cause is that view's pose (try `--refine-poses`)
    /// or its annotation. `names` are the views' names. None when the views agree.
    /// When the result is the `refine-poses` fallback's, the line names instead the view whose
    /// pose moved most (the views agree only with that correction).
    pub fn view_note(&self, names: &[String]) -> Option<String> {
        if let Some(note) = self.pose_note(names) {
            return Some(note);
        }
        let (worst, px, rest) = odd_view(&self.outline_px_per_view)?;
        Some(format!(
            "{} is {px:.1} px from its outline, the others at most {rest:.1} px: \
             the views do not agree on one shape; check that view's pose (--refine-poses \
             corrects small errors) and its annotation",
            view_label(names, worst)
        ))
    }

    /// The line for a result of the `refine-poses` fallback (`Fallback::RefinePoses`): how far
    /// the method's own result lay from the outlines, and the view whose pose the refinement
    /// moved most (by its shift, mm); None for any other result. Where another view moved
    /// nearly as far (`SHARED_CORRECTION` of the most or more), the line names both and says
    /// that the outlines cannot tell which pose is off: the first view holds the frame and the
    /// object's position is free, so a pose or principal point off in one view is taken up by
    /// moving the others, most evenly where the error lies across the axis the views turn
    /// about (measured: one oblique's outline 60 px off sideways moved the other oblique 5.8 mm
    /// and itself 4.6 mm).
    fn pose_note(&self, names: &[String]) -> Option<String> {
        if self.fallback != Some(Fallback::RefinePoses.name()) {
            return None;
        }
        let mut moved: Vec<(usize, [f64; 2])> =
            self.pose_corrections.iter().copied().enumerate().collect();
        moved.sort_by(|a, b| b.1[1].total_cmp(&a.1[1]));
        let &(view, [deg, mm]) = moved.first()?;
        let was = match &self.guard {
            Some(GuardFailure::Outlines { outline_px, .. }) => {
                format!(" (its outlines lay {outline_px:.1} px from the annotations)")
            }
            _ => String::new(),
        };
        let start = format!(
            "no shape met the views as their poses were given{was}, so the poses were refined \
             (as --refine-poses)"
        );
        if let Some(&(other, [deg2, mm2])) = moved
            .get(1)
            .filter(|(_, [_, mm2])| *mm2 >= SHARED_CORRECTION * mm && mm > 0.0)
        {
            // The fallback refines with `PoseParams::default()`, which holds the first view's
            // pose (`reference_view` 0).
            return Some(format!(
                "{start}: {} and {} moved by {mm:.1} and {mm2:.1} mm ({deg:.1} and {deg2:.1} \
                 degrees) against {}, which holds the frame; the outlines cannot tell which \
                 view's pose is off: check every view's pose (k, r, t) and annotation",
                view_label(names, view),
                view_label(names, other),
                view_label(names, 0),
            ));
        }
        Some(format!(
            "{start}: {} moved most, by {mm:.1} mm and {deg:.1} degrees; check that view's pose \
             and its annotation",
            view_label(names, view)
        ))
    }

    /// A line for the user when the run restarted: how far the given start's result left the
    /// outlines and which start gave the result; None when it did not restart.
    pub fn restart_note(&self) -> Option<String> {
        let kept = self.restart?;
        let given = self.restarts.first()?.rms_px;
        let from = self
            .restarts
            .iter()
            .find(|t| t.source == kept)
            .map_or(given, |t| t.rms_px);
        let tilts = self
            .restarts
            .iter()
            .filter(|t| t.source != "given" && t.source != restart::LIMB_SPHERE)
            .count();
        if !given.is_finite() {
            // The given start failed outright; the limb sphere's started the method again.
            return Some(if kept == restart::LIMB_SPHERE {
                let tried = if tilts > 0 {
                    format!("; {tilts} tilted starts did no better")
                } else {
                    String::new()
                };
                format!(
                    "the given start failed; restarted from the outlines' limb sphere \
                     ({from:.1} px from the outlines){tried}"
                )
            } else {
                format!(
                    "the given start failed; restarted from the outlines' limb sphere and \
                     {tilts} tilted starts, this result is from the {kept} tilt's ({from:.1} px)"
                )
            });
        }
        let why = match &self.restart_cause {
            Some(RestartCause::Folded(share)) => format!(
                "the given start's result was folded over at its rim ({:.1} % of its triangles \
                 face the cup's centre; its outlines {given:.1} px from the observed ones)",
                100.0 * share
            ),
            Some(RestartCause::Guard(failure)) => format!(
                "a guard refused the given start's result ({failure}; its outlines {given:.1} px \
                 from the observed ones)"
            ),
            Some(RestartCause::Outlines) | None => {
                format!("the given start's result left the outlines {given:.1} px away")
            }
        };
        let tried = self.restarts.len() - 1;
        Some(if kept == "given" {
            format!("{why}; {tried} tilted starts did no better, so this is the given start's")
        } else {
            format!(
                "{why}; restarted from {tried} tilted starts, this result is from the {kept} \
                 tilt's ({from:.1} px)"
            )
        })
    }
}

/// Why a run tried the tilted starts (`SolveLog::restart_cause`), the first that holds of the
/// result it started from.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartCause {
    /// A guard refused it (`GuardParams`), for this reason.
    Guard(GuardFailure),
    /// Its outlines lay farther from the observed ones than the trigger
    /// (`PlacementParams::restart_trigger_px`).
    Outlines,
    /// This share of its triangles faced its cup sphere's centre, more than
    /// `PlacementParams::restart_above_folded`.
    Folded(f64),
}

impl RestartCause {
    /// Its name, as runs.csv's `restart_cause` column writes it: "outlines", "folded", or
    /// "guard-" and the guard's name (`GuardFailure::name`).
    pub fn name(&self) -> String {
        match self {
            RestartCause::Guard(failure) => format!("guard-{}", failure.name()),
            RestartCause::Outlines => "outlines".into(),
            RestartCause::Folded(_) => "folded".into(),
        }
    }
}

/// One orientation stage B tried.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct OrientationTrial {
    /// "stage A" (the given start's result) or "mirrored" (the mirrored start, settled by
    /// stage A), the one stage A ranked first listed first; for a restart, "given" or the tilt
    /// ("+u", "-u", "+v", "-v").
    pub source: &'static str,
    /// Its reprojection RMS, pixels.
    pub rms_px: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn restarted(cause: RestartCause, kept: &'static str) -> SolveLog {
        let trial = |source, rms_px| OrientationTrial { source, rms_px };
        SolveLog {
            restarts: vec![trial("given", 2.36), trial("-u", 1.46), trial("+v", 3.1)],
            restart: Some(kept),
            restart_cause: Some(cause),
            ..Default::default()
        }
    }

    /// The note names why the tilted starts were tried: a fold with its share, a guard with
    /// its reason, or the outline distance; companion: a restart for the outlines says nothing
    /// of a fold.
    #[test]
    fn the_restart_note_says_why_the_run_restarted() {
        let folded = restarted(RestartCause::Folded(0.078), "-u")
            .restart_note()
            .unwrap();
        assert!(folded.contains("folded over at its rim (7.8 %"), "{folded}");
        assert!(folded.contains("2.4 px"), "{folded}");
        assert!(folded.contains("the -u tilt's (1.5 px)"), "{folded}");
        let failure = GuardFailure::Folded { folded: 0.2 };
        let guard = restarted(RestartCause::Guard(failure), "given")
            .restart_note()
            .unwrap();
        assert!(guard.starts_with("a guard refused"), "{guard}");
        assert!(
            guard.contains("20.0 % of the surface's triangles"),
            "{guard}"
        );
        assert!(guard.contains("2 tilted starts did no better"), "{guard}");
        let outlines = restarted(RestartCause::Outlines, "-u")
            .restart_note()
            .unwrap();
        assert!(
            outlines.contains("left the outlines 2.4 px away"),
            "{outlines}"
        );
        assert!(!outlines.contains("folded"), "{outlines}");
        assert_eq!(SolveLog::default().restart_note(), None);
    }

    /// runs.csv's names of the causes; companion: two guards' causes differ by the guard.
    #[test]
    fn a_restart_cause_is_named_by_its_kind_and_guard() {
        assert_eq!(RestartCause::Outlines.name(), "outlines");
        assert_eq!(RestartCause::Folded(0.03).name(), "folded");
        let folded = RestartCause::Guard(GuardFailure::Folded { folded: 0.2 });
        assert_eq!(folded.name(), "guard-folded");
        let rough = RestartCause::Guard(GuardFailure::Rough {
            rms_mm: 4.0,
            max_mm: 3.5,
        });
        assert_ne!(rough.name(), folded.name());
    }
}
