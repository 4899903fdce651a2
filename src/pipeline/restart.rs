//! Restarts: the method again from tilted starts when its result does not follow the outlines,
//! the result that follows them best kept.

use super::{
    attempt, folded_share, guard_failure, GuardFailure, Input, LimbOnce, OrientationTrial,
    ReconError, ReconParams, Reconstruction, RestartCause,
};
use crate::contours::ModelContour;
use crate::engine::Kernels;
use crate::geom::{Curve, Segments};
use crate::template::Placement;
use nalgebra::{Rotation3, Unit, Vector3};

/// The method from the given start and, when its model outlines lie farther than
/// `placement.restart_trigger_px` from the observed ones (`outline_distance_px`) or more than
/// `placement.restart_above_folded` of its triangles are folded over (`folded_share`), from
/// tilted starts too (`tilted_starts`); the result whose outlines lie nearest is kept, the
/// trials and the cause (`RestartCause`) in its log. A stage A that settled on a wrong turn of
/// the cap leaves a result whose outlines cannot follow the observed ones (stretches of them
/// left several noise SDs away), or one folded over at its rim; from a start tilted away from
/// that turn stage A settles elsewhere. The score needs no truth and does not depend on which
/// correspondences each result kept. A first result a guard refuses restarts
/// too (but for rims left open, `GuardFailure::OpenRims`), and a result the guards pass
/// outranks one they refuse. A restart that fails is skipped.
/// Where the given start fails outright, the method starts again on the limb sphere
/// (`limb_started`), and that start stands in for the given one (its tilts are tried when its
/// result leaves the outlines); when it fails too, the given start's error is returned.
/// Returned with the guard the kept result fails (None when it passes, or without guards).
pub(super) fn restarting(
    input: &Input,
    prm: &ReconParams,
    kernels: Kernels,
    limb: &LimbOnce,
) -> Result<(Reconstruction, Option<GuardFailure>), ReconError> {
    // A result's score: the guard it fails (None without guards), then its outline distance
    // (`SolveLog::outline_px`, measured once when the result was made);
    // it ranks by (refused or not, distance).
    let score = |rec: &Reconstruction| {
        (
            prm.guards.as_ref().and_then(|g| guard_failure(g, rec)),
            rec.log.outline_px,
        )
    };
    let rank = |s: &(Option<GuardFailure>, f64)| (s.0.is_some(), s.1);
    // The given start, or where it failed, the limb sphere's (see `limb_started`).
    let (first, start, kept_first) = match attempt(input, prm, kernels, limb) {
        Ok(rec) => (rec, input.init.clone(), "given"),
        Err(e) => {
            let Some(init) = limb_started(input, prm, limb) else {
                return Err(e);
            };
            let from_limb = Input {
                init: &init,
                ..*input
            };
            let Ok(rec) = attempt(&from_limb, prm, kernels, limb) else {
                return Err(e);
            };
            (rec, init, LIMB_SPHERE)
        }
    };
    // A given start that failed is a trial with no outline distance.
    let mut trials: Vec<OrientationTrial> = (kept_first == LIMB_SPHERE)
        .then_some(OrientationTrial {
            source: "given",
            rms_px: f64::INFINITY,
        })
        .into_iter()
        .collect();
    let mut best_score = score(&first);
    trials.push(OrientationTrial {
        source: kept_first,
        rms_px: best_score.1,
    });
    let trigger = prm.placement.restart_trigger_px(prm.pose.is_some());
    // The first cause that holds; the fold is measured only when nothing else restarts it.
    // Rims left open restart nothing: the gaps are the annotation's, whatever the start.
    let cause = match &best_score.0 {
        Some(GuardFailure::OpenRims { .. }) => None,
        Some(failure) => Some(RestartCause::Guard(failure.clone())),
        None if best_score.1 > trigger => Some(RestartCause::Outlines),
        None => {
            let folded = folded_share(&first.mesh, &first.sphere);
            (folded > prm.placement.restart_above_folded).then_some(RestartCause::Folded(folded))
        }
    };
    if cause.is_none() {
        let mut first = first;
        if kept_first == LIMB_SPHERE {
            first.log.restarts = trials;
            first.log.restart = Some(LIMB_SPHERE);
        }
        return Ok((first, best_score.0));
    }
    let mut best = first;
    let mut kept = kept_first;
    // The tilted starts are independent; they are judged in order.
    let starts = tilted_starts(&start, prm);
    let results = kernels.map_parts(&starts, |_, (_, init)| {
        let tilted = Input { init, ..*input };
        attempt(&tilted, prm, kernels, limb).ok()
    });
    for ((source, _), rec) in starts.iter().zip(results) {
        let Some(rec) = rec else {
            continue;
        };
        let source = *source;
        let s = score(&rec);
        trials.push(OrientationTrial {
            source,
            rms_px: s.1,
        });
        if rank(&s) < rank(&best_score) {
            (best, best_score, kept) = (rec, s, source);
        }
    }
    best.log.restarts = trials;
    best.log.restart = Some(kept);
    best.log.restart_cause = cause;
    Ok((best, best_score.0))
}

/// Where a run restarts when the given start fails outright (`restarting`).
pub const LIMB_SPHERE: &str = "limb sphere";

/// The given start moved onto the sphere the outlines' limbs define (its axis kept), when
/// `placement.limb_restart` is on and stage 0 does not already start there: with pose
/// refinement the method starts from the given placement, which may lie so far off (a study's
/// level 5 shifts it by 100 mm SD per axis) that the first correspondences cannot form; the
/// limbs, even of views whose poses are a little off, put it within millimetres. None when
/// stage 0 uses the limb sphere anyway, or no limb sphere fits.
fn limb_started(input: &Input, prm: &ReconParams, limb: &LimbOnce) -> Option<Placement> {
    if !prm.placement.limb_restart || (prm.pose.is_none() && prm.placement.limb_start) {
        return None;
    }
    let ls = limb.get()?;
    Some(Placement {
        center: ls.center,
        radius: ls.radius,
        ..input.init.clone()
    })
}

/// The restarts' starts: the given axis tilted by `placement.restart_tilt_deg` about two
/// directions perpendicular to it (the first also perpendicular to the body's long axis, z),
/// each way; the first `placement.restart_tilts` of them. Centre and size stay (stage 0 puts
/// the cap on the limb sphere anyway).
pub(super) fn tilted_starts(init: &Placement, prm: &ReconParams) -> Vec<(&'static str, Placement)> {
    let a = init.axis.into_inner();
    let u = a
        .cross(&Vector3::z())
        .try_normalize(1e-9)
        .unwrap_or_else(|| a.cross(&Vector3::x()).normalize());
    let v = a.cross(&u).normalize();
    let angle = prm.placement.restart_tilt_deg.to_radians();
    [("+u", u), ("-u", -u), ("+v", v), ("-v", -v)]
        .into_iter()
        .take(prm.placement.restart_tilts)
        .map(|(name, w)| {
            let turn = Rotation3::from_axis_angle(&Unit::new_normalize(w), angle);
            let axis = Unit::new_normalize(turn * a);
            (
                name,
                Placement {
                    axis,
                    ..init.clone()
                },
            )
        })
        .collect()
}

/// How far model outlines (one a view, as a result's `final_contours`) lie from the observed
/// ones, pixels: the RMS over every
/// observed point of its distance to the model outline of its view and, for a closed observed
/// outline, over every model outline point of its distance to the nearest observed outline (an
/// open one leaves part of the model outline unwatched). Infinite when a view has no model
/// outline.
pub fn outline_distance_px(model_contours: &[ModelContour], observed: &[Vec<Curve>]) -> f64 {
    outline_distances_px(model_contours, observed).1
}

/// `outline_distance_px` of each view alone (infinite for a view without a model contour),
/// and of all views at once, from one pass over the outlines.
pub fn outline_distances_px(
    model_contours: &[ModelContour],
    observed: &[Vec<Curve>],
) -> (Vec<f64>, f64) {
    let rms = |sum: f64, n: usize| {
        if n == 0 {
            f64::INFINITY
        } else {
            (sum / n as f64).sqrt()
        }
    };
    // One running sum over the views, in their order, beside each view's own.
    let (mut sum, mut n) = (0.0, 0usize);
    let mut all_seen = true;
    let per_view = (0..observed.len())
        .map(|view| {
            let (mut own, mut count) = (0.0, 0usize);
            let seen = add_view(model_contours, observed, view, &mut |d2| {
                sum += d2;
                own += d2;
                n += 1;
                count += 1;
            });
            all_seen &= seen;
            if seen {
                rms(own, count)
            } else {
                f64::INFINITY
            }
        })
        .collect();
    (per_view, if all_seen { rms(sum, n) } else { f64::INFINITY })
}

/// Pass each squared distance of one view to `add` for `outline_distance_px`; false when the
/// view has no model contour.
fn add_view(
    model_contours: &[ModelContour],
    observed: &[Vec<Curve>],
    view: usize,
    add: &mut impl FnMut(f64),
) -> bool {
    let curves = &observed[view];
    let Some(model) = model_contours.get(view).filter(|m| !m.points.is_empty()) else {
        return false;
    };
    let to_model = Segments::new(&model.points, true);
    for c in curves {
        for q in &c.points {
            add(to_model.distance(q).powi(2));
        }
    }
    if curves.iter().all(|c| c.closed) {
        let to_observed: Vec<Segments> = curves
            .iter()
            .map(|c| Segments::new(&c.points, true))
            .collect();
        for q in &model.points {
            let d = to_observed
                .iter()
                .map(|c| c.distance(q))
                .fold(f64::INFINITY, f64::min);
            add(d * d);
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point2;

    fn circle(r: f64, dx: f64, n: usize) -> Vec<Point2<f64>> {
        (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / n as f64;
                Point2::new(500.0 + dx + r * t.cos(), 400.0 + r * t.sin())
            })
            .collect()
    }

    #[test]
    fn the_outline_distance_measures_how_far_the_outlines_lie() {
        let observed = vec![vec![Curve {
            points: circle(100.0, 0.0, 300),
            closed: true,
        }]];
        let model = |r: f64| {
            vec![ModelContour {
                vertex_ids: (0..120).collect(),
                points: circle(r, 0.0, 120),
            }]
        };
        // The same circle: the chords of a 120-gon lie within 0.04 px of it.
        let same = outline_distance_px(&model(100.0), &observed);
        assert!(same < 0.05, "{same}");
        // Companion: a model outline 3 px larger lies about 3 px away, and one that follows
        // only part of the outline (a dent pushed 20 px in over a quarter) much farther.
        let larger = outline_distance_px(&model(103.0), &observed);
        assert!((larger - 3.0).abs() < 0.1, "{larger}");
        let mut dented = model(100.0);
        for p in dented[0].points.iter_mut().take(30) {
            let d = *p - Point2::new(500.0, 400.0);
            *p -= d * 0.2;
        }
        assert!(outline_distance_px(&dented, &observed) > 5.0);
        // An open observed outline is judged only along itself: the model beyond its ends is
        // not counted.
        let open = vec![vec![Curve {
            points: circle(100.0, 0.0, 300)[..150].to_vec(),
            closed: false,
        }]];
        let mut half_off = model(100.0);
        for p in half_off[0].points.iter_mut().skip(61) {
            p.y -= 30.0;
        }
        let d_open = outline_distance_px(&half_off, &open);
        let d_closed = outline_distance_px(&half_off, &observed);
        assert!(d_open < d_closed, "{d_open} {d_closed}");
        // No model outline in a view: infinitely far.
        assert!(outline_distance_px(&[], &observed).is_infinite());
    }

    #[test]
    fn the_tilted_starts_turn_the_axis_by_the_tilt_each_a_different_way() {
        let init = Placement {
            center: nalgebra::Point3::new(1.0, 2.0, 3.0),
            radius: 25.0,
            axis: Unit::new_normalize(Vector3::new(0.6, -0.5, 0.3)),
        };
        let prm = ReconParams::default();
        let starts = tilted_starts(&init, &prm);
        assert_eq!(starts.len(), prm.placement.restart_tilts);
        for (i, (_, p)) in starts.iter().enumerate() {
            let angle = p.axis.angle(&init.axis).to_degrees();
            assert!(
                (angle - prm.placement.restart_tilt_deg).abs() < 1e-9,
                "{angle}"
            );
            assert_eq!((p.center, p.radius), (init.center, init.radius));
            for (_, q) in &starts[..i] {
                assert!(p.axis.angle(&q.axis).to_degrees() > 30.0);
            }
        }
        // The first pair turns about a direction across the long axis (z): +u and -u move the
        // axis's z component opposite ways; the second pair keeps it about the same.
        let dz = |k: usize| starts[k].1.axis.z - init.axis.z;
        assert!(dz(0) * dz(1) < 0.0, "{} {}", dz(0), dz(1));
        let none = ReconParams {
            placement: crate::pipeline::PlacementParams {
                restart_tilts: 0,
                ..Default::default()
            },
            ..Default::default()
        };
        assert!(tilted_starts(&init, &none).is_empty());
    }
}
