//! The command line: the demo's JSON, a case file through `acetab reconstruct`, and bad input.

use acetab::case::CaseFile;
use acetab::sim::{phantom, PhantomParams};
use std::path::{Path, PathBuf};
use std::process::Command;

/// A study of one srvf run at level 1 on one thread.
const ONE_RUN: &str = "--levels 1 --runs 1 --methods srvf --threads 1";

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_acetab"))
}

/// A scratch folder (tempfile), removed when the test ends (kept when it fails, to look at).
struct Scratch(Option<tempfile::TempDir>);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.as_ref().expect("present until drop").path()
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        std::ops::Deref::deref(self).as_os_str()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if let Some(t) = self.0.take().filter(|_| std::thread::panicking()) {
            eprintln!("scratch folder kept: {}", t.keep().display());
        }
    }
}

fn tmp(tag: &str) -> Scratch {
    let t = tempfile::Builder::new()
        .prefix(&format!("acetab-cli-{tag}-"))
        .tempdir()
        .unwrap();
    Scratch(Some(t))
}

fn phantom_case(dir: &Path) -> PathBuf {
    let (_truth, sim) = acetab::sim::phantom_case(2, 4).unwrap();
    let file = CaseFile::from_parts(&sim.cameras, &sim.observed, &sim.init);
    let path = dir.join("case.json");
    std::fs::write(&path, serde_json::to_string_pretty(&file).unwrap()).unwrap();
    path
}

#[test]
fn demo_json_has_the_documented_fields_and_writes_its_files() {
    let out = tmp("demo");
    let o = bin()
        .args(["demo", "--json", "--seed", "7", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for k in [
        "mae_mm",
        "sd_mm",
        "p95_mm",
        "cup_diameter_mm",
        "gt_cup_diameter_mm",
        "seconds",
    ] {
        assert!(
            v[k].as_f64().is_some_and(|x| x.is_finite()),
            "{k}: {}",
            v[k]
        );
    }
    assert_eq!(v["seed"], 7);
    for f in [
        "reconstruction.ply",
        "reconstruction.png",
        "truth.ply",
        "report.json",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let ply = std::fs::read_to_string(out.join("reconstruction.ply")).unwrap();
    assert!(ply.contains("property uchar red") && ply.contains("property float error_mm"));
    // The 3D picture: two viewpoints and a colour bar, 990 x 460.
    let png = image::open(out.join("reconstruction.png")).unwrap();
    assert_eq!((png.width(), png.height()), (990, 460));
}

#[test]
fn a_case_file_reconstructs_through_the_cli() {
    let dir = tmp("case");
    let case = phantom_case(&dir);
    let out = dir.join("out");
    let o = bin()
        .arg("reconstruct")
        .arg(&case)
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let d = v["cup"]["diameter_mm"].as_f64().unwrap();
    // The phantom's fitted sphere is 52.45 mm across. The shipped realistic calibration, used by
    // default, corrects the fitted cup (its bias and shrink, reported beside it): undone, the
    // fitted cup is the phantom's.
    let (bias, shrink, to) = (
        v["cup"]["bias_mm"].as_f64().unwrap(),
        v["cup"]["shrink"].as_f64().unwrap(),
        v["cup"]["shrink_to_mm"].as_f64().unwrap(),
    );
    let shipped = acetab::pipeline::CupCalibration::shipped_realistic();
    assert_eq!(
        (bias, shrink, to),
        (shipped.bias_mm, shipped.shrink, shipped.shrink_to_mm)
    );
    let fitted = (d + bias - shrink * to) / (1.0 - shrink);
    assert!((fitted - 52.45).abs() < 2.0, "cup {d}, fitted {fitted}");
    // The cup report: a +- and probabilities over the catalogue sizes that sum to one.
    // Where it came from: the version and this command line.
    assert_eq!(v["provenance"]["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(v["provenance"]["command_line"][1], "reconstruct");
    assert_eq!(v["provenance"]["backend"], "cpu");
    let pm = v["cup"]["plus_minus_mm"].as_f64().unwrap();
    assert!(pm.is_finite() && pm >= 0.0);
    let p: f64 = v["cup"]["probabilities"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["probability"].as_f64().unwrap())
        .sum();
    assert!((p - 1.0).abs() < 1e-9, "probabilities sum to {p}");
    // The cup's centre and orientation: the phantom opens at 45 deg inclination, 20 deg
    // anteversion (its design axis); the rim fit is within 4 deg of each.
    let o = &v["cup"]["orientation"];
    let (i, a) = (
        o["inclination_deg"].as_f64().unwrap(),
        o["anteversion_deg"].as_f64().unwrap(),
    );
    assert!((i - 45.0).abs() < 4.0 && (a - 20.0).abs() < 4.0, "{o}");
    assert_eq!(v["cup"]["center_mm"], v["sphere"]["center"]);
    assert!(o["rms_px"].as_f64().unwrap() >= 0.0, "{o}");
    for f in [
        "reconstruction.ply",
        "report.json",
        "cup.json",
        "overlay-0-view0.png",
        "reconstruction.png",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    assert_eq!(v["cup"]["estimator"], "observed-part");
    assert_eq!(v["cup"]["bias_mm"], shipped.bias_mm);
    // The correction is the cup's size, not its geometry: without a calibration the orientation
    // is the same, the diameter is the fitted one (the companion: another number).
    let o = bin()
        .arg("reconstruct")
        .arg(&case)
        .args(["--calibration", "none", "--json", "--out"])
        .arg(dir.join("uncalibrated"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let raw: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // (The calibration's depth offset moves the cup, not the rim's orientation, which is read on
    // the fit's sphere: the same to rounding.)
    for k in ["inclination_deg", "anteversion_deg", "offset_mm", "rms_px"] {
        let (a, b) = (&raw["cup"]["orientation"][k], &v["cup"]["orientation"][k]);
        assert!(
            (a.as_f64().unwrap() - b.as_f64().unwrap()).abs() < 1e-6,
            "{k}: {a} {b}"
        );
    }
    let raw_d = raw["cup"]["diameter_mm"].as_f64().unwrap();
    assert!((raw_d - fitted).abs() < 1e-9, "{raw_d} {fitted}");
    assert!((raw_d - d).abs() > 0.5, "{raw_d} {d}");
    // The prior-region cup says so, with the shipped realistic calibration's bias; its cup is
    // another number (the companion).
    let o = bin()
        .arg("reconstruct")
        .arg(&case)
        .args([
            "--prior",
            "default",
            "--cup-estimator",
            "prior-region",
            "--json",
        ])
        .args(["--uncertainty-samples", "2", "--out"])
        .arg(dir.join("region"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["cup"]["estimator"], "prior-region");
    let bias = acetab::pipeline::CupCalibration::shipped_realistic_prior_region().bias_mm;
    assert_eq!(r["cup"]["bias_mm"], bias);
    assert!(
        (r["cup"]["diameter_mm"].as_f64().unwrap() - d).abs() > 1e-3,
        "{r}"
    );
    // A catalogue that cannot hold the cup is refused, naming its range; nothing is written.
    let mut cmd = bin();
    cmd.arg("reconstruct")
        .arg(&case)
        .args(["--catalogue", "60:70:2"]);
    fails_cleanly(
        cmd,
        &dir.join("small"),
        &["outside the catalogue's 60-70 mm", "no size is given"],
    );
}

#[test]
fn a_bad_case_fails_cleanly_and_writes_nothing() {
    let dir = tmp("bad");
    let case = phantom_case(&dir);
    let good: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&case).unwrap()).unwrap();
    let mut cases: Vec<(&str, String)> = Vec::new();
    let mut v = good.clone();
    v["views"][1]["k"]["fx"] = serde_json::json!(-5500.0);
    cases.push(("views[1].k.fx", v.to_string()));
    let mut v = good.clone();
    v["views"][0]["r"][0][0] = serde_json::json!(0.5);
    cases.push(("not orthonormal", v.to_string()));
    let mut v = good.clone();
    for c in 0..3 {
        let x = v["views"][0]["r"][0][c].as_f64().unwrap();
        v["views"][0]["r"][0][c] = serde_json::json!(-x);
    }
    cases.push(("reflection", v.to_string()));
    let mut v = good.clone();
    v["views"][2]["contours"][0]["points"] =
        serde_json::json!([[1000.0, 1000.0], [1000.0, 1000.0]]);
    cases.push(("views[2].contours[0].points", v.to_string()));
    let mut v = good.clone();
    v["template"].as_object_mut().unwrap().remove("radius");
    cases.push(("radius", v.to_string()));
    cases.push(("invalid JSON", good.to_string()[..200].to_string()));
    // Three copies of one view: no depth to recover.
    let mut v = good.clone();
    let first = v["views"][0].clone();
    v["views"] = serde_json::json!([first, first, first]);
    cases.push(("the views look along the same direction", v.to_string()));
    // The source inside the template: part of it cannot be projected.
    let mut v = good.clone();
    let t = v["views"][0]["t"][2].as_f64().unwrap();
    v["views"][0]["t"][2] = serde_json::json!(t - 880.0);
    cases.push(("reaches to or behind the source", v.to_string()));
    for (needle, text) in cases {
        let path = dir.join("bad.json");
        std::fs::write(&path, text).unwrap();
        let out = dir.join("bad-out");
        let mut cmd = bin();
        cmd.arg("reconstruct").arg(&path);
        fails_cleanly(cmd, &out, &[needle, "bad.json"]);
    }
}

#[test]
fn an_out_that_cannot_be_made_is_refused_before_the_work() {
    let dir = tmp("unwritable");
    let case = phantom_case(&dir);
    std::fs::write(dir.join("a-file"), b"x").unwrap();
    let mut cmd = bin();
    cmd.arg("reconstruct").arg(&case);
    fails_cleanly(cmd, &dir.join("a-file/out"), &["--out", "is not a folder"]);
    // The companion: missing folders above --out are made.
    let o = bin()
        .arg("reconstruct")
        .arg(&case)
        .args(["--uncertainty-samples", "2", "--out"])
        .arg(dir.join("new/deeper/out"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("new/deeper/out/report.json").is_file());
}

#[test]
fn a_view_whose_outline_disagrees_with_the_others_is_named_in_a_warning() {
    let dir = tmp("disagree");
    let case = phantom_case(&dir);
    let run = |case: &Path, out: &str| {
        let o = bin()
            .arg("reconstruct")
            .arg(case)
            .args(["--uncertainty-samples", "2", "--out"])
            .arg(dir.join(out))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let report: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(out).join("report.json")).unwrap(),
        )
        .unwrap();
        (String::from_utf8_lossy(&o.stderr).to_string(), report)
    };
    // As simulated, the views agree: no warning, and each view's outline distance is reported.
    let (err, report) = run(&case, "agree");
    assert!(!err.contains("do not agree"), "{err}");
    assert!(report["pose_prior"].is_null(), "{report}");
    assert_eq!(
        report["log"]["outline_px_per_view"]
            .as_array()
            .unwrap()
            .len(),
        3
    );
    // View 1's annotation moved `dy` px down, as a case file named `name`.
    let moved_by = |dy: f64, name: &str| {
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&case).unwrap()).unwrap();
        for p in v["views"][1]["contours"][0]["points"]
            .as_array_mut()
            .unwrap()
        {
            p[1] = serde_json::json!(p[1].as_f64().unwrap() + dy);
        }
        let path = dir.join(format!("{name}.json"));
        std::fs::write(&path, v.to_string()).unwrap();
        run(&path, name)
    };
    // 40 px: the views cannot meet one shape there. Its result's outlines lie far from the
    // annotations, so the poses are refined (the refine-poses fallback), and the warning names
    // the view that moved most.
    let (err, report) = moved_by(40.0, "moved");
    assert_eq!(report["log"]["fallback"], "refine-poses", "{report}");
    // The report says under which prior the fallback refined them (the default's).
    assert_eq!(
        report["pose_prior"],
        serde_json::json!([2.0, 5.0]),
        "{report}"
    );
    assert!(
        err.contains("warning: no shape met the views")
            && err.contains("view 1 (view1) moved most"),
        "{err}"
    );
    let moves = report["log"]["pose_corrections"].as_array().unwrap();
    let mm = |k: usize| moves[k][1].as_f64().unwrap();
    assert!(mm(1) > 2.0 * mm(2).max(mm(0)), "{moves:?}");
    assert!(
        report["log"]["outline_px"].as_f64().unwrap() < 3.0,
        "{report}"
    );
    // Companion, 20 px (half as far): the views still meet one shape about as well as the
    // method meets them, so no fallback.
    let (err, report) = moved_by(20.0, "nudged");
    assert!(report["log"]["fallback"].is_null(), "{report}");
    assert!(!err.contains("no shape met the views"), "{err}");
}

/// The example case with its images left out, written as DIR/case.json: the file and its JSON.
fn example_without_images(dir: &Path) -> (PathBuf, serde_json::Value) {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/case/case.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(example).unwrap()).unwrap();
    for view in v["views"].as_array_mut().unwrap() {
        view.as_object_mut().unwrap().remove("image");
    }
    let case = dir.join("case.json");
    std::fs::write(&case, v.to_string()).unwrap();
    (case, v)
}

#[test]
fn annotations_given_to_the_wrong_views_are_refused_with_the_reason() {
    let dir = tmp("swapped");
    // The example case (its images left out), and the same with the AP view's annotation and
    // the +20 degree oblique's swapped.
    let (case, mut v) = example_without_images(&dir);
    let first = v["views"][0]["contours"].take();
    v["views"][0]["contours"] = v["views"][1]["contours"].take();
    v["views"][1]["contours"] = first;
    let swapped = dir.join("swapped.json");
    std::fs::write(&swapped, v.to_string()).unwrap();
    let run = |case: &Path, out: &str| {
        bin()
            .arg("reconstruct")
            .arg(case)
            .args(["--uncertainty-samples", "2", "--out"])
            .arg(dir.join(out))
            .output()
            .unwrap()
    };
    // Swapped: a surface meets all three outlines only by crumpling or by leaving the
    // outlines' limb sphere (the cup fitted to one point per pair: 13.7 mm off it); refused,
    // nothing written, and the reason names the likely cause.
    let o = run(&swapped, "swapped");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("swapped.json")
            && err.contains("refused")
            && (err.contains("crumpled") || err.contains("limb sphere"))
            && err.contains("wrong view"),
        "{err}"
    );
    assert!(!dir.join("swapped").exists());
    // Companion: the case as it is gives its result.
    let o = run(&case, "as-is");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("as-is").join("report.json").exists());
}

/// A contour's points, pixels.
type Rim = Vec<[f64; 2]>;

/// The example case `v` with its AP view's closed rim changed by `f`, written as `dir/name`.
fn with_ap_rim(
    dir: &Path,
    v: &serde_json::Value,
    name: &str,
    f: impl Fn(&[[f64; 2]]) -> Rim,
) -> PathBuf {
    let mut v = v.clone();
    let rim = &mut v["views"][0]["contours"][0]["points"];
    let p: Rim = serde_json::from_value(rim.clone()).unwrap();
    *rim = serde_json::to_value(f(&p)).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, v.to_string()).unwrap();
    path
}

/// The mean of a rim's points.
fn rim_centre(p: &[[f64; 2]]) -> [f64; 2] {
    let n = p.len() as f64;
    p.iter()
        .fold([0.0, 0.0], |a, q| [a[0] + q[0] / n, a[1] + q[1] / n])
}

#[test]
fn a_rim_joined_on_backwards_is_refused_and_a_dented_one_is_read() {
    let dir = tmp("crossing");
    let (_, v) = example_without_images(&dir);
    // The AP view's closed rim (158 points) changed two ways: a quarter of it pushed 40 % of the
    // way to its centre (a deep dent, 91 % of its hull), and its second half joined on
    // backwards (a figure of eight, 22 %).
    let dented = with_ap_rim(&dir, &v, "dented.json", |p| {
        let c = rim_centre(p);
        p.iter()
            .enumerate()
            .map(|(i, q)| match i {
                20..60 => [q[0] + 0.4 * (c[0] - q[0]), q[1] + 0.4 * (c[1] - q[1])],
                _ => *q,
            })
            .collect()
    });
    let backwards = with_ap_rim(&dir, &v, "backwards.json", |p| {
        let h = p.len() / 2;
        p[..h].iter().chain(p[h..].iter().rev()).copied().collect()
    });
    let err = CaseFile::load(&backwards).unwrap_err().to_string();
    assert!(
        err.contains("backwards.json")
            && err.contains("field views[0].contours[0].points = 158 points enclosing")
            && err.contains("cross itself"),
        "{err}"
    );
    // Companion: a deep dent, as an annotator may trace round a notch, is read.
    let case = CaseFile::load(&dented).unwrap();
    assert_eq!(case.observed[0][0].points.len(), 158);
}

#[test]
fn an_outline_at_another_scale_is_refused_naming_its_view() {
    let dir = tmp("scale");
    let (_, v) = example_without_images(&dir);
    // The AP view's closed rim scaled about its centre: to 0.3 (an annotation at another scale,
    // or a focal length off by as much), and to 0.7 (within what views of one acetabulum show).
    let scaled = |f: f64| {
        with_ap_rim(&dir, &v, &format!("scaled{f}.json"), |p| {
            let c = rim_centre(p);
            p.iter()
                .map(|q| [c[0] + f * (q[0] - c[0]), c[1] + f * (q[1] - c[1])])
                .collect()
        })
    };
    let err = CaseFile::load(&scaled(0.3)).unwrap_err().to_string();
    assert!(
        err.contains("field views[0].contours[0].points = an outline of view AP spanning")
            && err.contains("another scale"),
        "{err}"
    );
    // Companion: 0.7 is read.
    assert!(CaseFile::load(&scaled(0.7)).is_ok());
    // Scaled to half it is read too (on the bound), and no shape meets all three outlines: the
    // refusal gives each view's outline distance, by the views' names.
    let o = bin()
        .arg("reconstruct")
        .arg(scaled(0.5))
        .args(["--uncertainty-samples", "2", "--out"])
        .arg(dir.join("half"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("the result was refused: ")
            && err.contains("; its outlines lay from the annotations: view 0 (AP) ")
            && err.contains(", view 2 (oblique -20) "),
        "{err}"
    );
    assert!(!dir.join("half").exists());
}

#[test]
fn the_uncertainty_does_not_depend_on_where_or_which_way_an_annotation_runs() {
    let dir = tmp("starts");
    // The example case (its images left out): its closed outlines started a third of the way
    // round and its open arc traced the other way give the same cup report, uncertainty
    // included, to the bit (the outlines are entered at a fixed point and turned one way before
    // anything reads them; the noise is how far the result's outlines lie from them).
    let (_, v) = example_without_images(&dir);
    let report = |v: &serde_json::Value, out: &str| -> serde_json::Value {
        let case = dir.join(format!("{out}.json"));
        std::fs::write(&case, v.to_string()).unwrap();
        let o = bin()
            .arg("reconstruct")
            .arg(&case)
            .args([
                "--uncertainty-samples",
                "2",
                "--calibration",
                "none",
                "--out",
            ])
            .arg(dir.join(out))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_str(&std::fs::read_to_string(dir.join(out).join("report.json")).unwrap())
            .unwrap()
    };
    let given = report(&v, "given");
    let mut retraced = v.clone();
    for view in retraced["views"].as_array_mut().unwrap() {
        let contour = &mut view["contours"][0];
        let closed = contour["closed"].as_bool().unwrap();
        let pts = contour["points"].as_array_mut().unwrap();
        if closed {
            let n = pts.len();
            pts.rotate_left(n / 3);
        } else {
            pts.reverse();
        }
    }
    let turned = report(&retraced, "turned");
    assert!(given["cup"]["noise_px"].as_f64().unwrap() > 0.0);
    assert_eq!(given["cup"], turned["cup"]);
    // Companion: one annotated point moved 3 px moves the report, and the same comparison
    // tells it apart.
    let mut moved = v.clone();
    let p = &mut moved["views"][0]["contours"][0]["points"][10];
    p[0] = serde_json::json!(p[0].as_f64().unwrap() + 3.0);
    let shifted = report(&moved, "moved");
    assert_ne!(given["cup"], shifted["cup"]);
}

/// `cmd --out out` exits with 1, its error holds every needle, and `out` is not written.
fn fails_cleanly(cmd: Command, out: &Path, needles: &[&str]) {
    fails_cleanly_with(cmd, out, needles, 1)
}

/// As `fails_cleanly`, with exit code `code`.
fn fails_cleanly_with(mut cmd: Command, out: &Path, needles: &[&str], code: i32) {
    let o = cmd.arg("--out").arg(out).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(code), "{needles:?}: {err}");
    assert!(
        needles.iter().all(|n| err.contains(n)),
        "{needles:?}: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out.exists(), "{needles:?}: output folder written");
}

/// A message that quotes something with a control character in it (here the case's own path,
/// as a corrupt DICOM file's bytes are quoted) reaches the terminal escaped, not as the raw
/// escape code. Companion: the same message printed raw is rejected by the same check.
#[test]
fn an_error_quoting_a_control_character_prints_it_escaped() {
    let dir = tmp("ctrl");
    let path = dir.join("no\u{1b}[2Jsuch.json");
    let out = dir.join("ctrl-out");
    let mut cmd = bin();
    cmd.arg("reconstruct").arg(&path);
    fails_cleanly(cmd, &out, &["no\\u{1b}[2Jsuch.json", "cannot read"]);
    let o = bin()
        .arg("reconstruct")
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let shows_escaped =
        |text: &str| text.contains("no\\u{1b}[2Jsuch.json") && !text.contains('\u{1b}');
    assert!(shows_escaped(&err), "{err:?}");
    // Companion: the same message printed raw, as before the escaping, is rejected.
    let raw = format!("error: cannot read {}", path.display());
    assert!(!shows_escaped(&raw), "{raw:?}");
}

#[test]
fn simulate_names_a_bad_list_entry_and_writes_nothing() {
    let dir = tmp("list");
    let out = dir.join("study");
    for (flag, value, needle) in [
        (
            "--methods",
            "srvf,icp-papr",
            "\"icp-papr\" (expected srvf, icp",
        ),
        ("--levels", "1,6", "\"6\" (expected levels 1 to 5)"),
        ("--levels", "1,,2", "cannot read \"\""),
        ("--methods", "srvf,icp,SRVF", "\"SRVF\" is listed twice"),
        ("--runs", "4000000000", "4000000000 is not in 1..=100000"),
        ("--threads", "0", "0 is not in 1..=1024"),
        ("--coarse-nodes", "1", "1 is not in 2..=150"),
        ("--correspondence-updates", "0", "0 is not in 1..=50"),
        ("--srvf-samples", "7", "7 is not in 8..=2000"),
        ("--batch", "0", "0 is not in 1..=1024"),
        ("--shard", "3/2", "expected I/N with 0 <= I < N"),
        (
            "--uncertainty-samples",
            "1001",
            "expected 0 (off) or 2 to 1000",
        ),
        ("--uncertainty-samples", "1", "one resample has no spread"),
        ("--views", "z:0,q:3", "cannot read \"q:3\""),
        (
            "--views",
            "z:0,y:30",
            "at least two views 15 degrees or more apart",
        ),
        ("--views", "z:0,z:1.5", "15 degrees or more apart"),
        ("--views", "z:0,z:6,z:-6", "15 degrees or more apart"),
        (
            "--views",
            "z:0,z:400,z:-20",
            "\"400\": the angle must be degrees from -180 to 180",
        ),
    ] {
        let mut cmd = bin();
        cmd.args(["simulate", "--gt", "phantom", flag, value]);
        // clap's value parsers refuse them: a usage error, exit 2.
        fails_cleanly_with(cmd, &out, &[flag, needle], 2);
    }
    // The pose refinement's prior: two SDs above 0, and only with the refinement.
    for (value, needle) in [
        (
            "1,-2",
            "translation SD (mm) \"-2\" must be a number above 0",
        ),
        (
            "nan,5",
            "rotation SD (degrees) \"nan\" must be a number above 0",
        ),
        ("2", "expected DEG,MM"),
    ] {
        let mut cmd = bin();
        cmd.args(["simulate", "--gt", "phantom", "--refine-poses"]);
        cmd.args(["--pose-prior", value]);
        fails_cleanly_with(cmd, &out, &["--pose-prior", needle], 2);
    }
    let mut cmd = bin();
    cmd.args(["simulate", "--gt", "phantom", "--pose-prior", "1,2"]);
    fails_cleanly_with(cmd, &out, &["--refine-poses"], 2);
    // The DPs on a device that the study does not open.
    let mut cmd = bin();
    cmd.args(["simulate", "--gt", "phantom", "--dp", "device"]);
    fails_cleanly_with(cmd, &out, &["--dp device", "--backend gpu"], 1);
    let mut cmd = bin();
    cmd.args(["simulate", "--gt", "phantom", "--batch", "8"]);
    fails_cleanly_with(cmd, &out, &["--batch 8", "--backend gpu"], 1);
    // The share that makes a pair the rim's: of the sphere's radius, 0 (off) to 1.
    for value in ["1.5", "nan"] {
        let mut cmd = bin();
        cmd.args(["simulate", "--gt", "phantom", "--rim-pairs", value]);
        fails_cleanly_with(cmd, &out, &["--rim-pairs", "[0, 1]"], 1);
    }
}

#[test]
fn bench_names_a_bad_size_before_looking_for_an_adapter() {
    for (flag, value, needle) in [
        (
            "--dp-batches",
            "1,0",
            "cannot read \"0\" (expected sizes 1 to 1000000)",
        ),
        ("--mesh-sizes", "500,500", "\"500\" is listed twice"),
        ("--threads", "0", "0 is not in 1..=1024"),
    ] {
        let o = bin().args(["bench", flag, value]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains(flag) && err.contains(needle), "{err}");
    }
}

#[test]
fn align_reports_a_rotation_and_rejects_a_bad_file() {
    let dir = tmp("align");
    let blob = |n: usize, rot: f64, shift: usize| -> String {
        let mut s = String::from("x,y\n");
        for i in 0..n {
            let t = std::f64::consts::TAU * ((i + shift) % n) as f64 / n as f64;
            let r = 1.0 + 0.3 * (2.0 * t).cos() + 0.15 * (3.0 * t + 0.4).sin();
            let (x, y) = (r * t.cos(), 0.8 * r * t.sin());
            s += &format!(
                "{},{}\n",
                rot.cos() * x - rot.sin() * y,
                rot.sin() * x + rot.cos() * y
            );
        }
        s
    };
    std::fs::write(dir.join("a.csv"), blob(300, 0.0, 0)).unwrap();
    std::fs::write(dir.join("b.csv"), blob(250, 0.5, 70)).unwrap();
    let o = bin()
        .arg("align")
        .arg(dir.join("a.csv"))
        .arg(dir.join("b.csv"))
        .args(["--json", "--samples", "120"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["distance"].as_f64().unwrap() < 0.02);
    assert!(
        (v["rotation_deg"].as_f64().unwrap() + 0.5f64.to_degrees()).abs() < 2.0,
        "{}",
        v["rotation_deg"]
    );
    assert_eq!(v["gamma"].as_array().unwrap().len(), 120);
    assert_eq!(v["aligned"].as_array().unwrap().len(), 120);
    std::fs::write(dir.join("bad.csv"), "x,y\n1,2\n3,four\n5,6\n").unwrap();
    let o = bin()
        .arg("align")
        .arg(dir.join("a.csv"))
        .arg(dir.join("bad.csv"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(err.contains("bad.csv") && err.contains("line 3"), "{err}");
    // A sample count whose seed search would not finish is refused at once.
    let o = bin()
        .arg("align")
        .arg(dir.join("a.csv"))
        .arg(dir.join("b.csv"))
        .args(["--samples", "100000000"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("--samples 100000000: must be 8 to 50000"),
        "{err}"
    );
    // A negative position weight is a usage error naming it; a positive one aligns.
    let o = bin()
        .arg("align")
        .arg(dir.join("a.csv"))
        .arg(dir.join("b.csv"))
        .arg("--anchor=-1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("--anchor") && err.contains("-1"), "{err}");
    let o = bin()
        .arg("align")
        .arg(dir.join("a.csv"))
        .arg(dir.join("a.csv"))
        .args(["--json", "--samples", "120", "--anchor", "3"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["distance"].as_f64().unwrap() < 0.02, "{}", v["distance"]);
}

/// A ground truth in the wrong units (the phantom in centimetres) is refused with the radius
/// found; the same phantom in millimetres runs (the companion that keeps the refusal from firing
/// always).
#[test]
fn simulate_refuses_a_ground_truth_in_the_wrong_units() {
    let dir = tmp("units");
    let mut mesh = phantom(&PhantomParams::default()).mesh;
    acetab::io::write_obj(&mesh, &dir.join("mm.obj")).unwrap();
    for v in &mut mesh.vertices {
        *v = nalgebra::Point3::from(v.coords * 0.1);
    }
    acetab::io::write_obj(&mesh, &dir.join("cm.obj")).unwrap();
    let mut cmd = bin();
    cmd.arg("simulate")
        .args(ONE_RUN.split(' '))
        .arg("--gt")
        .arg(dir.join("cm.obj"));
    fails_cleanly(
        cmd,
        &dir.join("out-cm"),
        &[
            "cm.obj",
            "radius is 2.6",
            "outside the 15-60 mm",
            "millimetres?",
        ],
    );
    let o = bin()
        .arg("simulate")
        .args(ONE_RUN.split(' '))
        .arg("--gt")
        .arg(dir.join("mm.obj"))
        .arg("--out")
        .arg(dir.join("out-mm"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `acetab merge` through the CLI: two shards merge into a new folder; merging into one of the
/// shards (which would overwrite its tables) and a shard with an unreadable cell are refused,
/// naming the folder or the column, and leave the shard as it was.
#[test]
fn merge_joins_shards_and_refuses_to_overwrite_one_or_read_a_bad_cell() {
    let dir = tmp("merge");
    for i in 0..2 {
        let o = bin()
            .args([
                "simulate", "--gt", "phantom", "--levels", "1", "--runs", "2",
            ])
            .args(["--methods", "srvf", "--threads", "1", "--shard"])
            .arg(format!("{i}/2"))
            .arg("--out")
            .arg(dir.join(format!("s{i}")))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let merge = |shards: &[&str], out: &Path| {
        let mut c = bin();
        c.arg("merge");
        for s in shards {
            c.arg(dir.join(s));
        }
        c.arg("--out").arg(out).output().unwrap()
    };
    let o = merge(&["s0", "s1"], &dir.join("all"));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let all = std::fs::read_to_string(dir.join("all/runs.csv")).unwrap();
    assert_eq!(all.lines().count(), 3, "header and two runs: {all}");
    // A shard set with a gap is refused, naming the missing shard.
    let o = merge(&["s1"], &dir.join("gap"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("shards 0/2 of 2 are missing"), "{err}");
    assert!(!dir.join("gap").exists());
    // Every shard there, but one cut short (its runs.csv only the header): refused, naming
    // the runs it lacks, nothing written.
    std::fs::create_dir_all(dir.join("s1cut")).unwrap();
    std::fs::copy(dir.join("s1/summary.json"), dir.join("s1cut/summary.json")).unwrap();
    let header = all.lines().next().unwrap().to_string() + "\n";
    std::fs::write(dir.join("s1cut/runs.csv"), header).unwrap();
    let o = merge(&["s0", "s1cut"], &dir.join("cut"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("1 of the study's 2 runs") && err.contains("srvf level 1 run 1"),
        "{err}"
    );
    assert!(!dir.join("cut").exists());
    // One mesh given relatively to one shard and absolutely to the other: the same study.
    let mesh = dir.join("m.obj");
    acetab::io::write_obj(&phantom(&PhantomParams::default()).mesh, &mesh).unwrap();
    for (i, gt) in [(0, mesh.clone()), (1, PathBuf::from("m.obj"))] {
        let o = bin()
            .current_dir(&*dir)
            .arg("simulate")
            .arg("--gt")
            .arg(&gt)
            .args([
                "--levels",
                "1",
                "--runs",
                "2",
                "--methods",
                "srvf",
                "--threads",
                "1",
            ])
            .args(["--uncertainty-samples", "0", "--shard"])
            .arg(format!("{i}/2"))
            .arg("--out")
            .arg(dir.join(format!("m{i}")))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let o = merge(&["m0", "m1"], &dir.join("m-all"));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The truth's cup and its outline-vertex sphere travel with the settings; the phantom is
    // wider in depth than the views see, so the two differ.
    let study: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("all/summary.json")).unwrap())
            .unwrap();
    // Every run carries its cup uncertainty (16 resamples by default).
    let s0 = &study["summary"][0];
    assert_eq!(s0["cup_sd_runs"], 2, "{s0}");
    assert!(s0["brier_mean"]
        .as_f64()
        .is_some_and(|b| (0.0..=2.0).contains(&b)));
    let truth = study["study"]["truth_cup_diameter_mm"].as_f64().unwrap();
    let outline = study["study"]["truth_outline_sphere_diameter_mm"]
        .as_f64()
        .unwrap();
    assert!(
        (40.0..70.0).contains(&truth) && (truth - outline).abs() > 0.5,
        "{truth} {outline}"
    );

    let before = std::fs::read_to_string(dir.join("s0/runs.csv")).unwrap();
    let o = merge(&["s0", "s1"], &dir.join("s0"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("is the shard folder"), "{err}");
    let after = std::fs::read_to_string(dir.join("s0/runs.csv")).unwrap();
    assert_eq!(before, after, "the shard was overwritten");

    let bad = std::fs::read_to_string(dir.join("s1/runs.csv"))
        .unwrap()
        .replace(",true,", ",yes,");
    std::fs::write(dir.join("s1/runs.csv"), bad).unwrap();
    let o = merge(&["s0", "s1"], &dir.join("bad"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("column \"converged\": \"yes\""), "{err}");
    assert!(!dir.join("bad").exists(), "output written for a bad shard");
}

/// A pose study whose every run fails (views shifted a kilometre) is an error, not a table of
/// nothing with exit 0; the same study with the default shift succeeds (the companion). A turn
/// beyond 180 degrees is refused before any run, naming the flag; 180 is not (the companion).
#[test]
fn pose_study_with_every_run_failed_is_an_error() {
    let run = |flag: &str, value: &str| {
        bin()
            .args(["pose-study", "--runs", "1", "--threads", "1", flag, value])
            .output()
            .unwrap()
    };
    let o = run("--mm", "1000000");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("pose-study: all 1 runs failed"), "{err}");
    let o = run("--mm", "5");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run("--deg", "1e9");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("--deg 1000000000: must be at most 180"),
        "{err}"
    );
    let o = run("--deg", "180");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !err.contains("at most 180") && !err.contains("panicked"),
        "{err}"
    );
}

/// A study in which every run fails (no regularisation, so the deformation flies off) is an
/// error with no output folder; the same study with the default weights writes its tables (the
/// companion).
#[test]
fn simulate_with_every_run_failed_writes_nothing() {
    let dir = tmp("allfail");
    let mut cmd = bin();
    cmd.args(["simulate", "--gt", "phantom"])
        .args(ONE_RUN.split(' '))
        .args(["--w-reg", "0", "--w-rot", "0"]);
    fails_cleanly(
        cmd,
        &dir.join("study"),
        &["all 1 runs failed, nothing written"],
    );
    let o = bin()
        .args(["simulate", "--gt", "phantom"])
        .args(ONE_RUN.split(' '))
        .arg("--out")
        .arg(dir.join("ok"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("ok/runs.csv").exists());
}

/// A population sweep: two meshes in a folder, one study each in its own subfolder, the
/// population table over both; run again, both are skipped (resumed) and the table is the same.
#[test]
fn a_population_sweep_writes_one_folder_a_mesh_and_resumes() {
    let dir = tmp("sweep");
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    let mut mesh = phantom(&PhantomParams::default()).mesh;
    acetab::io::write_obj(&mesh, &meshes.join("big.obj")).unwrap();
    for v in &mut mesh.vertices {
        *v = nalgebra::Point3::from(v.coords * 0.9);
    }
    acetab::io::write_obj(&mesh, &meshes.join("small.obj")).unwrap();
    let out = dir.join("pop");
    let run_with = |extra: &[&str]| {
        bin()
            .arg("simulate")
            .args(ONE_RUN.split(' '))
            .args(extra)
            .arg("--gt")
            .arg(&meshes)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap()
    };
    let run = || run_with(&[]);
    let o = run();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    for m in ["big", "small"] {
        assert!(out.join(m).join("runs.csv").is_file(), "{m}: {err}");
    }
    let table = std::fs::read_to_string(out.join("population.csv")).unwrap();
    // Two meshes and the whole population, one method at one level.
    assert_eq!(table.lines().count(), 1 + 3, "{table}");
    assert!(
        table.lines().any(|l| l.starts_with("all,srvf,1,2,")),
        "{table}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("population.json")).unwrap())
            .unwrap();
    assert_eq!(json["meshes"], 2);
    // One method, no baseline: the comparisons are there, and empty.
    assert_eq!(json["comparison_tolerance"], 1.05);
    assert_eq!(json["comparisons"].as_array().map(|a| a.len()), Some(0));
    assert!(out.join("population.png").is_file());
    // Resumed: the meshes done are skipped (`skipped` of them), and the table is the one the
    // sweep had.
    let resumes = |skipped: usize| {
        let o = run();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        assert_eq!(
            err.matches("done before, skipped").count(),
            skipped,
            "{err}"
        );
        assert_eq!(
            std::fs::read_to_string(out.join("population.csv")).unwrap(),
            table
        );
    };
    // Nothing is run again.
    resumes(2);
    // Resumed with another setting: refused, naming the mesh's summary and the setting, before
    // anything runs (the mesh not done, first in order, is not run), and the population table
    // is left as it was (it would have mixed two seeds under one).
    std::fs::remove_dir_all(out.join("big")).unwrap();
    let o = run_with(&["--seed", "2"]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("summary.json: study.seed is 1, this sweep's is 2"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out.join("big").exists(), "{err}");
    assert_eq!(
        std::fs::read_to_string(out.join("population.csv")).unwrap(),
        table
    );
    // A summary from a version that did not record a setting is not held to it: the sweep
    // resumes with the same settings (the mesh not done is run), and the table is the one it
    // had.
    let summary = out.join("small").join("summary.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    v["study"]
        .as_object_mut()
        .unwrap()
        .remove("srvf_alternations");
    std::fs::write(&summary, v.to_string()).unwrap();
    resumes(1);
    // A mesh whose every run fails (no regularisation: the deformation flies off) is not lost
    // from the sweep: its study is written with each run's reason, the population table counts
    // its runs as failed, and the sweep ends with an error naming it (resumed too). A single
    // study like it writes nothing (`simulate_with_every_run_failed_writes_nothing`).
    let wild = dir.join("wild");
    // The third pass prints the table as JSON, and fails all the same.
    let run_wild = |json: bool| {
        bin()
            .arg("simulate")
            .args(ONE_RUN.split(' '))
            .args(["--w-reg", "0", "--w-rot", "0", "--gt"])
            .arg(meshes.join("big.obj"))
            .arg(meshes.join("small.obj"))
            .args(json.then_some("--json"))
            .arg("--out")
            .arg(&wild)
            .output()
            .unwrap()
    };
    for pass in 0..3 {
        let o = run_wild(pass == 2);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(1), "pass {pass}: {err}");
        if pass == 2 {
            let rows: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            assert!(rows.as_array().is_some_and(|r| !r.is_empty()), "{rows}");
        }
        assert!(err.contains("big: all 1 runs failed"), "{err}");
        assert!(
            err.contains("the study failed on 2 mesh(es): big, small"),
            "{err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        let runs = std::fs::read_to_string(wild.join("big").join("runs.csv")).unwrap();
        assert_eq!(runs.lines().count(), 2, "{runs}");
        // No empty picture: nothing to draw is said, not drawn.
        assert!(!wild.join("big").join("errors.png").exists());
        if pass == 0 {
            assert!(
                err.contains("errors.png not drawn: no run has a result"),
                "{err}"
            );
        }
        let table = std::fs::read_to_string(wild.join("population.csv")).unwrap();
        let all = table
            .lines()
            .find(|l| l.starts_with("all,srvf,1,"))
            .unwrap();
        // runs 2, failed 2, ..., catastrophic 2
        assert!(all.starts_with("all,srvf,1,2,2,"), "{table}");
    }
    // Companion: the sweep whose every mesh ran, resumed with --json, prints its table and
    // succeeds.
    let o = run_with(&["--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(rows.as_array().is_some_and(|r| !r.is_empty()), "{rows}");
    // Companion: a folder with no mesh is refused.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let o = bin()
        .arg("simulate")
        .args(ONE_RUN.split(' '))
        .args(["--gt"])
        .arg(&empty)
        .arg("--gt")
        .arg(meshes.join("big.obj"))
        .arg("--out")
        .arg(dir.join("none"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("no .stl, .ply or .obj file"), "{err}");
}

/// A study folder `dir` of `n` srvf runs with cup errors `err(k)` and resampled SDs 0.2 mm.
fn study_of(dir: &Path, n: usize, err: impl Fn(usize) -> f64) {
    let cups: Vec<(f64, f64)> = (0..n).map(|k| (50.0 + err(k), 50.0)).collect();
    write_runs(dir, &cups, 0.2);
}

/// runs.csv in `dir`: srvf runs with these (cup, truth) diameters and resampled SDs `sd`.
fn write_runs(dir: &Path, cups: &[(f64, f64)], sd: f64) {
    let rows: Vec<acetab::study::Row> = cups
        .iter()
        .enumerate()
        .map(|(k, &(cup, truth))| {
            let t = acetab::study::Task {
                method: acetab::study::StudyMethod::Srvf,
                level: 1,
                run: k,
                seed: k as u64,
            };
            let mut r = acetab::study::Row::failed(&t, "");
            r.gt_cup_diameter_mm = truth;
            r.cup_diameter_mm = cup;
            r.cup_sd_mm = sd;
            r
        })
        .collect();
    std::fs::create_dir_all(dir).unwrap();
    acetab::study::write_csv(&rows, &dir.join("runs.csv")).unwrap();
}

/// `acetab calibrate` learns the result's depth offset from runs.csv's `depth_offset_mm` (the
/// runs' mean, one source of truths here) along with the cup; `--no-depth` writes 0 there and
/// the same cup correction (the companion: the default's offset is not 0).
#[test]
fn calibrate_learns_the_depth_offset_unless_told_not_to() {
    let dir = tmp("calibrate-depth");
    let pop = dir.join("pop");
    for (name, depth) in [("s1_lhip", 0.5), ("s2_rhip", 1.5)] {
        let d = pop.join(name);
        study_of(&d, 30, |k| 0.02 * k as f64);
        let mut rows = acetab::study::read_csv(&d.join("runs.csv")).unwrap();
        for r in &mut rows {
            r.depth_offset_mm = depth;
        }
        acetab::study::write_csv(&rows, &d.join("runs.csv")).unwrap();
    }
    let learn = |extra: &[&str], out: &Path| {
        let o = bin()
            .args(["calibrate", "--study"])
            .arg(&pop)
            .args(["--shrink"])
            .args(extra)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        acetab::pipeline::CupCalibration::read(out).unwrap()
    };
    let with = learn(&[], &dir.join("with.json"));
    assert!((with.depth_mm - 1.0).abs() < 1e-9, "{with:?}");
    let without = learn(&["--no-depth"], &dir.join("without.json"));
    assert_eq!(without.depth_mm, 0.0);
    assert_eq!(
        (without.bias_mm, without.shrink, without.model_sd_mm),
        (with.bias_mm, with.shrink, with.model_sd_mm)
    );
    // Leave-one-subject-out through simulate: a mesh of subject s1 is calibrated from s2's
    // runs alone (offset 1.5 mm), and with --calibrate-no-depth from the same runs without it.
    let mesh = dir.join("s1_lhip.obj");
    acetab::io::write_obj(&phantom(&PhantomParams::default()).mesh, &mesh).unwrap();
    // `acetab simulate` on `gt` calibrated leave-one-subject-out from `pop`, with `extra`.
    let run_loso = |gt: &Path, extra: &[&str], out: &str| {
        bin()
            .args(["simulate", "--gt"])
            .arg(gt)
            .args(ONE_RUN.split(' '))
            .args(["--calibrate-shrink", "--calibrate-loso"])
            .arg(&pop)
            .args(extra)
            .arg("--out")
            .arg(dir.join(out))
            .output()
            .unwrap()
    };
    let loso = |extra: &[&str], out: &str| -> serde_json::Value {
        let o = run_loso(&mesh, extra, out);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let text = std::fs::read_to_string(dir.join(out).join("summary.json")).unwrap();
        serde_json::from_str(&text).unwrap()
    };
    let learned = loso(&[], "loso");
    assert!((learned["study"]["cup_depth_mm"].as_f64().unwrap() - 1.5).abs() < 1e-9);
    let none = loso(&["--calibrate-no-depth"], "loso-no-depth");
    assert_eq!(none["study"]["cup_depth_mm"], 0.0, "{none}");
    assert_eq!(
        none["study"]["cup_bias_mm"],
        learned["study"]["cup_bias_mm"]
    );
    assert!(none["study"]["calibration"]
        .as_str()
        .is_some_and(|c| c.contains("without subject s1 (no depth offset)")));
    // A sweep (a folder of meshes) records what its leave-one-subject-out calibrations learn:
    // resumed with --calibrate-no-depth it is refused, and resumed as it was it skips the mesh.
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    std::fs::copy(&mesh, meshes.join("s1_lhip.obj")).unwrap();
    let sweep = |extra: &[&str]| run_loso(&meshes, extra, "sweep");
    let first = sweep(&[]);
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let mixed = sweep(&["--calibrate-no-depth"]);
    assert!(!mixed.status.success());
    let err = String::from_utf8_lossy(&mixed.stderr);
    assert!(err.contains("study.calibrate_loso is"), "{err}");
    let again = sweep(&[]);
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    assert!(String::from_utf8_lossy(&again.stderr).contains("done before, skipped"));
    // --calibrate-no-depth without --calibrate-loso is refused.
    let o = bin()
        .args([
            "simulate",
            "--gt",
            "phantom",
            "--calibrate-no-depth",
            "--out",
        ])
        .arg(dir.join("alone"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(!dir.join("alone").exists());
}

/// A run whose resampling failed (cup SD NaN, the result kept) in a study that resampled is
/// not learned from; in a study that resampled none (every SD NaN) each run counts with a
/// resampled SD of 0. Companion: the same run with its SD counts, and moves the bias.
#[test]
fn calibrate_skips_a_run_whose_resampling_failed() {
    let dir = tmp("calibrate-nan-sd");
    let learn = |pop: &Path| {
        let out = pop.with_extension("json");
        let o = bin()
            .args(["calibrate", "--study"])
            .arg(pop)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        acetab::pipeline::CupCalibration::read(&out).unwrap()
    };
    // 30 runs 0.02 k mm too large; run 0 instead 6 mm, with its SD as given.
    let study = |name: &str, sd0: f64, sd: f64| {
        let pop = dir.join(name);
        let d = pop.join("s1_lhip");
        study_of(&d, 30, |k| 0.02 * k as f64);
        let mut rows = acetab::study::read_csv(&d.join("runs.csv")).unwrap();
        for r in &mut rows {
            r.cup_sd_mm = sd;
        }
        rows[0].cup_diameter_mm = 56.0;
        rows[0].cup_sd_mm = sd0;
        acetab::study::write_csv(&rows, &d.join("runs.csv")).unwrap();
        learn(&pop)
    };
    let skipped = study("failed", f64::NAN, 0.2);
    assert!(
        skipped.learned_from.starts_with("29 srvf runs"),
        "{skipped:?}"
    );
    assert!((skipped.bias_mm - 0.30).abs() < 1e-9, "{skipped:?}");
    let counted = study("counted", 0.2, 0.2);
    assert!(
        counted.learned_from.starts_with("30 srvf runs"),
        "{counted:?}"
    );
    assert!(
        (counted.bias_mm - (8.7 + 6.0) / 30.0).abs() < 1e-9,
        "{counted:?}"
    );
    let unresampled = study("unresampled", f64::NAN, f64::NAN);
    assert!(
        unresampled.learned_from.starts_with("30 srvf runs"),
        "{unresampled:?}"
    );
    assert_eq!(unresampled.bias_mm, counted.bias_mm);
}

#[test]
fn calibrate_learns_the_model_sd_leaves_a_subject_out_and_names_bad_input() {
    let dir = tmp("calibrate");
    let pop = dir.join("pop");
    // Subject s1: errors 0.01 .. 1.00 mm; subject s2: errors of 5 mm.
    study_of(&pop.join("s1_lhip"), 100, |k| 0.01 * (k + 1) as f64);
    study_of(&pop.join("s2_rhip"), 100, |_| 5.0);
    let learn = |extra: &[&str], out: &Path| {
        bin()
            .args(["calibrate", "--study"])
            .arg(&pop)
            .args(extra)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    // Learning from `pop` is refused with exit 1, the stderr holding every one of `needles`,
    // and no file `out` written.
    let refused = |out: &str, needles: &[&str]| {
        let out = dir.join(out);
        let o = learn(&[], &out);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            needles.iter().all(|n| err.contains(n)),
            "{needles:?}: {err}"
        );
        assert!(!out.exists(), "{needles:?}");
    };
    let one = dir.join("one.json");
    let o = learn(&["--leave-out", "s2", "--no-bias"], &one);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cal = acetab::pipeline::CupCalibration::read(&one).unwrap();
    assert_eq!(
        (cal.bias_mm, cal.estimator.as_str()),
        (0.0, "observed-part")
    );
    // 69 of 100 errors (0.01 .. 0.69) within sqrt(0.04 + s^2): s^2 = 0.69^2 - 0.04.
    assert!(
        (cal.model_sd_mm - (0.69f64.powi(2) - 0.04).sqrt()).abs() < 1e-9,
        "{cal:?}"
    );
    assert_eq!(cal.runs, 100);
    // With the bias (the default): the mean error, 0.505 mm, and the model SD of the errors
    // less it, which spread less (companion: the SD without the bias is refused as this one).
    let biased = dir.join("biased.json");
    assert!(learn(&["--leave-out", "s2"], &biased).status.success());
    let cal_b = acetab::pipeline::CupCalibration::read(&biased).unwrap();
    assert!((cal_b.bias_mm - 0.505).abs() < 1e-9, "{cal_b:?}");
    assert!(cal_b.model_sd_mm < cal.model_sd_mm - 0.1, "{cal_b:?}");
    // Companion: with s2 in, the model SD is another (5 mm errors are half the runs).
    let both = dir.join("both.json");
    assert!(learn(&["--no-bias"], &both).status.success());
    let cal2 = acetab::pipeline::CupCalibration::read(&both).unwrap();
    assert!(cal2.model_sd_mm > 4.0, "{cal2:?}");
    // A study calibrated leave-one-subject-out learns without its own subject: here, a mesh of
    // subject s2 learns from s1 alone.
    let gt = dir.join("s2_rhip.obj");
    acetab::io::write_obj(&phantom(&PhantomParams::default()).mesh, &gt).unwrap();
    let study = dir.join("loso");
    let o = bin()
        .args(["simulate", "--gt"])
        .arg(&gt)
        .args(ONE_RUN.split(' '))
        .args(["--uncertainty-samples", "2", "--calibrate-loso"])
        .arg(&pop)
        .arg("--out")
        .arg(&study)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(study.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(s["study"]["cup_model_sd_mm"], cal_b.model_sd_mm, "{s}");
    assert_eq!(s["study"]["cup_bias_mm"], cal_b.bias_mm, "{s}");
    assert_eq!(s["study"]["cup_estimator"], "observed-part", "{s}");
    assert!(s["study"]["calibration"]
        .as_str()
        .unwrap()
        .contains("without subject s2"));
    // It cannot be given with a calibration file.
    let mut cmd = bin();
    cmd.args([
        "simulate",
        "--gt",
        "phantom",
        "--calibration",
        "none",
        "--calibrate-loso",
    ])
    .arg(&pop);
    fails_cleanly_with(cmd, &dir.join("both-flags"), &["--calibrate-loso"], 2);
    // A study whose summary.json holds a bias has it put back on its cups first: s1's cups
    // had 0.5 mm taken off, so its estimator's mean error is 1.005 mm.
    std::fs::write(
        pop.join("s1_lhip/summary.json"),
        r#"{"study": {"cup_bias_mm": 0.5, "cup_estimator": "observed-part"}}"#,
    )
    .unwrap();
    let again = dir.join("again.json");
    assert!(learn(&["--leave-out", "s2"], &again).status.success());
    let cal_a = acetab::pipeline::CupCalibration::read(&again).unwrap();
    assert!((cal_a.bias_mm - 1.005).abs() < 1e-9, "{cal_a:?}");
    // The views the studies were made with go into the calibration (a study that does not
    // say leaves it unsaid, as s2's here did above); studies made with different views are not
    // learned from together, and views that do not read are named.
    assert_eq!(cal_a.views, None);
    let judet = serde_json::json!({"study": {"views": ["z:0", "z:45", "z:-45"]}});
    for s in ["s1_lhip", "s2_rhip"] {
        std::fs::write(pop.join(s).join("summary.json"), judet.to_string()).unwrap();
    }
    let viewed = dir.join("viewed.json");
    assert!(learn(&[], &viewed).status.success());
    let cal_v = acetab::pipeline::CupCalibration::read(&viewed).unwrap();
    assert_eq!(
        cal_v.views,
        Some(vec!["z:0".to_string(), "z:45".into(), "z:-45".into()])
    );
    for (views, says) in [
        (r#"["z:0", "z:20", "z:-20"]"#, "one set of views"),
        (r#"["z:0", "q:20"]"#, "study.views"),
    ] {
        let other = format!(r#"{{"study": {{"views": {views}}}}}"#);
        std::fs::write(pop.join("s2_rhip/summary.json"), other).unwrap();
        refused("mixed-views.json", &[says, "s2_rhip"]);
    }
    // Studies made with different cup estimators are not learned from together.
    std::fs::write(
        pop.join("s2_rhip/summary.json"),
        r#"{"study": {"cup_estimator": "prior-region"}}"#,
    )
    .unwrap();
    refused("mixed.json", &["one estimator", "prior-region"]);
    // Studies made under different protocols are not learned from together either, and a
    // study of one protocol does not learn leave-one-subject-out from studies of the other
    // (nothing written); one that says no protocol is not held to one.
    let ideal = r#"{"study": {"protocol": "Ideal"}}"#;
    let realistic = r#"{"study": {"protocol": {"Realistic": {"pose_deg": 1.0}}}}"#;
    std::fs::write(pop.join("s1_lhip/summary.json"), ideal).unwrap();
    std::fs::write(pop.join("s2_rhip/summary.json"), realistic).unwrap();
    refused(
        "mixed-protocols.json",
        &["protocol realistic differs", "s2_rhip"],
    );
    std::fs::write(pop.join("s2_rhip/summary.json"), ideal).unwrap();
    assert!(learn(&[], &dir.join("ideal-only.json")).status.success());
    let mut cmd = bin();
    cmd.args(["simulate", "--gt"])
        .arg(&gt)
        .args(ONE_RUN.split(' '))
        .args([
            "--protocol",
            "realistic",
            "--uncertainty-samples",
            "2",
            "--calibrate-loso",
        ])
        .arg(&pop);
    fails_cleanly_with(
        cmd,
        &dir.join("loso-other-protocol"),
        &[
            "--calibrate-loso",
            "ideal protocol, this study is realistic",
        ],
        1,
    );
    std::fs::write(
        pop.join("s2_rhip/summary.json"),
        r#"{"study": {"protocol": 3}}"#,
    )
    .unwrap();
    refused("bad-protocol.json", &["study.protocol = 3"]);
    std::fs::remove_file(pop.join("s1_lhip/summary.json")).unwrap();
    // A study whose summary.json holds a model SD has it taken out of its cup SDs first.
    std::fs::write(
        pop.join("s2_rhip/summary.json"),
        r#"{"study": {"cup_model_sd_mm": -3}}"#,
    )
    .unwrap();
    refused("bad.json", &["summary.json", "cup_model_sd_mm = -3"]);
    let bad = dir.join("bad.json");
    // Too few runs, and a folder with no study, are refused with the reason.
    let o = learn(&["--leave-out", "s1", "--leave-out", "s2"], &bad);
    assert!(String::from_utf8_lossy(&o.stderr).contains("0 runs with a cup SD"));
    let o = bin()
        .args(["calibrate", "--study"])
        .arg(dir.join("nothing"))
        .arg("--out")
        .arg(&bad)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("nothing"));
    // A calibration file that is not one is named by simulate.
    std::fs::write(&bad, "{\"model_sd_mm\": \"x\"}").unwrap();
    let mut cmd = bin();
    cmd.args(["simulate", "--gt", "phantom"])
        .args(ONE_RUN.split(' '))
        .arg("--calibration")
        .arg(&bad);
    fails_cleanly(cmd, &dir.join("study"), &["--calibration", "bad.json"]);
}

/// A study folder `dir` of srvf runs with these (cup, truth) diameters and resampled SDs `sd`,
/// and a summary.json whose study holds `study` (its truth's path `gt`, a correction made).
fn study_with(dir: &Path, cups: &[(f64, f64)], sd: f64, study: serde_json::Value) {
    write_runs(dir, cups, sd);
    let summary = serde_json::json!({ "study": study });
    std::fs::write(dir.join("summary.json"), summary.to_string()).unwrap();
}

#[test]
fn calibrate_learns_a_shrink_with_each_source_of_truths_weighing_the_same() {
    let dir = tmp("calibrate-shrink");
    let pop = dir.join("pop");
    // Two sources of truths (the folders their meshes came from): 120 runs of bone-side
    // acetabula 3 mm too large, 40 of shells 1 mm too large, each with +-3 mm of error that
    // does not follow the truth (truths 42-60 mm).
    let runs = |n: usize, offset: f64| -> Vec<(f64, f64)> {
        (0..n)
            .map(|k| {
                let truth = 42.0 + (k * 7 % 19) as f64;
                let noise = if k % 2 == 0 { 3.0 } else { -3.0 };
                (truth + offset + noise, truth)
            })
            .collect()
    };
    let gt = |source: &str, name: &str| serde_json::json!({ "gt": format!("/data/{source}/{name}.stl") });
    study_with(
        &pop.join("b1_lhip"),
        &runs(60, 3.0),
        0.3,
        gt("bone", "b1_lhip"),
    );
    study_with(
        &pop.join("b2_rhip"),
        &runs(60, 3.0),
        0.3,
        gt("bone", "b2_rhip"),
    );
    study_with(
        &pop.join("c1_lhip"),
        &runs(40, 1.0),
        0.3,
        gt("shells", "c1_lhip"),
    );
    let learn = |pop: &Path, extra: &[&str], out: &Path| {
        bin()
            .args(["calibrate", "--study"])
            .arg(pop)
            .args(extra)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let first = dir.join("shrink.json");
    let o = learn(&pop, &["--shrink"], &first);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("shrink 0."));
    let cal = acetab::pipeline::CupCalibration::read(&first).unwrap();
    // Each source weighs half: the bias is 2 mm, not the pooled 2.5; the shrink takes off the
    // part of the spread that is noise.
    assert!((cal.bias_mm - 2.0).abs() < 1e-9, "{cal:?}");
    assert!(cal.shrink > 0.1 && cal.shrink < 0.5, "{cal:?}");
    assert!(cal.learned_from.contains("2 sources of truths"), "{cal:?}");
    // A study calibrated leave-one-subject-out with --calibrate-shrink gets the calibration
    // `--leave-out SUBJECT --shrink` learns (here subject c1: the bone-side source alone).
    let without_c1 = dir.join("without-c1.json");
    assert!(learn(&pop, &["--shrink", "--leave-out", "c1"], &without_c1)
        .status
        .success());
    let loso = acetab::pipeline::CupCalibration::read(&without_c1).unwrap();
    assert!(
        loso.shrink > 0.0 && (loso.bias_mm - 3.0).abs() < 1e-9,
        "{loso:?}"
    );
    let mesh = dir.join("c1_lhip.obj");
    acetab::io::write_obj(&phantom(&PhantomParams::default()).mesh, &mesh).unwrap();
    let o = bin()
        .args(["simulate", "--gt"])
        .arg(&mesh)
        .args(ONE_RUN.split(' '))
        .args([
            "--uncertainty-samples",
            "2",
            "--calibrate-shrink",
            "--calibrate-loso",
        ])
        .arg(&pop)
        .arg("--out")
        .arg(dir.join("loso"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("loso/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["study"]["cup_shrink"], loso.shrink, "{summary}");
    assert_eq!(summary["study"]["cup_shrink_to_mm"], loso.shrink_to_mm);
    assert_eq!(summary["study"]["cup_bias_mm"], loso.bias_mm);
    // --calibrate-shrink alone is refused.
    let o = bin()
        .args(["simulate", "--gt", "phantom", "--calibrate-shrink", "--out"])
        .arg(dir.join("alone"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(!dir.join("alone").exists());
    // Companion: without --shrink, no shrink.
    let plain = dir.join("plain.json");
    assert!(learn(&pop, &[], &plain).status.success());
    let p = acetab::pipeline::CupCalibration::read(&plain).unwrap();
    assert_eq!((p.shrink, p.shrink_to_mm), (0.0, 0.0));
    assert!((p.bias_mm - 2.0).abs() < 1e-9, "{p:?}");
    // The same studies made with that calibration (their cups corrected, their resampled SDs
    // shrunk with them, the correction in summary.json) give the same calibration back: the
    // correction a study made is undone before learning.
    let again = dir.join("again");
    let cup = cal.correcting(acetab::pipeline::CupParams::default());
    for (name, n, offset, source) in [
        ("b1_lhip", 60, 3.0, "bone"),
        ("b2_rhip", 60, 3.0, "bone"),
        ("c1_lhip", 40, 1.0, "shells"),
    ] {
        let corrected: Vec<(f64, f64)> = runs(n, offset)
            .iter()
            .map(|&(c, t)| (cup.corrected(c), t))
            .collect();
        let mut study = gt(source, name);
        study["cup_bias_mm"] = cal.bias_mm.into();
        study["cup_shrink"] = cal.shrink.into();
        study["cup_shrink_to_mm"] = cal.shrink_to_mm.into();
        study_with(
            &again.join(name),
            &corrected,
            0.3 * (1.0 - cal.shrink),
            study,
        );
    }
    let second = dir.join("second.json");
    assert!(learn(&again, &["--shrink"], &second).status.success());
    let cal2 = acetab::pipeline::CupCalibration::read(&second).unwrap();
    for (a, b) in [
        (cal.bias_mm, cal2.bias_mm),
        (cal.shrink, cal2.shrink),
        (cal.shrink_to_mm, cal2.shrink_to_mm),
        (cal.model_sd_mm, cal2.model_sd_mm),
    ] {
        // runs.csv keeps six decimals.
        assert!((a - b).abs() < 1e-5, "{cal:?} {cal2:?}");
    }
    // Companion: the corrected studies read as if uncorrected give another calibration.
    for name in ["b1_lhip", "b2_rhip", "c1_lhip"] {
        std::fs::write(again.join(name).join("summary.json"), "{}").unwrap();
    }
    let third = dir.join("third.json");
    assert!(learn(&again, &["--shrink"], &third).status.success());
    let cal3 = acetab::pipeline::CupCalibration::read(&third).unwrap();
    assert!(
        (cal3.shrink_to_mm - cal.shrink_to_mm).abs() > 0.5,
        "{cal3:?}"
    );
    // A shrink outside 0-0.9 in a study's summary is named, and so is a shrink without the
    // diameter it pulls toward (it cannot be undone); nothing is written.
    for (summary, named) in [
        (r#"{"study": {"cup_shrink": 1.5}}"#, "cup_shrink = 1.5"),
        (
            r#"{"study": {"cup_shrink": 0.3}}"#,
            "study.cup_shrink_to_mm = 0",
        ),
    ] {
        std::fs::write(again.join("b1_lhip/summary.json"), summary).unwrap();
        let o = learn(&again, &["--shrink"], &dir.join("bad.json"));
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(named), "{err}");
        assert!(!dir.join("bad.json").exists());
    }
    // --shrink with --no-bias is refused.
    let o = learn(&pop, &["--shrink", "--no-bias"], &dir.join("bad.json"));
    assert_eq!(o.status.code(), Some(2));
    assert!(!dir.join("bad.json").exists());
}

/// A one-run study of the phantom with `extra` flags written to `out`, which must succeed; its
/// summary.json.
fn phantom_study(extra: &[&str], out: &Path) -> serde_json::Value {
    let o = bin()
        .args(["simulate", "--gt", "phantom"])
        .args(ONE_RUN.split(' '))
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn a_realistic_study_records_its_protocol_and_calibration() {
    let dir = tmp("realistic");
    let out = dir.join("study");
    let s = phantom_study(
        &["--protocol", "realistic", "--uncertainty-samples", "2"],
        &out,
    );
    let study = &s["study"];
    assert_eq!(study["protocol"]["Realistic"]["pose_deg"], 1.0, "{study}");
    assert!(study["pose_prior"].is_null(), "{study}");
    assert_eq!(study["calibration"], "shipped calibration/realistic.json");
    assert_eq!(study["provenance"]["command_line"][1], "simulate");
    assert_eq!(study["provenance"]["threads"], 1);
    assert_eq!(study["engine"]["backend"], "cpu", "{study}");
    assert!(study["engine"]["adapter"].is_null(), "{study}");
    let shipped = acetab::pipeline::CupCalibration::shipped_realistic().model_sd_mm;
    assert_eq!(study["cup_model_sd_mm"], shipped);
    // How the runs were resampled: two resamples of two Gauss-Newton steps each.
    assert_eq!(
        (&study["uncertainty_samples"], &study["resample_steps"]),
        (&serde_json::json!(2), &serde_json::json!(2)),
        "{study}"
    );
    // The run's SD holds the model error.
    let rows = acetab::study::read_csv(&out.join("runs.csv")).unwrap();
    assert!(rows[0].cup_sd_mm >= shipped, "{}", rows[0].cup_sd_mm);
    // A study with the AP and Judet views gets the calibration learned on them (its own bias
    // and model SD); the paper's calibration given for it is used, and warned of.
    let judet = ["--protocol", "realistic", "--uncertainty-samples", "0"];
    let views = ["--views", "z:0,z:45,z:-45"];
    // (Its poses refined under a prior of its own, which the study records.)
    let refined = ["--refine-poses", "--pose-prior", "1.5,3"];
    let s = phantom_study(
        &[&judet[..], &views[..], &refined[..]].concat(),
        &dir.join("judet"),
    );
    assert_eq!(s["study"]["refine_poses"], true);
    assert_eq!(s["study"]["pose_prior"], serde_json::json!([1.5, 3.0]));
    let own = acetab::pipeline::CupCalibration::shipped_realistic_judet();
    assert_eq!(
        s["study"]["calibration"],
        "shipped calibration/realistic-judet.json"
    );
    assert_eq!(s["study"]["cup_bias_mm"], own.bias_mm);
    assert_ne!(
        own.bias_mm,
        acetab::pipeline::CupCalibration::shipped_realistic().bias_mm
    );
    let paper = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/realistic.json");
    let o = bin()
        .args(["simulate", "--gt", "phantom"])
        .args(ONE_RUN.split(' '))
        .args(judet)
        .args(views)
        .arg("--calibration")
        .arg(&paper)
        .arg("--out")
        .arg(dir.join("judet-paper"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("warning: the cup calibration") && err.contains("not on z:0,z:45,z:-45"),
        "{err}"
    );
    // --realistic sets one error over the defaults, recorded in summary.json; a setting that is
    // not one, a value out of range, or --realistic without the protocol are refused by name.
    let s = phantom_study(
        &[
            "--protocol",
            "realistic",
            "--realistic",
            "left_out=0,pose_deg=0.5,click_px=12,raster_px=2",
            "--uncertainty-samples",
            "0",
        ],
        &dir.join("whole"),
    );
    // Companion: a study without resampling records none.
    assert_eq!(s["study"]["uncertainty_samples"], 0, "{s}");
    assert!(s["study"]["resample_steps"].is_null(), "{s}");
    let p = &s["study"]["protocol"]["Realistic"];
    assert_eq!(p["left_out"], 0.0, "{p}");
    assert_eq!(p["pose_deg"], 0.5, "{p}");
    assert_eq!(p["pose_mm"], 2.0, "{p}");
    assert_eq!(p["click_px"], 12.0, "{p}");
    assert_eq!(p["raster_px"], 2.0, "{p}");
    for (args, needle, code) in [
        (
            vec!["--protocol", "realistic", "--realistic", "left=0"],
            "\"left\" is not a setting",
            2,
        ),
        (
            vec!["--protocol", "realistic", "--realistic", "left_out=0.9"],
            "left_out",
            2,
        ),
        (
            vec!["--protocol", "realistic", "--realistic", "click_px=-5"],
            "click_px",
            2,
        ),
        (
            vec!["--protocol", "realistic", "--realistic", "raster_px=1e9"],
            "raster_px = 1000000000",
            2,
        ),
        (
            vec!["--realistic", "left_out=0"],
            "add --protocol realistic",
            1,
        ),
    ] {
        let mut cmd = bin();
        cmd.args(["simulate", "--gt", "phantom"])
            .args(args)
            .args(ONE_RUN.split(' '));
        fails_cleanly_with(cmd, &dir.join("refused"), &[needle], code);
    }
}

/// A picture that cannot be drawn (here: ACETAB_FONT names no font) loses nothing: the study's
/// tables are written and the picture is a warning. Without ACETAB_FONT the shipped font draws
/// every picture and nothing is warned about (the companion).
#[test]
fn a_picture_that_cannot_be_drawn_is_a_warning_not_a_lost_study() {
    let dir = tmp("font");
    let run = |font: Option<&Path>, out: &Path| {
        let mut cmd = bin();
        cmd.args(["simulate", "--gt", "phantom"])
            .args(ONE_RUN.split(' '))
            .args(["--uncertainty-samples", "0", "--out"])
            .arg(out)
            .env_remove("ACETAB_FONT");
        if let Some(f) = font {
            cmd.env("ACETAB_FONT", f);
        }
        cmd.output().unwrap()
    };
    let out = dir.join("no-font");
    let o = run(Some(&dir.join("missing.ttf")), &out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("warning: errors.png not drawn") && err.contains("missing.ttf"),
        "{err}"
    );
    assert!(out.join("runs.csv").is_file() && out.join("summary.json").is_file());
    assert!(!out.join("errors.png").exists());
    let out = dir.join("shipped");
    let o = run(None, &out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && !err.contains("warning"), "{err}");
    assert!(out.join("errors.png").is_file() && out.join("example-srvf/view0.png").is_file());
}

/// One vocabulary: the singular flags are aliases of the plural ones, and simulate and merge
/// print their summary as JSON with --json (the table without it).
#[test]
fn singular_aliases_and_json_summaries() {
    let dir = tmp("vocab");
    let out = dir.join("study");
    let o = bin()
        .args(["simulate", "--gt", "phantom", "--level", "1", "--runs", "1"])
        .args([
            "--method",
            "srvf",
            "--threads",
            "1",
            "--uncertainty-samples",
            "0",
        ])
        .arg("--json")
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v[0]["method"], "srvf");
    assert_eq!(v[0]["level"], 1);
    let o = bin()
        .arg("merge")
        .arg(&out)
        .arg("--json")
        .arg("--out")
        .arg(dir.join("merged"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // The merge of one whole study is that study (to runs.csv's six decimals).
    assert_eq!(
        (&m[0]["method"], &m[0]["runs"]),
        (&v[0]["method"], &v[0]["runs"])
    );
    let mae = |x: &serde_json::Value| x[0]["mae_mean"].as_f64().unwrap();
    assert!((mae(&m) - mae(&v)).abs() < 1e-5, "{m} {v}");
    // Companion: without --json the table is printed, which is not JSON.
    let o = bin()
        .arg("merge")
        .arg(&out)
        .arg("--out")
        .arg(dir.join("table"))
        .output()
        .unwrap();
    assert!(serde_json::from_slice::<serde_json::Value>(&o.stdout).is_err());
}

/// `acetab simulate --gt phantom` with ONE_RUN and no resampling into `out`, and `extra` flags.
fn quick_study(out: &Path, extra: &[&str]) -> std::process::Output {
    bin()
        .args(["simulate", "--gt", "phantom"])
        .args(ONE_RUN.split(' '))
        .args(["--uncertainty-samples", "0"])
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap()
}

/// A reused --out is refused (an earlier result's files would mix with the new ones) unless
/// --force; the refusal leaves the folder as it was.
#[test]
fn a_reused_out_is_refused_unless_forced() {
    let dir = tmp("reuse");
    let out = dir.join("study");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("old.txt"), "earlier").unwrap();
    let o = quick_study(&out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("exists and is not empty") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_dir(&out).unwrap().count(),
        1,
        "the folder was touched"
    );
    // Companion: with --force the study is written beside the old file.
    let o = quick_study(&out, &["--force"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("runs.csv").is_file() && out.join("old.txt").is_file());
    // An empty folder is as good as a new one.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let o = quick_study(&empty, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// pose-study writes its summary (settings, means, rows, provenance) into --out.
#[test]
fn pose_study_writes_its_summary_into_out() {
    let dir = tmp("pose-out");
    let out = dir.join("pose");
    let o = bin()
        .args(["pose-study", "--runs", "1", "--threads", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["runs"], 1);
    assert_eq!(s["rows"].as_array().unwrap().len(), 1);
    assert_eq!(s["provenance"]["command_line"][1], "pose-study");
    // Companion: the same --out again is refused without --force.
    let o = bin()
        .args(["pose-study", "--runs", "1", "--threads", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("exists and is not empty"));
}

/// Several cases: one folder each under --out and cases.csv, a line per case; a case that fails
/// is a line with its error, the others still run, and the command exits non-zero naming it.
#[test]
fn several_cases_reconstruct_into_one_folder_each_and_a_table() {
    let dir = tmp("cases");
    let good = phantom_case(&dir);
    std::fs::copy(&good, dir.join("left.json")).unwrap();
    std::fs::write(dir.join("broken.json"), "{").unwrap();
    let out = dir.join("out");
    let o = bin()
        .arg("reconstruct")
        .arg(&good)
        .arg(dir.join("broken.json"))
        .arg(dir.join("left.json"))
        .args(["--uncertainty-samples", "2", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("2 of 3 cases reconstructed"), "{err}");
    assert!(err.contains("1 of 3 cases failed: broken"), "{err}");
    for name in ["case", "left"] {
        assert!(out.join(name).join("cup.json").is_file(), "{name}");
    }
    assert!(!out.join("broken").exists());
    let table = std::fs::read_to_string(out.join("cases.csv")).unwrap();
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 4, "{table}");
    assert!(
        lines[2].starts_with("broken,") && lines[2].contains("NaN"),
        "{table}"
    );
    assert!(
        lines[1].starts_with("case,") && !lines[1].contains("NaN"),
        "{table}"
    );
    // Companion: the same batch without the broken case succeeds.
    let o = bin()
        .arg("reconstruct")
        .arg(&good)
        .arg(dir.join("left.json"))
        .args(["--uncertainty-samples", "2", "--out"])
        .arg(dir.join("all-good"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("2 of 2 cases reconstructed"), "{err}");
    // Companion: two cases of one name would share a folder and are refused up front.
    let o = bin()
        .arg("reconstruct")
        .arg(&good)
        .arg(&good)
        .arg("--out")
        .arg(dir.join("twice"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("two cases are named"));
}

/// `acetab reconstruct` calibrates each case's cup with the shipped calibration learned on its
/// views: a case taken with the AP and Judet views gets calibration/realistic-judet.json, one
/// with the paper's views calibration/realistic.json (report.json says which, and that the
/// views fit); the paper's file given for the Judet case is used, with a warning on stderr and in
/// report.json naming both view sets.
#[test]
fn each_case_gets_the_calibration_learned_on_its_views() {
    let dir = tmp("judet");
    let truth = phantom(&PhantomParams::default()).mesh;
    let case_file = |views: &str, name: &str| {
        let geometry = acetab::sim::XrayGeometry {
            views: views.split(',').map(|v| v.parse().unwrap()).collect(),
            ..Default::default()
        };
        let level = acetab::sim::NoiseLevel::level(1).unwrap();
        let sim = acetab::sim::simulate_case(&truth, &geometry, 2.0, &level, 5).unwrap();
        let file = CaseFile::from_parts(&sim.cameras, &sim.observed, &sim.init);
        let path = dir.join(name);
        std::fs::write(&path, serde_json::to_string_pretty(&file).unwrap()).unwrap();
        path
    };
    let judet = case_file("z:0,z:45,z:-45", "judet.json");
    let paper = case_file("z:0,z:20,z:-20", "paper.json");
    let run = |case: &Path, out: &str, extra: &[&str]| {
        let o = bin()
            .arg("reconstruct")
            .arg(case)
            .args(["--uncertainty-samples", "2", "--out"])
            .arg(dir.join(out))
            .args(extra)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join(out).join("report.json")).unwrap())
                .unwrap();
        (report, err)
    };
    let (r, err) = run(&judet, "j", &[]);
    assert_eq!(r["calibration"]["name"], "calibration/realistic-judet.json");
    assert_eq!(r["calibration"]["views_fit"], "same");
    assert!(!err.contains("calibration"), "{err}");
    let judet_bias = acetab::pipeline::CupCalibration::shipped_realistic_judet().bias_mm;
    assert_eq!(r["cup"]["bias_mm"].as_f64(), Some(judet_bias));
    // Companion: the paper's views get the paper's calibration.
    let (r, _) = run(&paper, "p", &[]);
    assert_eq!(r["calibration"]["name"], "calibration/realistic.json");
    let paper_bias = acetab::pipeline::CupCalibration::shipped_realistic().bias_mm;
    assert_eq!(r["cup"]["bias_mm"].as_f64(), Some(paper_bias));
    assert_ne!(judet_bias, paper_bias);
    // The paper's file given for the Judet case: used as given, and warned of.
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/realistic.json");
    let (r, err) = run(&judet, "jp", &["--calibration", file.to_str().unwrap()]);
    assert_eq!(r["cup"]["bias_mm"].as_f64(), Some(paper_bias));
    assert_eq!(r["calibration"]["views_fit"], "other");
    assert!(
        err.contains("warning: the cup calibration") && err.contains("z:0,z:20,z:-20"),
        "{err}"
    );
    let warned = r["warnings"].as_array().unwrap();
    assert!(
        warned
            .iter()
            .any(|w| w.as_str().unwrap().contains("z:0,z:45,z:-45")),
        "{warned:?}"
    );
}

/// `acetab prior build` learns a prior from mesh files (both hips of three subjects, phantoms of
/// different shapes, left hips mirrored), a study uses it left-one-subject-out and says so in
/// summary.json; a mesh in centimetres, a broken prior file and --prior-leave-out without a
/// prior are refused, naming the file, field or flag, and write nothing.
#[test]
fn prior_build_makes_a_prior_a_study_leaves_its_subject_out_of_and_bad_input_is_named() {
    let dir = tmp("prior");
    let meshes = dir.join("meshes");
    std::fs::create_dir(&meshes).unwrap();
    for (i, s) in ["s1", "s2", "s3"].iter().enumerate() {
        for (side, x) in [("lhip", 1.0), ("rhip", -1.0)] {
            let mut p = PhantomParams {
                radius: 24.0 + 2.0 * i as f64,
                ellipticity: [1.0 + 0.02 * i as f64, 0.97 - 0.01 * i as f64],
                vertices: 1500,
                ..Default::default()
            };
            p.center = nalgebra::Point3::new(0.0, 0.0, 0.0);
            let mut m = phantom(&p).mesh;
            if x > 0.0 {
                // The other hip: mirrored in x (and its triangles turned to stay outward).
                for v in &mut m.vertices {
                    v.x = -v.x;
                }
                for t in &mut m.triangles {
                    t.swap(1, 2);
                }
                m.recompute_normals();
            }
            acetab::io::write_obj(&m, &meshes.join(format!("{s}_{side}.obj"))).unwrap();
        }
    }
    let prior = dir.join("prior.json");
    let o = bin()
        .args(["prior", "build", "--modes", "1", "--out"])
        .arg(&prior)
        .arg(&meshes)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("6 meshes (3 subjects), 1 mode(s)"), "{text}");
    let f = acetab::prior::PriorFile::read(&prior).unwrap();
    assert_eq!(f.meshes.iter().filter(|m| m.mirrored).count(), 3);

    let out = dir.join("study");
    let o = bin()
        .args(["simulate", "--gt"])
        .arg(meshes.join("s2_lhip.obj"))
        .args(ONE_RUN.split(' '))
        .args(["--uncertainty-samples", "0", "--prior-leave-out", "--prior"])
        .arg(&prior)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let from = s["study"]["prior"].as_str().unwrap();
    assert!(
        from.contains("without subject s2 (4 meshes, 1 modes)"),
        "{from}"
    );

    // A mesh in centimetres is refused by name.
    let mut cm = phantom(&PhantomParams::default()).mesh;
    for v in &mut cm.vertices {
        *v = nalgebra::Point3::from(v.coords * 0.1);
    }
    acetab::io::write_obj(&cm, &dir.join("cm.obj")).unwrap();
    let mut cmd = bin();
    cmd.args(["prior", "build"]).arg(dir.join("cm.obj"));
    fails_cleanly(cmd, &dir.join("cm-prior.json"), &["cm.obj", "millimetres?"]);
    // More modes than the meshes given can carry: the meshes are named as what falls short.
    let mut cmd = bin();
    cmd.args(["prior", "build", "--modes", "8"]).arg(&meshes);
    fails_cleanly(
        cmd,
        &dir.join("eight-prior.json"),
        &[
            "the meshes given",
            "needs at least 10 training meshes, got 6",
            "fewer --modes",
        ],
    );
    // A prior file with a bad field, and one with more modes than its meshes can carry, are
    // refused by name, before any run.
    let study_with = |prior: &Path| {
        let mut cmd = bin();
        cmd.args(["simulate", "--gt", "phantom"])
            .args(ONE_RUN.split(' '))
            .arg("--prior")
            .arg(prior);
        cmd
    };
    let mut bad = f.clone();
    bad.meshes[2].radius_mm = -3.0;
    let bad_path = dir.join("bad-prior.json");
    std::fs::write(&bad_path, bad.to_json()).unwrap();
    fails_cleanly(
        study_with(&bad_path),
        &dir.join("bad-out"),
        &["bad-prior.json", "meshes[2].radius_mm", "-3"],
    );
    let mut five = f.clone();
    five.modes = 5;
    let five_path = dir.join("five.json");
    std::fs::write(&five_path, five.to_json()).unwrap();
    let mut cmd = bin();
    cmd.args(["simulate", "--gt", "phantom", "--prior-leave-out"])
        .args(ONE_RUN.split(' '));
    fails_cleanly(
        cmd,
        &dir.join("none-out"),
        &["--prior-leave-out needs a prior"],
    );
    let cmd = study_with(&five_path);
    fails_cleanly(cmd, &dir.join("five-out"), &["five.json", "at least 7"]);
    // The prior-region cup needs a prior, and a calibration learned for it; an unknown
    // estimator is a usage error.
    let mut cmd = bin();
    cmd.args([
        "simulate",
        "--gt",
        "phantom",
        "--cup-estimator",
        "prior-region",
    ])
    .args(ONE_RUN.split(' '));
    fails_cleanly(
        cmd,
        &dir.join("region-out"),
        &["--cup-estimator prior-region", "--prior"],
    );
    // A calibration file learned for the observed part is refused for it by name.
    let mut cmd = bin();
    cmd.args(["simulate", "--gt", "phantom", "--prior", "default"])
        .args(["--cup-estimator", "prior-region", "--calibration"])
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/ideal.json"))
        .args(ONE_RUN.split(' '));
    fails_cleanly(
        cmd,
        &dir.join("region-file-out"),
        &["ideal.json", "estimator = observed-part"],
    );
    let mut cmd = bin();
    cmd.args(["simulate", "--gt", "phantom", "--cup-estimator", "sphere"])
        .args(ONE_RUN.split(' '));
    fails_cleanly_with(cmd, &dir.join("bogus-out"), &["unknown cup estimator"], 2);
    // With --calibration none it runs, and says which estimator gave its cups.
    let s = phantom_study(
        &[
            "--prior",
            "default",
            "--cup-estimator",
            "prior-region",
            "--calibration",
            "none",
        ],
        &dir.join("region"),
    );
    assert_eq!(s["study"]["cup_estimator"], "prior-region", "{s}");
    assert_eq!(s["study"]["cup_bias_mm"], 0.0, "{s}");
    // The shipped ideal prior-region calibration takes its bias off the same reconstruction's
    // cup (companion: the raw cup is not the calibrated one).
    let s2 = phantom_study(
        &["--prior", "default", "--cup-estimator", "prior-region"],
        &dir.join("region-shipped"),
    );
    let bias = acetab::pipeline::CupCalibration::shipped_ideal_prior_region().bias_mm;
    assert_eq!(s2["study"]["cup_bias_mm"], bias, "{s2}");
    let cup = |d: &str| {
        acetab::study::read_csv(&dir.join(d).join("runs.csv")).unwrap()[0].cup_diameter_mm
    };
    let (raw, calibrated) = (cup("region"), cup("region-shipped"));
    assert!(
        (raw - bias - calibrated).abs() < 2e-6,
        "{raw} {calibrated} {bias}"
    );
    assert!((raw - calibrated).abs() > 0.5);
}

#[test]
fn a_study_records_its_correspondence_schedule_and_runs_it() {
    // --correspondence-updates, --settled-round-mm and --srvf-samples reach the method: the
    // rounds show in runs.csv and the settings in summary.json; the defaults are recorded the
    // same way, as are the SRVF alignments' alternations and step neighbourhood.
    let dir = tmp("schedule");
    let srvf_rows = |out: &Path| -> Vec<acetab::study::Row> {
        acetab::study::read_csv(&out.join("runs.csv"))
            .unwrap()
            .into_iter()
            .filter(|r| r.method == acetab::study::StudyMethod::Srvf)
            .collect()
    };
    let rounds = |out: &Path| -> Vec<usize> {
        srvf_rows(out)
            .iter()
            .map(|r| r.correspondence_updates)
            .collect()
    };
    let default = dir.join("default");
    let s = phantom_study(&[], &default);
    assert_eq!(s["study"]["correspondence_updates"], 3, "{}", s["study"]);
    assert_eq!(s["study"]["settled_round_mm"], 0.0);
    assert_eq!(s["study"]["srvf_samples"], 200);
    assert_eq!(s["study"]["srvf_alternations"], 3);
    assert_eq!(s["study"]["srvf_neighbourhood"], 5);
    let five = dir.join("five");
    let s = phantom_study(
        &["--correspondence-updates", "5", "--srvf-samples", "100"],
        &five,
    );
    assert_eq!(s["study"]["correspondence_updates"], 5, "{}", s["study"]);
    assert_eq!(s["study"]["srvf_samples"], 100);
    let (r3, r5) = (rounds(&default), rounds(&five));
    assert!(!r3.is_empty() && r3.iter().all(|&r| r == 3), "{r3:?}");
    // The companion: the five-round study is told apart from the default by the same column.
    assert!(!r5.is_empty() && r5.iter().all(|&r| r == 5), "{r5:?}");
    // With stage B ended where the surface settles (1 mm), the phantom's second round, which
    // moves it less than that, is its last, five rounds scheduled or not.
    let settled = dir.join("settled");
    let s = phantom_study(
        &["--correspondence-updates", "5", "--settled-round-mm", "1"],
        &settled,
    );
    assert_eq!(s["study"]["settled_round_mm"], 1.0, "{}", s["study"]);
    let r2 = rounds(&settled);
    assert!(!r2.is_empty() && r2.iter().all(|&r| r == 2), "{r2:?}");
    // One alternation and the 7-step neighbourhood reach every alignment: recorded, and the
    // same runs end elsewhere (the default's MAE is not the cheaper study's).
    let cheap = dir.join("cheap");
    let s = phantom_study(
        &["--srvf-alternations", "1", "--srvf-neighbourhood", "3"],
        &cheap,
    );
    assert_eq!(s["study"]["srvf_alternations"], 1, "{}", s["study"]);
    assert_eq!(s["study"]["srvf_neighbourhood"], 3);
    let mae = |out: &Path| -> Vec<f64> { srvf_rows(out).iter().map(|r| r.mae_mm).collect() };
    let (m_default, m_cheap) = (mae(&default), mae(&cheap));
    assert_eq!(m_default.len(), m_cheap.len());
    assert!(
        m_default.iter().zip(&m_cheap).any(|(a, b)| a != b),
        "{m_default:?}"
    );
    // A neighbourhood outside 2-7 is refused, naming the flag, and nothing is written.
    let bad = dir.join("bad");
    let o = bin()
        .args(["simulate", "--gt", "phantom"])
        .args(ONE_RUN.split(' '))
        .args(["--srvf-neighbourhood", "9", "--out"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--srvf-neighbourhood") && err.contains('9'),
        "{err}"
    );
    assert!(!bad.exists());
}

/// A single study with srvf and a baseline compares them run by run in summary.json and on
/// stdout; a study of srvf alone has nothing to compare.
#[test]
fn a_study_compares_srvf_with_its_baseline_run_by_run() {
    let dir = tmp("compare");
    let study = |methods: &str, out: &str| {
        bin()
            .args([
                "simulate", "--gt", "phantom", "--levels", "1", "--runs", "2",
            ])
            .args(["--methods", methods, "--threads", "1"])
            .args(["--uncertainty-samples", "0", "--out"])
            .arg(dir.join(out))
            .output()
            .unwrap()
    };
    let o = study("srvf,icp-normvec", "both");
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("both/summary.json")).unwrap())
            .unwrap();
    let c = &json["comparisons"];
    assert_eq!(c.as_array().map(|a| a.len()), Some(1), "{c}");
    assert_eq!(
        (&c[0]["mesh"], &c[0]["baseline"], &c[0]["pairs"]),
        (
            &serde_json::json!("phantom"),
            &serde_json::json!("icp-normvec"),
            &serde_json::json!(2)
        ),
        "{c}"
    );
    let ratio = c[0]["method_mae"].as_f64().unwrap() / c[0]["baseline_mae"].as_f64().unwrap();
    assert!(
        (c[0]["ratio"].as_f64().unwrap() - ratio).abs() < 1e-12,
        "{c}"
    );
    assert!(
        stdout.contains("srvf against icp-normvec, level 1 (2 paired runs)"),
        "{stdout}"
    );
    // Companion: srvf alone is compared with nothing.
    let o = study("srvf", "alone");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!String::from_utf8_lossy(&o.stdout).contains(" against "));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("alone/summary.json")).unwrap())
            .unwrap();
    assert_eq!(json["comparisons"].as_array().map(|a| a.len()), Some(0));
}

/// A view set's sweep under `dir`: subjects s1-s4, two hips each, six srvf runs a hip, cups
/// `truth + offset + noise(k)`, from two sources of truths, recorded as made with `views`.
fn sweep_of(dir: &Path, views: &[&str], offset: f64, noise: impl Fn(usize) -> f64) {
    for s in 1..=4 {
        for hip in ["lhip", "rhip"] {
            let name = format!("s{s}_{hip}");
            let truth = 46.0 + 2.4 * s as f64 + if hip == "lhip" { 0.3 } else { -0.4 };
            let cups: Vec<(f64, f64)> = (0..6)
                .map(|k| (truth + offset + noise(k + s), truth))
                .collect();
            let source = if s <= 2 { "shells" } else { "bone" };
            study_with(
                &dir.join(&name),
                &cups,
                f64::NAN,
                serde_json::json!({
                    "gt": format!("/data/{source}/{name}.stl"),
                    "views": views,
                }),
            );
        }
    }
}

#[test]
fn plan_views_ranks_view_sets_by_the_corrected_cup_and_refuses_mixed_sweeps() {
    let dir = tmp("plan-views");
    // Set A: every cup 2 mm too large, +-0.3 mm about it (a bias a correction removes); set B:
    // no bias, but +-1.5 mm of scatter (nothing to learn).
    let alternating = |amp: f64| move |k: usize| if k.is_multiple_of(2) { amp } else { -amp };
    sweep_of(
        &dir.join("A"),
        &["z:0", "z:45", "z:-45"],
        2.0,
        alternating(0.3),
    );
    sweep_of(
        &dir.join("B"),
        &["z:0", "z:20", "z:-20"],
        0.0,
        alternating(1.5),
    );
    let plan = |extra: &[&str], out: &Path| {
        bin()
            .args(["plan-views", "--sweep"])
            .arg(dir.join("A"))
            .arg(dir.join("B"))
            .args(extra)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let rows = |out: &Path| -> Vec<serde_json::Value> {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("views.json")).unwrap())
                .unwrap();
        v["rows"].as_array().unwrap().clone()
    };
    let find = |rows: &[serde_json::Value], views: &str, source: &str| -> serde_json::Value {
        rows.iter()
            .find(|r| r["views"] == views && r["source"] == source)
            .unwrap_or_else(|| panic!("no row {views} {source} in {rows:?}"))
            .clone()
    };
    let corrected = dir.join("corrected");
    let o = plan(&[], &corrected);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = rows(&corrected);
    // Two sets x (two sources + all).
    assert_eq!(r.len(), 6, "{r:?}");
    let a = find(&r, "z:0,z:45,z:-45", "all");
    let b = find(&r, "z:0,z:20,z:-20", "all");
    assert_eq!(a["runs"], 48);
    assert!(
        (a["fitted_bias_mm"].as_f64().unwrap() - 2.0).abs() < 1e-9,
        "{a}"
    );
    // Each subject's bias is learned from the other three: all 2 mm, so A's cups land within
    // 0.3 mm; B's scatter stays.
    assert!(a["rms_mm"].as_f64().unwrap() < 0.31, "{a}");
    assert_eq!(a["within_1mm"], 1.0);
    assert_eq!(b["within_1mm"], 0.0);
    // These studies did not resample: no SD to cover with.
    assert!(a["sd_coverage"].is_null(), "{a}");
    assert!(
        stdout.contains("most cups within 1 mm over all sources: z:0,z:45,z:-45"),
        "{stdout}"
    );
    assert!(std::fs::read_to_string(corrected.join("views.csv"))
        .unwrap()
        .starts_with("views,source,runs,failed,mae_mm"));
    // The companion: the cups as fitted rank the sets the other way (A's 2 mm bias is a miss).
    let fitted = dir.join("fitted");
    let o = plan(&["--correction", "none"], &fitted);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = rows(&fitted);
    assert_eq!(find(&r, "z:0,z:45,z:-45", "all")["within_1mm"], 0.0);
    assert!(String::from_utf8_lossy(&o.stdout)
        .contains("most cups within 1 mm over all sources: z:0,z:20,z:-20"));
    // Sweeps of different acetabula are compared with a warning naming the difference.
    std::fs::remove_dir_all(dir.join("B").join("s4_rhip")).unwrap();
    let fewer = dir.join("fewer");
    let o = plan(&[], &fewer);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("holds 7 acetabula") && err.contains(": s4_rhip;"),
        "{err}"
    );
    assert_eq!(find(&rows(&fewer), "z:0,z:20,z:-20", "all")["runs"], 42);
    // A sweep whose studies were made with different views is refused, naming the study, and
    // nothing is written.
    study_with(
        &dir.join("A").join("s9_lhip"),
        &[(50.0, 50.0)],
        f64::NAN,
        serde_json::json!({"gt": "/data/bone/s9_lhip.stl", "views": ["z:0", "z:20", "z:-20"]}),
    );
    let mixed = dir.join("mixed");
    let mut cmd = bin();
    cmd.args(["plan-views", "--sweep"]).arg(dir.join("A"));
    fails_cleanly(
        cmd,
        &mixed,
        &[
            "s9_lhip",
            "views z:0,z:20,z:-20 differ",
            "a sweep is one view set",
        ],
    );
    // And a run without its truth's cup.
    study_with(
        &dir.join("A").join("s9_lhip"),
        &[(50.0, f64::NAN)],
        f64::NAN,
        serde_json::json!({"gt": "/data/bone/s9_lhip.stl", "views": ["z:0", "z:45", "z:-45"]}),
    );
    let mut cmd = bin();
    cmd.args(["plan-views", "--sweep"]).arg(dir.join("A"));
    fails_cleanly(cmd, &mixed, &["s9_lhip", "gt_cup_diameter_mm = NaN"]);
    // So is a sweep whose studies do not say their views.
    std::fs::write(
        dir.join("A").join("s9_lhip").join("summary.json"),
        serde_json::json!({"study": {"gt": "/data/bone/s9_lhip.stl"}}).to_string(),
    )
    .unwrap();
    let mut cmd = bin();
    cmd.args(["plan-views", "--sweep"]).arg(dir.join("A"));
    fails_cleanly(cmd, &mixed, &["s9_lhip", "study.views missing"]);
    std::fs::remove_dir_all(dir.join("A").join("s9_lhip")).unwrap();
    // View sets are compared under one protocol: within a sweep, and between sweeps (a study
    // that does not say its protocol, as these did above, is not held to one).
    let say = |sweep: &str, name: &str, protocol: serde_json::Value| {
        let views = if sweep == "A" {
            ["z:0", "z:45", "z:-45"]
        } else {
            ["z:0", "z:20", "z:-20"]
        };
        let study = serde_json::json!({"study": {
            "gt": format!("/data/bone/{name}.stl"), "views": views, "protocol": protocol,
        }});
        std::fs::write(
            dir.join(sweep).join(name).join("summary.json"),
            study.to_string(),
        )
        .unwrap();
    };
    let realistic = serde_json::json!({"Realistic": {"pose_deg": 1.0}});
    say("A", "s1_lhip", serde_json::json!("Ideal"));
    say("A", "s2_lhip", realistic.clone());
    let mut cmd = bin();
    cmd.args(["plan-views", "--sweep"]).arg(dir.join("A"));
    fails_cleanly(
        cmd,
        &mixed,
        &[
            "s2_lhip",
            "protocol realistic differs",
            "a sweep is one protocol",
        ],
    );
    say("A", "s2_lhip", serde_json::json!("Ideal"));
    say("B", "s1_lhip", realistic);
    let mut cmd = bin();
    cmd.args(["plan-views", "--sweep"])
        .arg(dir.join("A"))
        .arg(dir.join("B"));
    fails_cleanly(
        cmd,
        &mixed,
        &[
            "made under the realistic protocol",
            "compared under one protocol",
        ],
    );
    // The companion: under one protocol the same sweeps are compared.
    say("B", "s1_lhip", serde_json::json!("Ideal"));
    assert!(plan(&[], &dir.join("one-protocol")).status.success());
}
