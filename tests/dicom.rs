//! X-ray DICOM views: the example case written as DICOM (examples/case-dicom/, its intrinsics
//! taken from the tags) reconstructs to the PNG case's cup, and DICOM files that cannot give a
//! view what it needs are refused, naming the file and the tag.

use acetab::io::{read_dicom_image, write_dicom_xray, DicomXray, SpacingTag};
use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_acetab"))
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The reconstruct report (--json) of `case`, written into `out`.
fn reconstruct(case: &Path, out: &Path) -> serde_json::Value {
    let o = bin()
        .arg("reconstruct")
        .arg(case)
        .args(["--uncertainty-samples", "2", "--out"])
        .arg(out)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn cup_mm(report: &serde_json::Value) -> f64 {
    report["sphere"]["radius"].as_f64().unwrap() * 2.0
}

/// A copy of examples/case-dicom in `dir`, its view 0 rewritten with `spacing` and `sid`.
fn dicom_case(dir: &Path, spacing: Option<([f64; 2], SpacingTag)>, sid: Option<f64>) -> PathBuf {
    let src = root().join("examples/case-dicom");
    for f in ["case.json", "view0.dcm", "view1.dcm", "view2.dcm"] {
        std::fs::copy(src.join(f), dir.join(f)).unwrap();
    }
    let img = read_dicom_image(&src.join("view0.dcm")).unwrap();
    let x = DicomXray {
        columns: img.width(),
        rows: img.height(),
        pixels: img.pixels().map(|p| u16::from(p.0[0]) * 16).collect(),
        spacing,
        sid_mm: sid,
        sod_mm: Some(900.0),
        view: "AP".into(),
        uid_seed: 11,
    };
    write_dicom_xray(&dir.join("view0.dcm"), &x).unwrap();
    dir.join("case.json")
}

/// `dicom_case` in a new folder `name` under `dir`.
fn dicom_case_in(
    dir: &Path,
    name: &str,
    spacing: Option<([f64; 2], SpacingTag)>,
    sid: Option<f64>,
) -> PathBuf {
    let sub = dir.join(name);
    std::fs::create_dir(&sub).unwrap();
    dicom_case(&sub, spacing, sid)
}

/// Give view 0 of the case file at `case` the nominal focal length (5500 px) in `k`.
fn give_k(case: &Path) {
    let mut file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(case).unwrap()).unwrap();
    file["views"][0]["k"] = serde_json::json!({"fx": 5500.0, "fy": 5500.0});
    std::fs::write(case, file.to_string()).unwrap();
}

/// `acetab reconstruct case` fails with exit 1, its error holds every needle, nothing written:
/// the error.
fn refused(case: &Path, out: &Path, needles: &[&str]) -> String {
    let o = bin()
        .arg("reconstruct")
        .arg(case)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        needles.iter().all(|n| err.contains(n)),
        "{needles:?}: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out.exists(), "output written");
    err.into_owned()
}

#[test]
fn the_dicom_example_gives_the_png_example_cup() {
    let dir = tempfile::tempdir().unwrap();
    let png = reconstruct(
        &root().join("examples/case/case.json"),
        &dir.path().join("png"),
    );
    let dcm = reconstruct(
        &root().join("examples/case-dicom/case.json"),
        &dir.path().join("dcm"),
    );
    let (a, b) = (cup_mm(&png), cup_mm(&dcm));
    assert!(
        (a - b).abs() < 0.05,
        "PNG case {a:.4} mm, DICOM case {b:.4} mm"
    );
    // The intrinsics came from the tags, and the magnification is reported.
    let v = &dcm["views"][0];
    assert_eq!(v["k_source"][0], "dicom");
    assert_eq!(v["k_source"][2], "image centre");
    assert!((v["k"][0].as_f64().unwrap() - 5500.0).abs() < 1e-6, "{v}");
    assert!((v["magnification_dicom"].as_f64().unwrap() - 1100.0 / 900.0).abs() < 1e-9);
    assert!(dir.path().join("dcm/overlay-0-AP.png").is_file());
    assert_eq!(png["views"][0]["k_source"][0], "case");
}

#[test]
fn a_wrong_pixel_spacing_moves_the_cup_and_a_disagreeing_k_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let reference = cup_mm(&reconstruct(
        &root().join("examples/case-dicom/case.json"),
        &dir.path().join("ref"),
    ));
    // The companion: a spacing 10 % off gives another focal length, and another cup.
    let wrong = dir.path().join("wrong");
    std::fs::create_dir(&wrong).unwrap();
    let case = dicom_case(
        &wrong,
        Some(([0.22, 0.22], SpacingTag::Imager)),
        Some(1100.0),
    );
    let moved = cup_mm(&reconstruct(&case, &dir.path().join("wrong-out")));
    assert!(
        (moved - reference).abs() > 0.05,
        "a 10 % spacing error left the cup at {moved:.4} mm (reference {reference:.4})"
    );
    // A k in the case wins over the tags, and the disagreement is reported.
    give_k(&case);
    let r = reconstruct(&case, &dir.path().join("k-out"));
    assert!((cup_mm(&r) - reference).abs() < 0.05, "{}", cup_mm(&r));
    let warnings = r["warnings"].to_string();
    assert!(
        warnings.contains("views[0].k.fx") && warnings.contains("+10.0 %"),
        "{warnings}"
    );
    assert_eq!(r["views"][0]["k_source"][0], "case");
    // Within 1 % nothing is reported.
    let close = dir.path().join("close");
    std::fs::create_dir(&close).unwrap();
    let case = dicom_case(
        &close,
        Some(([0.2016, 0.2016], SpacingTag::Pixel)),
        Some(1100.0),
    );
    give_k(&case);
    let r = reconstruct(&case, &dir.path().join("close-out"));
    assert_eq!(r["warnings"], serde_json::json!([]), "{}", r["warnings"]);
    assert_eq!(
        r["views"][0]["dicom"]["spacing_tag"],
        "PixelSpacing (0028,0030)"
    );
}

#[test]
fn dicom_files_that_cannot_give_a_view_are_refused_by_tag() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // No pixel spacing.
    let case = dicom_case_in(d, "a", None, Some(1100.0));
    refused(
        &case,
        &d.join("a-out"),
        &[
            "case.json",
            "views[0].k",
            "view0.dcm",
            "(0018,1164)",
            "(0028,0030)",
        ],
    );
    // No source-to-detector distance.
    let case = dicom_case_in(d, "b", Some(([0.2, 0.2], SpacingTag::Imager)), None);
    refused(
        &case,
        &d.join("b-out"),
        &["case.json", "views[0].k", "view0.dcm", "(0018,1110)"],
    );
    // A DICOM file that is not an image (a text report: no pixel data).
    let case = dicom_case_in(d, "c", Some(([0.2, 0.2], SpacingTag::Imager)), Some(1100.0));
    {
        use dicom_core::{DataElement, PrimitiveValue, VR};
        use dicom_dictionary_std::{tags, uids};
        let mut obj = dicom_object::InMemDicomObject::new_empty();
        for (tag, vr, v) in [
            (tags::SOP_CLASS_UID, VR::UI, uids::BASIC_TEXT_SR_STORAGE),
            (tags::SOP_INSTANCE_UID, VR::UI, "2.25.99"),
            (tags::MODALITY, VR::CS, "SR"),
        ] {
            obj.put(DataElement::new(tag, vr, PrimitiveValue::from(v)));
        }
        obj.with_meta(
            dicom_object::FileMetaTableBuilder::new()
                .transfer_syntax(uids::EXPLICIT_VR_LITTLE_ENDIAN)
                .media_storage_sop_class_uid(uids::BASIC_TEXT_SR_STORAGE)
                .media_storage_sop_instance_uid("2.25.99"),
        )
        .unwrap()
        .write_to_file(case.with_file_name("view1.dcm"))
        .unwrap();
    }
    refused(
        &case,
        &d.join("c-out"),
        &[
            "views[1].image",
            "view1.dcm",
            "PixelData (7FE0,0010)",
            "not an image",
        ],
    );
    // A file named .dcm that is not DICOM at all.
    std::fs::write(case.with_file_name("view1.dcm"), b"not a dicom file").unwrap();
    refused(
        &case,
        &d.join("c2-out"),
        &["views[1].image", "view1.dcm", "not a DICOM Part 10 file"],
    );
    // The size in the case must match the DICOM's Rows and Columns.
    let case = dicom_case_in(d, "e", Some(([0.2, 0.2], SpacingTag::Imager)), Some(1100.0));
    let mut file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&case).unwrap()).unwrap();
    file["views"][2]["width"] = serde_json::json!(1024);
    file["views"][2]["height"] = serde_json::json!(2048);
    std::fs::write(&case, file.to_string()).unwrap();
    refused(
        &case,
        &d.join("e-out"),
        &["views[2].image", "2048x2048", "1024x2048"],
    );
    // A pixel spacing so fine that SID / spacing is no focal length: the error says where the
    // value came from ...
    let case = dicom_case_in(
        d,
        "g",
        Some(([1e-6, 1e-6], SpacingTag::Imager)),
        Some(1100.0),
    );
    refused(
        &case,
        &d.join("g-out"),
        &[
            "case.json",
            "views[0].k.fx",
            "focal length",
            "view0.dcm",
            "(0018,1110)",
        ],
    );
    // ... and an absurd focal length the case gives itself is the case's own.
    let case = dicom_case_in(d, "h", Some(([0.2, 0.2], SpacingTag::Imager)), Some(1100.0));
    let mut file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&case).unwrap()).unwrap();
    file["views"][0]["k"] = serde_json::json!({"fx": 1e9, "fy": 5500.0});
    std::fs::write(&case, file.to_string()).unwrap();
    let err = refused(&case, &d.join("h-out"), &["views[0].k.fx", "focal length"]);
    assert!(!err.contains("SID / pixel spacing"), "{err}");
}
