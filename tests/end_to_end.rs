//! Whole-pipeline checks on the phantom and, when ../shared is present, on a real acetabulum.

use acetab::engine::Kernels;
use acetab::pipeline::Input;
use acetab::report::accuracy;
use acetab::template::Template;

use acetab::io::read_mesh;
use acetab::pipeline::{reconstruct, DeformationParams, PlacementParams, ReconParams};
use acetab::sim::run_demo;
use acetab::sim::XrayGeometry;
use acetab::sim::{ground_truth_surface, simulate_case, NoiseLevel};
use std::path::Path;

#[test]
fn phantom_level_1_reaches_sub_millimetre_accuracy() {
    let (r, _, _) = run_demo(2, 1, &ReconParams::default(), Kernels::Cpu).unwrap();
    println!(
        "seed 2 level 1: MAE {:.3} mm, cup error {:+.2} mm",
        r.mae_mm, r.cup_error_mm
    );
    assert!(r.mae_mm < 1.0, "MAE {}", r.mae_mm);
    assert!(r.mae_mm < 0.25 * r.initial_mae_mm);
}

#[test]
fn phantom_level_3_stays_under_one_and_a_half_millimetres() {
    let (r, _, _) = run_demo(2, 3, &ReconParams::default(), Kernels::Cpu).unwrap();
    println!(
        "seed 2 level 3: MAE {:.3} mm, cup error {:+.2} mm",
        r.mae_mm, r.cup_error_mm
    );
    assert!(r.mae_mm < 1.5, "MAE {}", r.mae_mm);
}

#[test]
fn the_accuracy_measure_rejects_an_unfitted_template() {
    // Companion of the two tests above: the untouched start is far outside their bounds.
    let (r, _, _) = run_demo(
        2,
        3,
        &ReconParams {
            placement: PlacementParams {
                rounds: 1,
                ..Default::default()
            },
            deformation: DeformationParams {
                correspondence_updates: 1,
                ..Default::default()
            },
            ..Default::default()
        },
        Kernels::Cpu,
    )
    .unwrap();
    assert!(r.initial_mae_mm > 5.0, "start MAE {}", r.initial_mae_mm);
}

/// Stage A's rounds on the phantom (seed 2, level 1) from the given start alone (no mirrored
/// probe), damped or not.
fn stage_a_rounds(damped: bool) -> usize {
    let prm = ReconParams {
        placement: PlacementParams {
            mirrored_start: false,
            damped,
            ..Default::default()
        },
        ..Default::default()
    };
    let (r, _, _) = run_demo(2, 1, &prm, Kernels::Cpu).unwrap();
    r.log.similarity_rounds
}

#[test]
fn damped_stage_a_rounds_settle_where_plain_ones_turn_back_and_forth() {
    // Undamped, the cap turns between two axes a few degrees apart until the rounds run out
    // (the companion: the cycle the damping is for is there); damped, the rounds settle.
    let (damped, plain) = (stage_a_rounds(true), stage_a_rounds(false));
    println!("stage A rounds: damped {damped}, plain {plain}");
    assert_eq!(plain, PlacementParams::default().rounds);
    assert!(damped + 3 <= plain, "damped {damped}, plain {plain}");
}

#[test]
fn a_coarse_graph_changes_only_the_rounds_before_the_last() {
    let mae = |updates: usize, coarse: Option<usize>| {
        let prm = ReconParams {
            deformation: DeformationParams {
                correspondence_updates: updates,
                coarse_graph_nodes: coarse,
                ..Default::default()
            },
            ..Default::default()
        };
        let (r, _, _) = run_demo(2, 1, &prm, Kernels::Cpu).unwrap();
        (r.mae_mm, r.cup_error_mm)
    };
    // One round is the last round: the full graph either way, so the same numbers exactly.
    assert_eq!(mae(1, Some(40)), mae(1, None));
    // Three rounds: the first two on 40 nodes, a different result, still sub-millimetre.
    let (coarse, fine) = (mae(3, Some(40)), mae(3, None));
    println!("coarse-to-fine {coarse:?}, full graph {fine:?}");
    assert_ne!(coarse, fine);
    assert!(coarse.0 < 1.0, "MAE {}", coarse.0);
}

/// The phantom's level-1 case with the start moved 292 mm and scaled by 2.5: the limb sphere
/// uses only the start's axis. Returns the MAE of the result and of the start itself.
fn far_start_mae() -> (f64, f64) {
    let (truth, sim) = acetab::sim::phantom_case(1, 4).unwrap();
    let mut init = sim.init.clone();
    init.center += nalgebra::Vector3::new(150.0, -200.0, 150.0);
    init.radius *= 2.5;
    let template = Template::standard();
    let input = Input {
        init: &init,
        ..sim.input(&template)
    };
    let rec = reconstruct(&input, &ReconParams::default(), Kernels::Cpu).unwrap();
    assert!(rec.log.limb_sphere.is_some());
    (
        accuracy(&truth, &rec.mesh).mae_mm,
        accuracy(&truth, &rec.initial).mae_mm,
    )
}

#[test]
fn a_start_far_off_in_place_and_size_still_reaches_sub_millimetre() {
    let (mae, start) = far_start_mae();
    println!("far start: MAE {mae:.3} mm (start {start:.1} mm)");
    assert!(mae < 1.0, "MAE {mae}");
    // Companion: the same bound rejects the start itself.
    assert!(start >= 1.0, "start MAE {start}");
}

/// One real acetabulum from ../shared (m2, right hip): the same bounds as the phantom.
#[test]
fn shared_real_acetabulum_levels_1_and_3() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/acetabula/m2_rhip_ac_wo_gap.stl");
    if !path.exists() {
        eprintln!(
            "skipped: {} is absent (../shared not beside the repository)",
            path.display()
        );
        return;
    }
    let truth = ground_truth_surface(&read_mesh(&path).unwrap()).unwrap();
    for (level, bound) in [(1u32, 1.0), (3, 1.5)] {
        let sim = simulate_case(
            &truth,
            &XrayGeometry::default(),
            2.0,
            &NoiseLevel::level(level).unwrap(),
            3,
        )
        .unwrap();
        let template = Template::standard();
        let rec =
            reconstruct(&sim.input(&template), &ReconParams::default(), Kernels::Cpu).unwrap();
        let acc = accuracy(&truth, &rec.mesh);
        println!(
            "m2_rhip level {level}: MAE {:.3} mm, cup {:.2} vs {:.2} mm",
            acc.mae_mm,
            rec.sphere.diameter(),
            sim.truth_sphere.diameter()
        );
        assert!(acc.mae_mm < bound, "level {level}: MAE {}", acc.mae_mm);
    }
}

/// A run of the seed-7 study of a shared acetabulum (`file` under ../shared/data): `level`,
/// run `run`, simulated as `simulated_run` does. Returns the MAE and the log; None when
/// ../shared is absent.
fn shared_run(
    file: &str,
    level: u32,
    run: usize,
    prm: &ReconParams,
) -> Option<(f64, acetab::pipeline::SolveLog)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(file);
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return None;
    }
    let truth = ground_truth_surface(&read_mesh(&path).unwrap()).unwrap();
    Some(simulated_run(
        &truth,
        acetab::study::run_seed(7, level, run),
        level,
        prm,
    ))
}

/// One simulated case of `truth` (2 px outline noise, the default views) at `level` with
/// `seed`, reconstructed with `prm`: its MAE and the log (the orientations stage B compared,
/// the restart kept).
fn simulated_run(
    truth: &acetab::Mesh,
    seed: u64,
    level: u32,
    prm: &ReconParams,
) -> (f64, acetab::pipeline::SolveLog) {
    let sim = simulate_case(
        truth,
        &XrayGeometry::default(),
        2.0,
        &NoiseLevel::level(level).unwrap(),
        seed,
    )
    .unwrap();
    let template = Template::standard();
    let rec = reconstruct(&sim.input(&template), prm, Kernels::Cpu).unwrap();
    (accuracy(truth, &rec.mesh).mae_mm, rec.log)
}

/// The default settings but for SRVF's pairs the rim makes, which weigh as the alignment gives
/// them (`ReconParams::rim_pairs` None, the settings before they weighed less). Since they do,
/// few runs of the seed-7 study turn the cap wrong (a scan of the 47 shared acetabula at levels
/// 1, 3, 5 x 3 runs: no given start's result refused by a guard, two fold restarts, neither
/// gaining; at a 2 px outline trigger the largest gain of a restart 0.06 mm, and of a dropped
/// mirrored lead 0.06 mm: docs/population.md, "Pairs the rim makes"). The tests of those
/// mechanisms keep their cases under these settings.
fn before_rim_pairs() -> ReconParams {
    ReconParams {
        rim_pairs: None,
        ..Default::default()
    }
}

/// `base` without stage B's comparison of orientations, without restarts, and without the
/// outline guard (whose pose-refinement fallback would also rescue a wrong turn).
fn no_comparison_no_restarts_from(base: ReconParams) -> ReconParams {
    ReconParams {
        deformation: DeformationParams {
            orientation_rounds: 0,
            ..Default::default()
        },
        placement: PlacementParams {
            restart_above_px: f64::INFINITY,
            restart_above_folded: f64::INFINITY,
            ..Default::default()
        },
        guards: Some(acetab::pipeline::GuardParams {
            max_outline_px: f64::INFINITY,
            ..Default::default()
        }),
        ..base
    }
}

/// The default settings without stage B's comparison of orientations, without restarts, and
/// without the outline guard.
fn no_comparison_no_restarts() -> ReconParams {
    no_comparison_no_restarts_from(ReconParams::default())
}

/// The candidate with the lowest reprojection RMS.
fn chosen(trials: &[acetab::pipeline::OrientationTrial]) -> &'static str {
    trials
        .iter()
        .min_by(|a, b| a.rms_px.total_cmp(&b.rms_px))
        .map_or("none", |t| t.source)
}

/// The seed-7 study's run `run` at `level` of `file` with `prm`: stage B compared the
/// orientations with `lead` first, kept `kept`, and the MAE is under `max_mae`. False (nothing
/// checked) when ../shared is absent.
fn compared_with(
    prm: &ReconParams,
    (file, level, run): (&str, u32, usize),
    lead: &str,
    kept: &str,
    max_mae: f64,
) -> bool {
    let Some((mae, log)) = shared_run(file, level, run, prm) else {
        return false;
    };
    let trials = &log.orientations;
    println!("{file} L{level} run {run}: MAE {mae:.3} mm, orientations {trials:?}");
    assert_eq!(trials.first().map(|t| t.source), Some(lead));
    assert_eq!(chosen(trials), kept, "{trials:?}");
    assert!(mae < max_mae, "MAE {mae}");
    true
}

/// `compared_with` the default settings.
fn compared(file: &str, level: u32, run: usize, lead: &str, kept: &str, max_mae: f64) -> bool {
    compared_with(
        &ReconParams::default(),
        (file, level, run),
        lead,
        kept,
        max_mae,
    )
}

#[test]
fn an_orientation_the_cap_cannot_choose_is_chosen_after_a_deformation_round() {
    // m3_lhip (LibHip, MIT) level 1, run 0: the mirrored cap scores within the MIRROR_SWITCH
    // band of the given one in stage A, which leads and is wrong (0.821 mm with the comparison,
    // 0.997 mm without, when this case was chosen by a scan of the 47 acetabula at levels 1,
    // 3, 5 x 3 runs: the largest gain of the 156 runs whose comparison kept the mirrored cap;
    // a55_lhip's level-5 run 0 was the case until SRVF's pairs the rim makes weighed less,
    // a02_rhip's level-3 run 0 until they were held more along the outline, a46_rhip's until
    // the outlines were entered at a fixed point).
    let file = "acetabula/m3_lhip_ac_wo_gap.stl";
    if !compared(file, 1, 0, "stage A", "mirrored", 0.9) {
        return;
    }
    // Companion: without the comparison (and without restarts, which could also rescue it)
    // the given (wrong) orientation stays, and the same bound rejects it.
    let (wrong, none) = shared_run(file, 1, 0, &no_comparison_no_restarts()).unwrap();
    println!("without the comparison: MAE {wrong:.3} mm");
    assert!(none.orientations.is_empty());
    assert!(wrong >= 0.9, "MAE {wrong}");
}

/// The pose-refinement bar on a small sample: views 1 and 2 off by 2 degrees and 5 mm.
fn pose_reduction(pose: Option<acetab::solve::PoseParams>) -> f64 {
    use acetab::study::pose::{run_pose_study, PoseStudy};
    let truth = acetab::sim::phantom(&acetab::sim::PhantomParams::default()).mesh;
    let cfg = PoseStudy {
        runs: 3,
        threads: 2,
        pose: pose.unwrap_or_default(),
        ..Default::default()
    };
    let rows = run_pose_study(&truth, &cfg).unwrap();
    assert!(rows.iter().all(|r| r.error.is_empty()), "{rows:?}");
    let without: f64 = rows.iter().map(|r| r.mae_without_mm).sum();
    let with: f64 = rows.iter().map(|r| r.mae_with_mm).sum();
    1.0 - with / without
}

#[test]
fn pose_refinement_lowers_the_error_by_at_least_30_percent() {
    let r = pose_reduction(None);
    assert!(r >= 0.3, "MAE only {:.0} % lower", 100.0 * r);
}

#[test]
fn pose_bar_rejects_a_refinement_that_cannot_move() {
    // Companion: a prior that pins the corrections at zero must fail the same bar.
    let pinned = acetab::solve::PoseParams {
        sigma_deg: 1e-9,
        sigma_mm: 1e-9,
        ..Default::default()
    };
    let r = pose_reduction(Some(pinned));
    assert!(
        r < 0.3,
        "a pinned refinement still gained {:.0} %",
        100.0 * r
    );
}

/// One srvf run of the seed-7 study of an atlas acetabulum (../shared, the JHU pelvis atlas):
/// `mesh` at `level`, run `run`. None when ../shared is absent.
fn atlas_run(mesh: &str, level: u32, run: usize, prm: ReconParams) -> Option<acetab::study::Row> {
    let row = atlas_row(mesh, level, run, prm, acetab::sim::Protocol::Ideal)?;
    assert!(row.error.is_empty(), "{}", row.error);
    Some(row)
}

/// `atlas_run` under `protocol`, the row as it is (an error in it included).
fn atlas_row(
    mesh: &str,
    level: u32,
    run: usize,
    prm: ReconParams,
    protocol: acetab::sim::Protocol,
) -> Option<acetab::study::Row> {
    use acetab::study::{run_one, run_seed, StudyConfig, StudyMethod, Task};
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(format!("../shared/data/pelvis-atlas/acetabula/{mesh}.stl"));
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return None;
    }
    let truth = acetab::sim::load_truth(path.to_str().unwrap()).unwrap();
    let cfg = StudyConfig {
        levels: vec![level],
        runs: run + 1,
        methods: vec![StudyMethod::Srvf],
        seed: 7,
        uncertainty: None,
        params: prm,
        protocol,
        ..Default::default()
    };
    let task = Task {
        method: StudyMethod::Srvf,
        level,
        run,
        seed: run_seed(7, level, run),
    };
    let (row, _) = run_one(&truth, &task, &cfg, Kernels::Cpu);
    Some(row)
}

#[test]
fn a_start_too_far_off_for_any_outline_restarts_from_the_limb_sphere() {
    // a02_lhip, the realistic protocol with pose refinement, level 5 run 1: with pose refinement
    // stage 0 does not put the cap on the limb sphere, and level 5's start lies so far off
    // (100 mm SD per axis) that the first correspondences cannot form (a view's model contour
    // collapses to one point). Started again on the limb sphere, the run gives a result. (Two
    // of the 117 atlas runs at level 5, runs 0-2, restart so, this and a14_rhip's run 0;
    // a10_rhip's run 1 was the case until SRVF's pairs were held more along the outline,
    // a02_rhip's run 0 until the outlines were entered at a fixed point.)
    let realistic = || acetab::sim::Protocol::Realistic(acetab::sim::RealisticErrors::default());
    let prm = |limb_restart: bool| ReconParams {
        pose: Some(acetab::solve::PoseParams::default()),
        placement: PlacementParams {
            limb_restart,
            ..Default::default()
        },
        ..Default::default()
    };
    let Some(row) = atlas_row("a02_lhip", 5, 1, prm(true), realistic()) else {
        return;
    };
    println!(
        "a02_lhip realistic L5 run 1: MAE {:.3} mm, cup {:.2} (truth {:.2}), restart {:?}",
        row.mae_mm, row.cup_diameter_mm, row.gt_cup_diameter_mm, row.restart
    );
    assert!(row.error.is_empty(), "{}", row.error);
    assert_eq!(row.restart, "limb sphere");
    assert!(row.mae_mm < 2.0, "MAE {}", row.mae_mm);
    assert!((row.cup_diameter_mm - row.gt_cup_diameter_mm).abs() < 3.0);
    // The companion: without the restart the same run fails, with the reason.
    let without = atlas_row("a02_lhip", 5, 1, prm(false), realistic()).unwrap();
    assert!(
        without.error.contains("model contour"),
        "{:?}",
        without.error
    );
}

/// Whether a run's `restart` names one of the tilted starts (`pipeline::restart`).
fn is_tilted_start(restart: &str) -> bool {
    ["+u", "-u", "+v", "-v"].contains(&restart)
}

#[test]
fn a_result_that_leaves_the_outlines_restarts_from_tilted_starts() {
    // a55_lhip level 1 run 2: stage A settles on a wrong turn of the cap, and the result's
    // outlines lie 2.2 px (RMS) from the annotations, its surface 1.55 mm off. The default
    // outline trigger (4 px) lets it through (the rough guard catches it: the guard test below);
    // here the guards and the fold trigger are off and the outline trigger is 2 px, so what is
    // tested is the outline trigger and the ranking alone: the tilted starts' results are ranked
    // by how near their outlines lie, and the nearest is kept. (a08_rhip's level-1 run 1 was the
    // case until SRVF's pairs were held more along the outline: its restart no longer gains.)
    // Under the settings before SRVF's pairs the rim makes weighed less (`before_rim_pairs`):
    // with them no run of the seed-7 scan restarted at the 2 px trigger gains more than 0.06
    // mm (18 of 423 restart from a tilted start).
    let prm = |trigger: f64| ReconParams {
        guards: None,
        placement: PlacementParams {
            restart_above_px: trigger,
            restart_above_folded: f64::INFINITY,
            ..Default::default()
        },
        ..before_rim_pairs()
    };
    let Some(row) = atlas_run("a55_lhip", 1, 2, prm(2.0)) else {
        return;
    };
    println!(
        "a55_lhip L1 run 2: MAE {:.3} mm, outlines {:.2} px, restart {:?}",
        row.mae_mm, row.outline_px, row.restart
    );
    assert!(row.mae_mm < 1.0, "MAE {}", row.mae_mm);
    assert!(is_tilted_start(&row.restart), "{:?}", row.restart);
    assert_eq!(row.restart_cause, "outlines");
    assert!(row.outline_px < 2.0, "{}", row.outline_px);
    // Companion: without restarts the given start's result stays, and the same bounds reject it.
    let alone = atlas_run("a55_lhip", 1, 2, prm(f64::INFINITY)).unwrap();
    println!(
        "without restarts: MAE {:.3} mm, outlines {:.2} px",
        alone.mae_mm, alone.outline_px
    );
    assert!(alone.restart.is_empty(), "{:?}", alone.restart);
    assert!(alone.restart_cause.is_empty(), "{:?}", alone.restart_cause);
    assert!(alone.mae_mm >= 1.0, "MAE {}", alone.mae_mm);
    assert!(alone.outline_px >= 2.0, "{}", alone.outline_px);
}

/// The atlas run with the settings before SRVF's pairs the rim makes weighed less
/// (`before_rim_pairs`) restarts for `cause` (runs.csv's `restart_cause`), keeps a tilted
/// start's result, needs no fallback and ends under 1 mm (asserted); false when the atlas is
/// absent.
fn restarts_to_a_good_tilted_start(mesh: &str, level: u32, run: usize, cause: &str) -> bool {
    let Some(row) = atlas_run(mesh, level, run, before_rim_pairs()) else {
        return false;
    };
    println!(
        "{mesh} L{level} run {run}, defaults: MAE {:.3} mm, outlines {:.2} px, restart {:?}, \
         fallback {:?}",
        row.mae_mm, row.outline_px, row.restart, row.fallback
    );
    assert!(is_tilted_start(&row.restart), "{:?}", row.restart);
    assert_eq!(row.restart_cause, cause);
    assert!(row.fallback.is_empty(), "{:?}", row.fallback);
    assert!(row.fallback_guard.is_empty(), "{:?}", row.fallback_guard);
    assert!(row.mae_mm < 1.0, "MAE {}", row.mae_mm);
    true
}

#[test]
fn a_result_folded_at_its_rim_restarts_from_tilted_starts() {
    // a55_lhip level 1 run 0 (under `before_rim_pairs`: with SRVF's pairs the rim makes
    // weighing less, two runs of the seed-7 scan restart for a fold, one keeping its given
    // start's result and the other ending 0.01 mm worse): the given start's result is folded
    // over at its rim (more than the fold trigger's 2 % of its triangles, under the guard's
    // 10 %; its outlines 3.9 px off, under the 4 px trigger), so the fold trigger restarts it,
    // and a tilted start's result, whose outlines lie nearer, is kept: 0.52 mm instead of 1.91.
    // (a08_rhip's level-1 run 1 was the case until SRVF's pairs were held more along the
    // outline: its restart, still taken, now ends 0.04 mm worse than the result it replaces.)
    if !restarts_to_a_good_tilted_start("a55_lhip", 1, 0, "folded") {
        return;
    }
    // Companion: without the fold trigger the folded result is returned as it stands.
    let mut prm = before_rim_pairs();
    prm.placement.restart_above_folded = f64::INFINITY;
    let alone = atlas_run("a55_lhip", 1, 0, prm).unwrap();
    println!("without the fold trigger: MAE {:.3} mm", alone.mae_mm);
    assert!(alone.restart.is_empty(), "{:?}", alone.restart);
    assert!(alone.restart_cause.is_empty(), "{:?}", alone.restart_cause);
    assert!(alone.mae_mm >= 1.0, "MAE {}", alone.mae_mm);
}

#[test]
fn a_result_a_guard_refuses_restarts_before_it_falls_back() {
    // a55_lhip level 1 run 2 (under `before_rim_pairs`: with SRVF's pairs the rim makes
    // weighing less, no run of the seed-7 scan is refused by a guard from its given start):
    // the given start's result (1.55 mm off,
    // the outline test above) is too rough for the rough guard, so the run restarts from the
    // tilted starts, and one of them passes the guards: no fallback is needed. (Its level-1
    // run 0, refused by the limb-sphere guard, was the case until SRVF's pairs were held more
    // along the outline: the fold trigger now restarts it first, the test above.)
    if !restarts_to_a_good_tilted_start("a55_lhip", 1, 2, "guard-rough") {
        return;
    }
    // Companion: with no tilted starts the guard's refusal stands and a fallback is taken.
    let mut prm = before_rim_pairs();
    prm.placement.restart_tilts = 0;
    let alone = atlas_run("a55_lhip", 1, 2, prm).unwrap();
    println!(
        "without tilted starts: fallback {:?} after the {:?} guard",
        alone.fallback, alone.fallback_guard
    );
    assert!(!alone.fallback.is_empty());
    assert_eq!(alone.fallback_guard, "rough");
}

#[test]
fn srvf_follows_an_outline_that_departs_from_the_templates_shape() {
    // a09_lhip level 3 run 2: a stretch of an outline departs from the round model outline;
    // SRVF's pairs there have large residuals, and kept at full weight they pull the surface
    // onto the outline (0.50 mm; 2.52 with the companion's rule, the largest loss of a scan of
    // the 47 acetabula at levels 1, 3, 5 x 3 runs; a08_lhip's level-1 run 1 was the case until
    // SRVF's pairs the rim makes weighed less).
    let mut prm = ReconParams::default();
    prm.placement.restart_above_px = f64::INFINITY;
    prm.placement.restart_above_folded = f64::INFINITY;
    // Nor the outline guard, whose pose-refinement fallback would rescue the companion too.
    prm.guards = Some(acetab::pipeline::GuardParams {
        max_outline_px: f64::INFINITY,
        ..Default::default()
    });
    let Some(row) = atlas_run("a09_lhip", 3, 2, prm.clone()) else {
        return;
    };
    println!("a09_lhip L3 run 2: MAE {:.3} mm", row.mae_mm);
    assert!(row.mae_mm < 1.0, "MAE {}", row.mae_mm);
    // Companion: the baselines' outlier rule and robust weights on SRVF's pairs drop or damp
    // exactly that stretch, the surface bulges out there, and the same bound rejects it.
    prm.correspond.srvf_outlier_k = Some(prm.correspond.outlier_k);
    prm.robust_srvf = true;
    let damped = atlas_run("a09_lhip", 3, 2, prm).unwrap();
    println!(
        "with the outlier rule and robust weights: MAE {:.3} mm",
        damped.mae_mm
    );
    assert!(damped.mae_mm >= 1.0, "MAE {}", damped.mae_mm);
}

#[test]
fn the_population_prior_left_out_of_its_subject_puts_the_unseen_walls_closer() {
    // a40_lhip (JHU I-STAR pelvis atlas, CC BY 4.0), ideal protocol, level 3 run 1: the shipped
    // prior learned without subject a40 holds the walls no outline watches to the population's
    // shape instead of the bare sphere (measured 0.77 mm without, 0.28 mm with).
    let with = |p: Option<acetab::prior::ShapePrior>| {
        let mut prm = ReconParams::default();
        prm.deformation.shape_prior = p.map(std::sync::Arc::new);
        atlas_row("a40_lhip", 3, 1, prm, acetab::sim::Protocol::Ideal)
    };
    let Some(bare) = with(None) else {
        return;
    };
    let loso = acetab::prior::PriorFile::shipped().without_subject("a40");
    assert!(loso.meshes.iter().all(|m| m.subject != "a40"));
    let prior = with(Some(loso.prior().unwrap())).unwrap();
    // The companion: the same prior with its deviations turned inside out is told apart.
    let mut wrong = loso.clone();
    for m in &mut wrong.meshes {
        for d in m.deviation.iter_mut().flatten() {
            *d = -*d;
        }
    }
    let wrong = with(Some(wrong.prior().unwrap())).unwrap();
    println!(
        "a40_lhip L3 run 1 MAE: bare sphere {:.3}, prior without a40 {:.3}, inverted prior {:.3} mm",
        bare.mae_mm, prior.mae_mm, wrong.mae_mm
    );
    for r in [&bare, &prior, &wrong] {
        assert!(r.error.is_empty(), "{}", r.error);
    }
    assert!(
        prior.mae_mm < 0.6 * bare.mae_mm,
        "{} {}",
        prior.mae_mm,
        bare.mae_mm
    );
    assert!(
        wrong.mae_mm > prior.mae_mm + 0.2,
        "{} {}",
        wrong.mae_mm,
        prior.mae_mm
    );
}

#[test]
fn the_shipped_prior_is_what_prior_build_makes_of_the_shared_populations() {
    // priors/default.json is `acetab prior build ../shared/data/acetabula
    // ../shared/data/pelvis-atlas/acetabula`; rebuilt here entry by entry. The companion: the
    // entry of one mesh compared with another mesh's is told apart.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    let dirs = [root.join("acetabula"), root.join("pelvis-atlas/acetabula")];
    if !dirs.iter().all(|d| d.is_dir()) {
        eprintln!("skipped: {} is absent", root.display());
        return;
    }
    let mut files: Vec<std::path::PathBuf> = Vec::new();
    for d in &dirs {
        let mut v: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "stl"))
            .collect();
        v.sort();
        files.extend(v);
    }
    let shipped = acetab::prior::PriorFile::shipped();
    assert_eq!(shipped.meshes.len(), files.len());
    assert_eq!(shipped.modes, acetab::prior::DEFAULT_MODES);
    let entry = |f: &Path| {
        let stem = f.file_stem().unwrap().to_string_lossy();
        let name = stem.trim_end_matches("_ac_wo_gap").to_string();
        let subject = name.split('_').next().unwrap().to_string();
        let truth = acetab::sim::load_truth(f.to_str().unwrap()).unwrap();
        acetab::prior::PriorMesh::of(&name, &subject, &truth).unwrap()
    };
    for (f, m) in files.iter().zip(&shipped.meshes) {
        assert!(entry(f) == *m, "{}: the shipped entry differs", f.display());
    }
    assert!(entry(&files[0]) != shipped.meshes[1]);
}

#[test]
fn a_mirrored_cap_that_leads_in_stage_a_is_still_compared_with_the_given_one() {
    // a09_rhip (the JHU pelvis atlas) level 5, run 0: the mirrored cap scores clearly better in
    // stage A, so it leads, yet a deformation round tells that the given one meets the outlines
    // better, and that one goes on (the largest gain of the 30 runs of the scan
    // above whose mirrored lead was dropped; a10_rhip's level-3 run 0 was the case until SRVF's
    // pairs were held more along the outline, and no mirrored lead then was wrong enough for a
    // bound on the MAE to tell). Under the settings before SRVF's pairs the rim makes weighed
    // less (`before_rim_pairs`): with them, 11 runs of the scan drop a mirrored lead, the
    // largest gain 0.06 mm (a09_rhip level 3 run 1, 1.045 against 1.107 mm).
    let file = "pelvis-atlas/acetabula/a09_rhip.stl";
    if !compared_with(
        &before_rim_pairs(),
        (file, 5, 0),
        "mirrored",
        "stage A",
        1.0,
    ) {
        return;
    }
    // Companion: without the comparison the mirrored cap goes on alone, uncompared, and the
    // same bound rejects it (2.19 mm when measured).
    let (alone, none) = shared_run(
        file,
        5,
        0,
        &no_comparison_no_restarts_from(before_rim_pairs()),
    )
    .unwrap();
    println!("without the comparison: MAE {alone:.3} mm");
    assert!(none.orientations.is_empty());
    assert!(alone >= 1.0, "MAE {alone}");
}

/// Mean absolute cup error (mm) of the seed-7 study's runs 0-2 at levels 1, 3 and 5 of
/// `truth` with `prm`.
fn mean_cup_error(truth: &acetab::Mesh, prm: &ReconParams) -> f64 {
    use acetab::study::{run_one, run_seed, StudyConfig, StudyMethod, Task};
    let cfg = StudyConfig {
        levels: vec![1, 3, 5],
        runs: 3,
        methods: vec![StudyMethod::Srvf],
        seed: 7,
        uncertainty: None,
        params: prm.clone(),
        ..Default::default()
    };
    let errors: Vec<f64> = [1, 3, 5]
        .into_iter()
        .flat_map(|level| (0..3).map(move |run| (level, run)))
        .map(|(level, run)| {
            let task = Task {
                method: StudyMethod::Srvf,
                level,
                run,
                seed: run_seed(7, level, run),
            };
            let (row, _) = run_one(truth, &task, &cfg, Kernels::Cpu);
            assert!(row.error.is_empty(), "{}", row.error);
            row.cup_diameter_mm - row.gt_cup_diameter_mm
        })
        .collect();
    println!("cup errors {errors:?}");
    errors.iter().map(|e| e.abs()).sum::<f64>() / errors.len() as f64
}

#[test]
fn the_surplus_of_a_template_wider_than_the_acetabulum_does_not_shrink_the_cup() {
    // m2_lhip (LibHip, MIT), the seed-7 study's nine runs at levels 1, 3, 5: the cartilage
    // shell ends 65-80 degrees from its dome, the hemisphere template reaches 90, and the
    // template's surplus beyond the rim forms part of the model outline. SRVF pairs that
    // stretch with the rim's outline, whose rays pass well inside the sphere; at full weight
    // those pairs crush the surplus inwards, and the cup fitted to the observed part shrinks
    // (docs/population.md, "Pairs the rim makes": measured 0.38 mm mean |error| against 0.73
    // with the cup fitted to each held vertex once; 0.30 against 0.52 fitted to one point per
    // pair).
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/acetabula/m2_lhip_ac_wo_gap.stl");
    if !path.exists() {
        eprintln!("skipped: {} is absent", path.display());
        return;
    }
    let truth = acetab::sim::load_truth(path.to_str().unwrap()).unwrap();
    let with = mean_cup_error(&truth, &ReconParams::default());
    println!("rim pairs weighing less: mean |cup error| {with:.3} mm");
    assert!(with < 0.42, "{with}");
    // Companion: with every pair at the alignment's weight the cup comes out smaller, and the
    // same bound rejects it.
    let without = mean_cup_error(&truth, &before_rim_pairs());
    println!("every pair at full weight: mean |cup error| {without:.3} mm");
    assert!(without >= 0.42, "{without}");
}
