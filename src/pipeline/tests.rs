//! The pipeline's tests: whole reconstructions through `reconstruct` (the depth offset, where and
//! which way an outline was traced, each method's own pair rules), their guards and fallbacks
//! (open rims, crumpled surfaces, a wrong pose, a result no guard passes) and the views' notes.

use super::*;

#[test]
fn a_view_far_worse_than_the_others_is_named_and_agreeing_views_are_not() {
    let names: Vec<String> = ["AP", "oblique +20", "oblique -20"]
        .map(String::from)
        .to_vec();
    let note = |d: &[f64]| {
        SolveLog {
            outline_px_per_view: d.to_vec(),
            ..Default::default()
        }
        .view_note(&names)
    };
    let n = note(&[5.46, 13.61, 2.11]).expect("view 1 is named");
    assert!(n.starts_with("view 1 (oblique +20) is 13.6 px"), "{n}");
    assert!(n.contains("at most 5.5 px"), "{n}");
    // The companions: views that share the misfit, a misfit under the floor, no outlines.
    assert_eq!(note(&[3.26, 5.01, 2.62]), None);
    assert_eq!(note(&[0.5, 2.9, 0.4]), None);
    assert_eq!(note(&[]), None);
    assert_eq!(note(&[1.0, f64::INFINITY, 1.0]), None);
    // A result of the refine-poses fallback names the view whose pose moved most.
    let refined = SolveLog {
        outline_px_per_view: vec![1.4, 1.5, 1.8],
        pose_corrections: vec![[0.0, 0.0], [0.7, 6.2], [1.3, 1.1]],
        fallback: Some("refine-poses"),
        guard: Some(GuardFailure::Outlines {
            outline_px: 7.9,
            max_px: 5.0,
        }),
        ..Default::default()
    };
    let n = refined.view_note(&names).expect("the moved view is named");
    assert!(n.contains("lay 7.9 px"), "{n}");
    assert!(
        n.contains("view 1 (oblique +20) moved most, by 6.2 mm"),
        "{n}"
    );
    // Corrections shared between the obliques (one oblique's outline 60 px off sideways)
    // name both and no culprit; the clear case above names one.
    let shared = SolveLog {
        pose_corrections: vec![[0.0, 0.0], [1.76, 5.82], [1.28, 4.59]],
        ..refined.clone()
    };
    let n = shared.view_note(&names).expect("the moved views are named");
    assert!(
        n.contains("view 1 (oblique +20) and view 2 (oblique -20) moved by 5.8 and 4.6 mm"),
        "{n}"
    );
    assert!(
        n.contains("against view 0 (AP), which holds the frame"),
        "{n}"
    );
    assert!(!n.contains("moved most"), "{n}");
    let n = refined.view_note(&names).unwrap();
    assert!(!n.contains("cannot tell"), "{n}");
    // Companion: the same corrections asked for (--refine-poses, no fallback) name nothing.
    let asked = SolveLog {
        fallback: None,
        guard: None,
        ..refined
    };
    assert_eq!(asked.view_note(&names), None);
}
use crate::sim::XrayGeometry;
use crate::sim::{phantom, PhantomParams};
use crate::sim::{simulate_case, NoiseLevel};

#[test]
fn a_reference_view_that_is_not_a_view_is_named() {
    let truth = phantom(&PhantomParams::default()).mesh;
    let level = NoiseLevel::level(1).unwrap();
    let sim = simulate_case(&truth, &XrayGeometry::default(), 2.0, &level, 3).unwrap();
    let with_reference = |reference_view| ReconParams {
        pose: Some(crate::solve::PoseParams {
            reference_view,
            ..Default::default()
        }),
        ..Default::default()
    };
    let template = Template::standard();
    let r = reconstruct(&sim.input(&template), &with_reference(3), Kernels::Cpu);
    assert!(
        matches!(
            r,
            Err(ReconError::Param {
                field: "pose.reference_view",
                ..
            })
        ),
        "{r:?}"
    );
    // Companion: the last view is a view.
    let ok = reconstruct(&sim.input(&template), &with_reference(2), Kernels::Cpu);
    assert!(ok.is_ok(), "{:?}", ok.err());
}

#[test]
fn a_depth_offset_moves_the_result_and_its_cup_along_the_depth_axis_and_nothing_else() {
    let (_, sim) = crate::sim::phantom_case(1, 3).unwrap();
    let template = Template::standard();
    let run = |depth_mm: f64| {
        let mut prm = ReconParams::default();
        prm.cup.depth_mm = depth_mm;
        reconstruct(&sim.input(&template), &prm, Kernels::Cpu).unwrap()
    };
    let (own, moved) = (run(0.0), run(0.8));
    // The phantom opens toward the sources (+y): its axis leans +y, at full length.
    let a = own.log.depth_axis.map(nalgebra::Vector3::from).unwrap();
    assert!((a.norm() - 1.0).abs() < 1e-9 && a.y > 0.9, "{a:?}");
    assert_eq!(
        (own.log.depth_moved_mm, moved.log.depth_moved_mm),
        (0.0, 0.8)
    );
    assert_eq!(moved.log.depth_axis, own.log.depth_axis);
    for (p, q) in own.mesh.vertices.iter().zip(&moved.mesh.vertices) {
        assert!((q - p - 0.8 * a).norm() < 1e-9, "{p} {q}");
    }
    // The cup keeps its size and moves with the surface.
    assert!((moved.sphere.radius - own.sphere.radius).abs() < 1e-6);
    let shift = moved.sphere.center_point() - own.sphere.center_point();
    assert!((shift - 0.8 * a).norm() < 1e-4, "{shift:?}");
    assert_eq!(moved.cup, own.cup);
    // The restarts and guards judged the fit before the move: the log's outline distances
    // are the fit's. Companion: the moved result's own outlines, drawn again, lie farther
    // from the annotations than the fit's.
    assert_eq!(moved.log.outline_px, own.log.outline_px);
    assert_eq!(moved.log.outline_px_per_view, own.log.outline_px_per_view);
    let input = sim.input(&template);
    let observed = entered(input.observed);
    let (_, drawn) = restart::outline_distances_px(&moved.final_contours, &observed);
    assert!(
        drawn > own.log.outline_px + 0.05,
        "{drawn} {}",
        own.log.outline_px
    );
    // The resamples start from the fit too: the moved result's are the unmoved one's.
    // Companion: the moved surface taken for a fit (no record of the move) resamples
    // otherwise.
    let up = UncertaintyParams {
        samples: 4,
        ..Default::default()
    };
    let full = |rec: &Reconstruction| {
        cup_report(
            rec,
            &sim.observed,
            &ReconParams::default(),
            Kernels::Cpu,
            &up,
        )
        .unwrap()
    };
    let report = |rec: &Reconstruction| full(rec).resampled_mm;
    // The rim's orientation is read on the fit's sphere as well. Companion: read on the
    // moved sphere it turns.
    let (o_fit, o_moved) = (full(&own).orientation, full(&moved).orientation);
    let (o_fit, o_moved) = (o_fit.unwrap(), o_moved.unwrap());
    assert!((o_fit.inclination_deg - o_moved.inclination_deg).abs() < 1e-6);
    assert!((o_fit.anteversion_deg - o_moved.anteversion_deg).abs() < 1e-6);
    let on_moved =
        crate::solve::rim_orientation(&moved.cameras, &observed, &moved.fitted_sphere).unwrap();
    assert!(
        (on_moved.inclination_deg - o_fit.inclination_deg).abs()
            + (on_moved.anteversion_deg - o_fit.anteversion_deg).abs()
            > 0.05,
        "{on_moved:?} {o_fit:?}"
    );
    let (from_fit, from_moved) = (report(&own), report(&moved));
    for (a, b) in from_fit.iter().zip(&from_moved) {
        assert!((a - b).abs() < 1e-6, "{from_fit:?} {from_moved:?}");
    }
    let mut unrecorded = moved.clone();
    unrecorded.log.depth_moved_mm = 0.0;
    let apart = from_fit
        .iter()
        .zip(&report(&unrecorded))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(apart > 1e-3, "{apart} {from_fit:?}");
    // Companion: an offset too large for a correction is refused before any work, named.
    let mut prm = ReconParams::default();
    prm.cup.depth_mm = 9.0;
    let e = reconstruct(&sim.input(&template), &prm, Kernels::Cpu)
        .unwrap_err()
        .to_string();
    assert!(e.contains("depth_mm"), "{e}");
}

#[test]
fn outlines_a_wrong_pose_keeps_far_away_send_the_run_to_pose_refinement() {
    let (_, mut sim) = crate::sim::phantom_case(1, 3).unwrap();
    let template = Template::standard();
    // View 1's pose is 9 mm off across its image (about 54 px at the object) and nothing
    // refines it. (8 mm was this test's case until stage A's rounds were damped: the
    // method's own result then lay 5.3 px from the outlines, now 4.9 px, under the guard,
    // with the cup 3.3 mm off: docs/population.md, "Stage A's rounds damped".)
    sim.cameras[1].t.x += 9.0;
    let truth = sim.truth_sphere.diameter();
    let rec = reconstruct(&sim.input(&template), &ReconParams::default(), Kernels::Cpu).unwrap();
    assert_eq!(rec.log.fallback, Some("refine-poses"));
    // The method's own result lies far from the outlines; since SRVF's pairs the rim makes
    // weigh less (`RimPairs`), it also lies far from the limb sphere, the guard checked
    // first (7.1 mm off; outlines 6.6 px, 5.4 px before).
    assert!(
        matches!(rec.log.guard, Some(GuardFailure::Outlines { outline_px, .. }) if outline_px > 5.0)
            || matches!(rec.log.guard, Some(GuardFailure::LimbSphere { .. })),
        "{:?}",
        rec.log.guard
    );
    assert!(rec.log.outline_px < 3.0, "{}", rec.log.outline_px);
    assert!(!rec.log.pose_corrections.is_empty());
    // The phantom's cup is 1.1-1.5 mm small with exact poses (`acetab demo`); the poses
    // refined from 9 mm off leave this one 2.46 mm small (2.60 with `settled_round_mm` 1.0
    // applied to refined poses as well, which it is not), the refused result 3.66 mm large.
    assert!(
        (rec.sphere.diameter() - truth).abs() < 2.5,
        "{} against {truth}",
        rec.sphere.diameter()
    );
    // The companion: without the guards the method's own result stands, and it is what the
    // guards refuse: outlines far off and a cup farther from the truth.
    let unguarded = ReconParams {
        guards: None,
        ..Default::default()
    };
    let own = reconstruct(&sim.input(&template), &unguarded, Kernels::Cpu).unwrap();
    assert_eq!(own.log.fallback, None);
    assert!(own.log.outline_px > 5.0, "{}", own.log.outline_px);
    assert!(
        guard_failure(&GuardParams::default(), &own).is_some(),
        "{}",
        own.log.outline_px
    );
    assert!(
        (own.sphere.diameter() - truth).abs() > (rec.sphere.diameter() - truth).abs(),
        "{} / {} against {truth}",
        own.sphere.diameter(),
        rec.sphere.diameter()
    );
    // A run that refines its poses already has no such fallback.
    let refining = ReconParams {
        pose: Some(crate::solve::PoseParams::default()),
        ..Default::default()
    };
    assert!(Fallback::RefinePoses.params(&refining).is_none());
    assert_eq!(
        Fallback::order(&GuardFailure::Outlines {
            outline_px: 7.0,
            max_px: 5.0
        })[0],
        Fallback::RefinePoses
    );
    assert_eq!(
        Fallback::order(&GuardFailure::Folded { folded: 0.5 }),
        FALLBACKS
    );
    assert!(!Fallback::order(&GuardFailure::Rough {
        rms_mm: 5.0,
        max_mm: 3.5
    })
    .contains(&Fallback::RefinePoses));
    // Rims left open: no fallback (the annotation's gaps are the cause, which none fills).
    assert!(Fallback::order(&GuardFailure::OpenRims {
        share: 0.3,
        min: 0.45
    })
    .is_empty());
}

/// Where an annotator started each outline, and which way round it was traced, makes no
/// difference: the same outlines entered at other points, one closed outline and one open
/// arc traced the other way, give the same surface and the same cup report (its resamples
/// and the rim's orientation), to the bit. Before the outlines were entered at a fixed
/// point, such a change moved a shared acetabulum's error by up to 1.5 mm; before they were
/// also turned to one direction, a closed outline traced clockwise was matched backwards by
/// a library caller (the case file turned them) and an open arc traced the other way moved
/// the example case's cup by 0.14 mm. Companion: one outline point moved 3 px gives another
/// surface and other resamples.
#[test]
fn where_and_which_way_an_outline_was_traced_does_not_change_the_result() {
    let (_, sim) = crate::sim::phantom_case(3, 5).unwrap();
    let template = Template::standard();
    let prm = ReconParams::default();
    let up = UncertaintyParams {
        samples: 4,
        ..Default::default()
    };
    let run = |observed: &[Vec<Curve>]| {
        let input = Input {
            observed,
            ..sim.input(&template)
        };
        let rec = reconstruct(&input, &prm, Kernels::Cpu).unwrap();
        let cup = cup_report(&rec, observed, &prm, Kernels::Cpu, &up).unwrap();
        let turned = cup
            .orientation
            .map(|o| (o.inclination_deg, o.anteversion_deg));
        (rec.mesh.vertices, cup.resampled_mm, turned)
    };
    // The last view's outline as an open arc: three quarters of it.
    let mut given = sim.observed.clone();
    let last = &mut given[2][0];
    last.points.truncate(3 * last.points.len() / 4);
    last.closed = false;
    let own = run(&given);
    let restarted: Vec<Vec<Curve>> = given
        .iter()
        .enumerate()
        .map(|(v, curves)| {
            curves
                .iter()
                .map(|c| c.retraced(c.points.len() / 3 + 7 * v, v > 0))
                .collect()
        })
        .collect();
    assert_ne!(restarted[0][0].points[0], given[0][0].points[0]);
    assert_ne!(restarted[2][0].points[0], given[2][0].points[0]);
    assert!(own.2.is_some());
    assert_eq!(run(&restarted), own);
    let mut moved = given.clone();
    moved[1][0].points[10].x += 3.0;
    let moved = run(&moved);
    assert_ne!(moved.0, own.0);
    assert_ne!(moved.1, own.1);
}

/// The along-outline weight is each method's own: SRVF's weight changes an srvf result and
/// leaves an icp-normvec one to the bit, the baselines' weight the other way round.
#[test]
fn the_along_outline_weight_is_each_methods_own() {
    use crate::correspond::Method;
    let (_, sim) = crate::sim::phantom_case(3, 5).unwrap();
    let template = Template::standard();
    let run = |method, srvf: f64, icp: f64| {
        let mut prm = ReconParams {
            method,
            ..Default::default()
        };
        (prm.tangential_srvf, prm.weights.tangential) = (srvf, icp);
        let rec = reconstruct(&sim.input(&template), &prm, Kernels::Cpu).unwrap();
        assert_eq!(rec.log.fallback, None);
        rec.mesh.vertices
    };
    let srvf = run(Method::Srvf, 0.1, 0.1);
    assert_ne!(run(Method::Srvf, 0.3, 0.1), srvf);
    assert_eq!(run(Method::Srvf, 0.1, 0.3), srvf);
    let icp = run(Method::IcpNormvec, 0.1, 0.1);
    assert_ne!(run(Method::IcpNormvec, 0.1, 0.3), icp);
    assert_eq!(run(Method::IcpNormvec, 0.3, 0.1), icp);
}

#[test]
fn the_rim_pairs_rule_is_srvfs_alone() {
    use crate::correspond::Method;
    // A cap reaching 60 degrees from its dome, turned as an acetabulum opens: narrower than
    // the hemisphere template, so SRVF pairs some model vertices with the rim's outline.
    let cap = crate::template::spherical_cap(25.0, 1500, 60f64.to_radians());
    let axis = nalgebra::Vector3::new(0.7, -0.3, -0.65).normalize();
    let turn = nalgebra::Rotation3::rotation_between(&nalgebra::Vector3::z(), &axis).unwrap();
    let truth = cap.transformed(1.0, &turn, &nalgebra::Vector3::zeros());
    let level = crate::sim::NoiseLevel::level(3).unwrap();
    let geometry = crate::sim::XrayGeometry::default();
    let sim = crate::sim::simulate_case(&truth, &geometry, 2.0, &level, 1).unwrap();
    let template = Template::standard();
    let run = |method, rim_pairs: Option<RimPairs>| {
        let prm = ReconParams {
            method,
            rim_pairs,
            ..Default::default()
        };
        let rec = reconstruct(&sim.input(&template), &prm, Kernels::Cpu).unwrap();
        rec.mesh.vertices
    };
    // SRVF's result moves with it; an ICP-NormVec result is the same to the bit.
    let srvf = run(Method::Srvf, Some(RimPairs::default()));
    assert!(run(Method::Srvf, None) != srvf);
    let icp = run(Method::IcpNormvec, Some(RimPairs::default()));
    assert!(run(Method::IcpNormvec, None) == icp);
    // Companion: a rule that lowers no pair (every vertex counted as near the border)
    // leaves SRVF's result as without it.
    let idle = RimPairs {
        border_rings: usize::MAX - 1,
        ..RimPairs::default()
    };
    assert!(run(Method::Srvf, Some(idle)) == run(Method::Srvf, None));
}

#[test]
fn rims_left_open_in_every_view_are_refused_and_rims_nearly_whole_run() {
    let (_, sim) = crate::sim::phantom_case(1, 3).unwrap();
    let template = Template::standard();
    // Each view's rim annotated over the first `keep` of its points only.
    let open = |keep: f64| {
        let mut s = sim.clone();
        for view in s.observed.iter_mut() {
            let c = &mut view[0];
            c.points.truncate((c.points.len() as f64 * keep) as usize);
            c.closed = false;
        }
        reconstruct(&s.input(&template), &ReconParams::default(), Kernels::Cpu)
    };
    match open(0.3) {
        Err(ReconError::Guard(Refusal {
            failure: GuardFailure::OpenRims { share, min },
            ..
        })) => assert!(share < min && min == 0.45, "{share}"),
        other => panic!(
            "expected the open rims refused, got {:?}",
            other.map(|r| (r.log.annotated_share_per_view, r.log.fallback, r.log.guard))
        ),
    }
    // The companion: rims annotated over 85 % of their points pass as the method asked.
    let most = open(0.85).expect("rims nearly whole run");
    assert_eq!((most.log.fallback, most.log.guard), (None, None));
    assert!(
        most.log.annotated_share > 0.7,
        "{:?}",
        most.log.annotated_share_per_view
    );
}

#[test]
fn annotations_given_to_the_wrong_views_leave_a_crumpled_surface_that_is_refused() {
    let (_, mut sim) = crate::sim::phantom_case(1, 3).unwrap();
    let template = Template::standard();
    // The AP view's annotation and the +20 degree oblique's swapped: a surface can still
    // meet all three outlines, by crumpling (about 5 mm RMS from its cup sphere, against
    // 0.5-2 mm for real results); no fallback smooths it, so the run fails with the reason.
    sim.observed.swap(0, 1);
    match reconstruct(&sim.input(&template), &ReconParams::default(), Kernels::Cpu) {
        Err(ReconError::Guard(Refusal {
            failure: GuardFailure::Rough { rms_mm, max_mm },
            ..
        })) => {
            assert!(rms_mm > max_mm && max_mm == 3.5, "{rms_mm}")
        }
        other => panic!(
            "expected the crumpled surface refused, got {:?}",
            other.map(|r| r.log)
        ),
    }
    // The companion: without this guard the crumpled surface is the result, its outlines
    // met well enough for every other guard.
    let unguarded = ReconParams {
        guards: Some(GuardParams {
            max_sphere_rms_mm: f64::INFINITY,
            ..Default::default()
        }),
        ..Default::default()
    };
    let own = reconstruct(&sim.input(&template), &unguarded, Kernels::Cpu).unwrap();
    assert_eq!((own.log.fallback, own.log.guard), (None, None));
    assert!(own.sphere.rms > 3.5, "{}", own.sphere.rms);
    assert!(own.log.outline_px < 5.0, "{}", own.log.outline_px);
    // The views as they are: the same phantom's result lies well inside the limit.
    let (_, sim) = crate::sim::phantom_case(1, 3).unwrap();
    let rec = reconstruct(&sim.input(&template), &ReconParams::default(), Kernels::Cpu).unwrap();
    assert!(rec.sphere.rms < 2.0, "{}", rec.sphere.rms);
}

#[test]
fn a_result_no_guard_passes_is_refused_with_its_reason() {
    let (_, sim) = crate::sim::phantom_case(1, 3).unwrap();
    let template = Template::standard();
    // No result ends within 0.1 px: the method and both fallbacks are refused.
    let strict = ReconParams {
        guards: Some(GuardParams {
            max_rms_px: 0.1,
            ..Default::default()
        }),
        ..Default::default()
    };
    match reconstruct(&sim.input(&template), &strict, Kernels::Cpu) {
        Err(ReconError::Guard(Refusal {
            failure: GuardFailure::Reprojection { max_px, .. },
            ..
        })) => {
            assert_eq!(max_px, 0.1)
        }
        other => panic!("expected a guard failure, got {:?}", other.map(|r| r.log)),
    }
    // Companion: with the default guards the phantom passes as it is, no fallback.
    let rec = reconstruct(&sim.input(&template), &ReconParams::default(), Kernels::Cpu).unwrap();
    assert_eq!((rec.log.fallback, rec.log.guard), (None, None));
    // A fallback is named with what the method's own result failed: a cup range only the
    // ICP-NormVec result meets is not constructible here, so check the fallbacks' settings.
    let p = ReconParams::default();
    let icp = Fallback::IcpNormvec.params(&p).unwrap();
    assert_eq!(icp.method, crate::correspond::Method::IcpNormvec);
    let rigid = Fallback::Rigid.params(&p).unwrap();
    assert_eq!(
        (rigid.weights.rot, rigid.weights.reg),
        (10.0 * p.weights.rot, 10.0 * p.weights.reg)
    );
    let shape = Fallback::ShapeOnly.params(&p).unwrap();
    assert_eq!(shape.correspond.srvf.anchor, 0.0);
    assert_eq!(shape.method, crate::correspond::Method::Srvf);
    assert!(p.correspond.srvf.anchor > 0.0);
    assert!(Fallback::ShapeOnly.params(&shape).is_none());
    let icp_baseline = ReconParams {
        method: crate::correspond::Method::Icp,
        ..Default::default()
    };
    let borrowed = Fallback::IcpNormvec.params(&icp_baseline).unwrap();
    assert_eq!(borrowed.method, crate::correspond::Method::IcpNormvec);
    let normvec_baseline = ReconParams {
        method: crate::correspond::Method::IcpNormvec,
        ..Default::default()
    };
    assert!(Fallback::IcpNormvec.params(&normvec_baseline).is_none());
    assert!(Fallback::ShapeOnly.params(&icp_baseline).is_none());
}
