//! The malformed-input corpus (tests/cases/bad/, written by tests/cases/make_bad.py, listed in
//! expected.tsv): every case must end in a clear error that names the file and the problem, a
//! non-zero exit that is not a panic, and no output files. The valid case beside it
//! (tests/cases/good.json) must pass, so the corpus cannot pass by rejecting everything.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/cases")
}

fn scratch(tag: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("acetab-bad-{tag}-"))
        .tempdir()
        .unwrap()
}

fn run(command: &str, file: &Path, out: &Path) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_acetab"));
    match command {
        "reconstruct" => c
            .arg("reconstruct")
            .arg(file)
            .arg("--out")
            .arg(out)
            .args(["--uncertainty-samples", "2"]),
        "simulate" => c
            .args(["simulate", "--gt"])
            .arg(file)
            .args([
                "--levels",
                "1",
                "--runs",
                "1",
                "--methods",
                "srvf",
                "--threads",
                "1",
                "--out",
            ])
            .arg(out),
        other => panic!("expected.tsv: unknown command {other}"),
    };
    c.output().unwrap()
}

/// The reasons a run fails the corpus's rules, if any.
fn judge(o: &Output, file: &Path, expect: &str, out: &Path, dir: &Path) -> Vec<String> {
    let err = String::from_utf8_lossy(&o.stderr);
    let mut why = Vec::new();
    if o.status.success() {
        why.push("exit status 0".into());
    }
    if o.status.code() == Some(101) || err.contains("panicked") {
        why.push(format!("panicked: {err}"));
    }
    let name = file.file_name().unwrap().to_string_lossy();
    if !err.contains(name.as_ref()) {
        why.push(format!("the message does not name the file: {err}"));
    }
    if !err.contains(expect) {
        why.push(format!("the message lacks {expect:?}: {err}"));
    }
    if out.exists() {
        why.push("the output folder was created".into());
    }
    let stray: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    if !stray.is_empty() {
        why.push(format!("files left behind: {stray:?}"));
    }
    why
}

fn corpus() -> Vec<(String, String, String)> {
    std::fs::read_to_string(root().join("bad/expected.tsv"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            (
                f[0].to_string(),
                f[1].to_string(),
                f.get(2).unwrap_or(&"").to_string(),
            )
        })
        .collect()
}

#[test]
fn every_malformed_case_is_a_clear_error_with_no_output() {
    let cases = corpus();
    assert!(cases.len() >= 30, "the corpus has {} cases", cases.len());
    let mut failures = Vec::new();
    for (file, command, expect) in &cases {
        let tmp = scratch(file);
        let dir = tmp.path();
        let out = dir.join("out");
        let path = root().join("bad").join(file);
        assert!(path.is_file(), "{file} is listed but missing");
        let o = run(command, &path, &out);
        let why = judge(&o, &path, expect, &out, dir);
        if !why.is_empty() {
            failures.push(format!("{file}: {}", why.join("; ")));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases fail:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

#[test]
fn the_valid_case_beside_the_corpus_succeeds_and_the_judge_rejects_it() {
    let tmp = scratch("good");
    let dir = tmp.path();
    let out = dir.join("out");
    let path = root().join("good.json");
    let o = run("reconstruct", &path, &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["reconstruction.ply", "cup.json", "report.json"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    // Companion: the corpus's judge must reject a successful run.
    assert!(!judge(&o, &path, "invalid JSON", &out, dir).is_empty());
}

/// The companion of `two_closed_contours.json` and `closed_contour_and_arc.json`: a view's rim
/// given as two open arcs (the valid case's first outline cut in two, a gap either side) is
/// one acetabulum's rim and reconstructs.
#[test]
fn a_rim_given_as_two_open_arcs_is_accepted() {
    let tmp = scratch("arcs");
    let dir = tmp.path();
    let mut case: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root().join("good.json")).unwrap()).unwrap();
    let contours = &mut case["views"][0]["contours"];
    let points = contours[0]["points"].as_array().unwrap().clone();
    let half = points.len() / 2;
    *contours = serde_json::json!([
        {"points": points[..half - 1], "closed": false},
        {"points": points[half + 1..], "closed": false},
    ]);
    let path = dir.join("arcs.json");
    std::fs::write(&path, case.to_string()).unwrap();
    let out = dir.join("out");
    let o = run("reconstruct", &path, &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("report.json").is_file());
}
