//! The case check that the views' outline centres point at one place (`acetab::case::centre_miss`)
//! against every acetabulum of ../shared/data (the LibHip cartilage shells, MIT, and the JHU
//! pelvis atlas's bone-side acetabula, CC BY 4.0): simulated cases under every view set and both
//! protocols stay well inside the bound, and the same cases with one view's outline moved off are
//! refused.

use acetab::case::{
    centre_miss, centre_spread, open_arc, CaseFile, CentreMiss, MAX_CENTRE_MISS, OPEN_ARC_SHARE,
};
use acetab::geom::{longest_segment, widest_extent};
use acetab::sim::{load_truth, NoiseLevel, RealisticErrors, SimCase, SimSetup, XrayGeometry};
use nalgebra::Point2;
use std::path::Path;

/// The shared acetabula's files, or None (with a message) when ../shared is absent.
fn shared_meshes() -> Option<Vec<String>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    let dirs = [root.join("acetabula"), root.join("pelvis-atlas/acetabula")];
    if !dirs.iter().all(|d| d.is_dir()) {
        eprintln!("skipped: {} is absent", root.display());
        return None;
    }
    let mut files: Vec<String> = dirs
        .iter()
        .flat_map(|d| std::fs::read_dir(d).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "stl"))
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    files.sort();
    Some(files)
}

/// Every simulated case of every shared acetabulum: the paper's views, inlet and outlet views, and
/// views 45 degrees apart; the ideal protocol (2 px noise) and the realistic one (pose errors,
/// partial outlines, drift); levels 1 and 5, one draw each.
fn every_case(files: &[String], mut f: impl FnMut(&str, SimCase)) {
    let view_sets = ["z:0,z:20,z:-20", "z:0,x:30,x:-30", "z:0,z:45,z:-45"];
    for file in files {
        let truth = load_truth(file).unwrap();
        for views in view_sets {
            let geometry = XrayGeometry {
                views: views.split(',').map(|v| v.parse().unwrap()).collect(),
                ..Default::default()
            };
            let setup = SimSetup::new(&truth, &geometry).unwrap();
            for level in [1, 5] {
                let lv = NoiseLevel::level(level).unwrap();
                let seed = 11 + level as u64;
                let name = format!("{file} {views} L{level}");
                f(&name, setup.case(2.0, &lv, seed).unwrap());
                let realistic = setup
                    .realistic_case(&truth, &RealisticErrors::default(), &lv, seed)
                    .unwrap();
                f(&format!("{name} realistic"), realistic);
            }
        }
    }
}

#[test]
fn every_shared_acetabulums_views_point_at_one_place_and_one_moved_off_is_refused() {
    let Some(files) = shared_meshes() else {
        return;
    };
    let (mut worst, mut worst_case, mut cases) = (0.0f64, String::new(), 0);
    let mut named = 0;
    every_case(&files, |name, mut case| {
        cases += 1;
        let spread = centre_spread(&case.cameras, &case.observed).unwrap();
        if spread > worst {
            (worst, worst_case) = (spread, name.to_string());
        }
        assert_eq!(centre_miss(&case.cameras, &case.observed), None, "{name}");
        // The companion: view 1's outline annotated 300 px lower (about 50 mm at the object)
        // is refused, and named when the views can tell it.
        for c in &mut case.observed[1] {
            for p in &mut c.points {
                p.y += 300.0;
            }
        }
        match centre_miss(&case.cameras, &case.observed) {
            Some(CentreMiss::View { view, .. }) => {
                assert_eq!(view, 1, "{name}");
                named += 1;
            }
            Some(CentreMiss::Views { .. }) => {}
            None => panic!("{name}: an outline 300 px off passed"),
        }
    });
    println!(
        "{cases} cases: the farthest centre ray {worst:.3} spans off ({worst_case}), the bound \
         {MAX_CENTRE_MISS}; with view 1's outline 300 px lower, {named} named view 1"
    );
    // Measured: 0.34 (a02_rhip, inlet and outlet views, the realistic protocol's partial
    // outlines and pose errors); the bound leaves twice that.
    assert!(worst < 0.6 * MAX_CENTRE_MISS, "{worst} ({worst_case})");
}

/// A closed outline's longest step as a share of its width (what `open_arc` measures first),
/// for the report.
fn longest_share(p: &[Point2<f64>]) -> f64 {
    longest_segment(p).unwrap().1 / widest_extent(p)
}

/// No closed outline simulated from the shared acetabula looks like an open arc closed by its
/// chord (the largest share is where one straight step spans the notch); the companion: the
/// same outlines cut to their first half of points and left closed mostly do (measured: 610 of
/// 846; cut to 60 / 70 / 80 %, 464 / 254 / 29: the check is a warning for the clear cases).
#[test]
fn closed_outlines_do_not_look_like_open_arcs_and_their_cut_arcs_do() {
    let Some(files) = shared_meshes() else {
        return;
    };
    let (mut worst, mut outlines) = (0.0f64, 0);
    let mut flagged = [0usize; 4];
    every_case(&files, |name, case| {
        for c in case.observed.iter().flatten().filter(|c| c.closed) {
            outlines += 1;
            worst = worst.max(longest_share(&c.points));
            assert_eq!(open_arc(&c.points), None, "{name}");
            for tenths in [5usize, 6, 7, 8] {
                let cut = &c.points[..c.points.len() * tenths / 10];
                if open_arc(cut).is_some() {
                    flagged[tenths - 5] += 1;
                }
            }
        }
    });
    eprintln!("{outlines} closed outlines; largest step's share of the width at most {worst:.3} (bound {OPEN_ARC_SHARE}); cut to their first 50 / 60 / 70 / 80 % of points and left closed, warned: {flagged:?}");
    assert!(2 * flagged[0] > outlines, "{flagged:?} of {outlines}");
    assert!(flagged[0] >= flagged[1] && flagged[1] >= flagged[3]);
}

/// The example case with its first view's closed outline cut to 60 % of the rim (an open arc
/// left marked closed) is read with a warning naming that outline; the companion: the case as
/// it is is read without one.
#[test]
fn a_closed_outline_that_is_an_open_arc_is_named_in_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/case/case.json");
    let mut case: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&example).unwrap()).unwrap();
    for v in case["views"].as_array_mut().unwrap() {
        v.as_object_mut().unwrap().remove("image");
    }
    let write = |case: &serde_json::Value, name: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, case.to_string()).unwrap();
        p
    };
    let whole = CaseFile::load(&write(&case, "whole.json")).unwrap();
    assert!(
        !whole.warnings.iter().any(|w| w.contains(".closed")),
        "{:?}",
        whole.warnings
    );
    assert_eq!(case["views"][0]["contours"][0]["closed"], true);
    let points = case["views"][0]["contours"][0]["points"]
        .as_array_mut()
        .unwrap();
    let keep = points.len() * 6 / 10;
    points.truncate(keep);
    let cut = CaseFile::load(&write(&case, "cut.json")).unwrap();
    assert!(
        cut.warnings
            .iter()
            .any(|w| w.contains("views[0].contours[0].closed") && w.contains("\"closed\": false")),
        "{:?}",
        cut.warnings
    );
}
