//! A view's camera as a case file gives it: the image size (given, or read off the image), the
//! intrinsics (given, or from an X-ray DICOM file's source-to-detector distance and pixel
//! spacing), the pose, and the template in front of the source. Each value is checked where it
//! is read; an error names the view's field.

use super::image::{view_image, ViewImage};
use super::{field_err, CaseError, ViewFile};
use crate::io::DicomGeometry;
use crate::pipeline::ABSURD;
use crate::template::Placement;
use crate::views::{Camera, Intrinsics};
use nalgebra::{Matrix3, Rotation3, Vector3};
use std::path::Path;

/// A view's camera and where its values came from.
pub(super) struct ViewCamera {
    /// The camera.
    pub cam: Camera,
    /// The view's image, when it names one.
    pub image: Option<ViewImage>,
    /// The image's DICOM geometry, when it is a DICOM file.
    pub dicom: Option<DicomGeometry>,
    /// fx, fy as the DICOM tags give them, when they do.
    pub dicom_focal: Option<(f64, f64)>,
    /// Per value of k (fx, fy, cx, cy): "case", "dicom" or "image centre".
    pub k_source: [&'static str; 4],
    /// Where the case's k and the DICOM tags disagree by over 1 %.
    pub warnings: Vec<String>,
}

/// The camera of view `vi` (`v`) of the case file at `path` (images relative to `base`), with
/// the template placed at `init` in front of its source.
pub(super) fn view_camera(
    path: &Path,
    base: &Path,
    vi: usize,
    v: &ViewFile,
    init: &Placement,
) -> Result<ViewCamera, CaseError> {
    let f = |name: &str| format!("views[{vi}].{name}");
    // The image first: a DICOM file may give the size and the intrinsics.
    let image = match &v.image {
        Some(p) => Some(view_image(path, &f("image"), &base.join(p))?),
        None => None,
    };
    let (width, height) = image_size(path, vi, v, image.as_ref())?;
    let dicom = image.as_ref().and_then(|i| i.dicom.clone());
    let dicom_focal = match &dicom {
        Some(d) if d.spacing_mm.is_some() && d.sid_mm.is_some() => {
            let p = image.as_ref().map_or(path, |i| i.path.as_path());
            d.focal_px(p).ok()
        }
        _ => None,
    };
    let (k, k_source, warnings) = intrinsics(
        path,
        vi,
        v,
        (width, height),
        image.as_ref(),
        dicom.as_ref(),
        dicom_focal,
    )?;
    let cam = Camera {
        k,
        r: Rotation3::from_matrix(&rotation(path, vi, v)?),
        t: translation(path, vi, v)?,
        width,
        height,
    };
    in_front(path, vi, v, &cam, init)?;
    Ok(ViewCamera {
        cam,
        image,
        dicom,
        dicom_focal,
        k_source,
        warnings,
    })
}

/// The view's width and height: given both, or neither with an image to take them from, and
/// the image's own where both are there.
fn image_size(
    path: &Path,
    vi: usize,
    v: &ViewFile,
    image: Option<&ViewImage>,
) -> Result<(u32, u32), CaseError> {
    let f = |name: &str| format!("views[{vi}].{name}");
    let from_image = image.map(|i| i.size);
    let (width, height) = match (v.width, v.height, from_image) {
        (Some(w), Some(h), _) => (w, h),
        (None, None, Some(s)) => s,
        (w, h, _) => {
            let or_missing = |x: Option<u32>| x.map_or("missing".to_string(), |x| x.to_string());
            return Err(field_err(
                path,
                f("width/height"),
                format!("width {}, height {}", or_missing(w), or_missing(h)),
                "give both width and height, or neither with an image to take them from",
            ));
        }
    };
    if width == 0 || height == 0 || width > 65536 || height > 65536 {
        return Err(field_err(
            path,
            f("width/height"),
            format!("{width}x{height}"),
            "image size must be 1..65536 pixels",
        ));
    }
    if let (Some((w, h)), Some(img)) = (from_image, image) {
        if (w, h) != (width, height) {
            return Err(field_err(
                path,
                f("image"),
                img.path.display(),
                format!("the image is {w}x{h}, the view says {width}x{height}"),
            ));
        }
    }
    Ok((width, height))
}

/// The view's intrinsics: each of fx, fy as given or from the DICOM tags, cx, cy as given or the
/// image centre; with where each came from and a warning per focal length the tags contradict.
fn intrinsics(
    path: &Path,
    vi: usize,
    v: &ViewFile,
    (width, height): (u32, u32),
    image: Option<&ViewImage>,
    dicom: Option<&DicomGeometry>,
    dicom_focal: Option<(f64, f64)>,
) -> Result<(Intrinsics, [&'static str; 4], Vec<String>), CaseError> {
    let f = |name: &str| format!("views[{vi}].{name}");
    let kf = v.k.clone().unwrap_or_default();
    let mut k_source = ["case"; 4];
    let focal = |given: Option<f64>, i: usize, src: &mut [&'static str; 4]| {
        if let Some(val) = given {
            return Ok(val);
        }
        src[i] = "dicom";
        match (dicom, image) {
            (Some(d), Some(img)) => d
                .focal_px(&img.path)
                .map(|(fx, fy)| if i == 0 { fx } else { fy })
                .map_err(|source| CaseError::Dicom {
                    path: path.to_path_buf(),
                    field: f("k"),
                    source: Box::new(source),
                }),
            _ => Err(field_err(
                path,
                f(if i == 0 { "k.fx" } else { "k.fy" }),
                "missing",
                "give k (fx, fy, cx, cy), or an X-ray DICOM image whose pixel spacing and source-to-detector distance give it",
            )),
        }
    };
    let fx = focal(kf.fx, 0, &mut k_source)?;
    let fy = focal(kf.fy, 1, &mut k_source)?;
    let mut centre = |given: Option<f64>, i: usize, half: u32| {
        given.unwrap_or_else(|| {
            k_source[i] = "image centre";
            0.5 * half as f64
        })
    };
    let (cx, cy) = (centre(kf.cx, 2, width), centre(kf.cy, 3, height));
    let mut warnings = Vec::new();
    if let (Some((dfx, dfy)), Some(img)) = (dicom_focal, image) {
        for (name, given, tags) in [("k.fx", kf.fx, dfx), ("k.fy", kf.fy, dfy)] {
            if let Some(g) = given {
                let off = g / tags - 1.0;
                if off.abs() > 0.01 {
                    warnings.push(format!(
                        "{}: {} = {g} in the case, {} gives SID / spacing = {tags:.1} ({:+.1} %); the case's value is used",
                        path.display(),
                        f(name),
                        img.path.display(),
                        100.0 * off
                    ));
                }
            }
        }
    }
    for (i, (name, val)) in [("k.fx", fx), ("k.fy", fy)].into_iter().enumerate() {
        if !(val.is_finite() && val > 0.0 && val < ABSURD) {
            // A focal length the case did not give came from the image's tags: say so.
            let from = match (image, k_source[i]) {
                (Some(img), "dicom") => format!(
                    " (SID / pixel spacing of {}: tags (0018,1110) and (0018,1164) or (0028,0030))",
                    img.path.display()
                ),
                _ => String::new(),
            };
            return Err(field_err(
                path,
                f(name),
                val,
                format!("focal length must be a positive finite number of pixels{from}"),
            ));
        }
    }
    for (name, val) in [("k.cx", cx), ("k.cy", cy)] {
        if !val.is_finite() || val.abs() > ABSURD {
            return Err(field_err(
                path,
                f(name),
                val,
                "principal point must be finite",
            ));
        }
    }
    Ok((Intrinsics { fx, fy, cx, cy }, k_source, warnings))
}

/// The view's world-to-camera rotation: finite, orthonormal, not a reflection.
fn rotation(path: &Path, vi: usize, v: &ViewFile) -> Result<Matrix3<f64>, CaseError> {
    let field = format!("views[{vi}].r");
    let r = Matrix3::from_fn(|i, j| v.r[i][j]);
    if !r.iter().all(|x| x.is_finite()) {
        return Err(field_err(
            path,
            field,
            format!("{:?}", v.r),
            "rotation entries must be finite",
        ));
    }
    let orth = (r.transpose() * r - Matrix3::identity()).abs().max();
    if orth > 1e-4 {
        return Err(field_err(
            path,
            field,
            format!("{:?}", v.r),
            format!("rotation is not orthonormal (|R^T R - I| = {orth:.3e})"),
        ));
    }
    let det = r.determinant();
    if det < 0.0 {
        return Err(field_err(
            path,
            field,
            format!("{:?}", v.r),
            format!("rotation is a reflection (det = {det:.3})"),
        ));
    }
    Ok(r)
}

/// The view's world-to-camera translation: finite numbers of mm.
fn translation(path: &Path, vi: usize, v: &ViewFile) -> Result<Vector3<f64>, CaseError> {
    for (i, val) in v.t.iter().enumerate() {
        if !val.is_finite() || val.abs() > ABSURD {
            return Err(field_err(
                path,
                format!("views[{vi}].t[{i}]"),
                val,
                "translation must be a finite number of mm",
            ));
        }
    }
    Ok(Vector3::from(v.t))
}

/// The whole template sphere at `init` must lie in front of the view's source, or some of its
/// vertices cannot be projected.
fn in_front(
    path: &Path,
    vi: usize,
    v: &ViewFile,
    cam: &Camera,
    init: &Placement,
) -> Result<(), CaseError> {
    let field = format!("views[{vi}].t");
    if let Err(e) = cam.project(&init.center) {
        return Err(field_err(
            path,
            field,
            format!("{:?}", v.t),
            format!("the template centre is not in front of the source: {e}"),
        ));
    }
    let depth = cam.to_camera(&init.center).z;
    if depth <= 1.5 * init.radius {
        return Err(field_err(
            path,
            field,
            format!("{:?}", v.t),
            format!(
                "the template (radius {:.1} mm) reaches to or behind the source: its centre is {depth:.1} mm in front of it",
                init.radius
            ),
        ));
    }
    Ok(())
}
