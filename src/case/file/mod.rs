//! Case files (JSON): the views (K, R, t, image size, optional image), their annotated contours,
//! and the template's initial placement. Everything is validated on load; an error names the
//! file, the field and the value: the format and the case as a whole here, a view's camera in
//! `camera` (its image's header in `image`), its contours in `contour`.

mod camera;
mod contour;
mod image;

use super::views_agree::{outline_centre_mismatch, outline_span_mismatch, Views};
use crate::geom::Curve;
use crate::pipeline::{Input, ABSURD, START_RADIUS_MM};
use crate::template::{Placement, Template};
use crate::views::{cameras_too_narrow, Camera, MAX_VIEWS, MIN_VIEWS, MIN_VIEW_SPREAD_DEG};
use nalgebra::{Point2, Point3, Unit, Vector3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Intrinsics as written in a case file. A field left out is taken from the view's DICOM image:
/// fx, fy = source-to-detector distance / pixel spacing, cx, cy = the image centre.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct IntrinsicsFile {
    /// Focal length in x, pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fx: Option<f64>,
    /// Focal length in y, pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fy: Option<f64>,
    /// Principal point x, pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cx: Option<f64>,
    /// Principal point y, pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cy: Option<f64>,
}

/// What an annotated contour covers.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ContourKind {
    /// The whole rim, a closed loop.
    Closed,
    /// Part of the rim (where blurred walls are left out). The model outline is always closed,
    /// so an open contour is matched to its best sub-arc, either direction.
    Open,
    /// The same as `open`: an arc matched to a part of the model outline.
    Partial,
}

/// One annotated contour: a pixel polyline and what it covers, given either as
/// `"closed": true|false` or as `"kind": "closed"|"open"|"partial"` (exactly one of them).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ContourFile {
    /// The rim's points, pixels, in order.
    pub points: Vec<[f64; 2]>,
    /// Whether the rim is closed (may be left out when `kind` says it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub closed: Option<bool>,
    /// closed, open (a part left out) or partial (an arc of a closed rim).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<ContourKind>,
    /// The points are clicks on the rim rather than a traced line (default false): the method
    /// meets the curve through them (`Curve::clicked`), not the straight steps between them,
    /// which cut inside a round rim and make the cup small the farther apart the clicks are.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clicked: Option<bool>,
}

/// One view.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ViewFile {
    /// The view's name (AP, oblique, ...).
    #[serde(default)]
    pub name: Option<String>,
    /// Intrinsics (may be left out, whole or in part, when `image` is an X-ray DICOM file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k: Option<IntrinsicsFile>,
    /// World-to-camera rotation, rows.
    pub r: [[f64; 3]; 3],
    /// World-to-camera translation, mm.
    pub t: [f64; 3],
    /// Image width, pixels (may be left out when `image` is given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    /// Image height, pixels (may be left out when `image` is given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
    /// Optional X-ray image (PNG, JPEG or a DX/CR DICOM file), relative to the case file.
    #[serde(default)]
    pub image: Option<PathBuf>,
    /// The rim annotated in this view (one or more contours).
    pub contours: Vec<ContourFile>,
}

/// Initial template placement.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TemplateFile {
    /// Sphere centre, mm.
    pub center: [f64; 3],
    /// Sphere radius, mm.
    pub radius: f64,
    /// Opening axis: from the sphere centre out through the rim plane.
    pub axis: [f64; 3],
}

/// A whole case.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CaseFile {
    /// The views.
    pub views: Vec<ViewFile>,
    /// Where the template starts.
    pub template: TemplateFile,
}

/// A validated case, ready for reconstruction.
#[derive(Clone, Debug)]
pub struct Case {
    /// The views as cameras.
    pub cameras: Vec<Camera>,
    /// Per view, the observed outlines.
    pub observed: Vec<Vec<Curve>>,
    /// The template's start.
    pub init: Placement,
    /// Per view, its X-ray image, when given.
    pub images: Vec<Option<PathBuf>>,
    /// Per view, its name.
    pub names: Vec<String>,
    /// Per view, where its intrinsics came from and what its DICOM file says.
    pub geometry: Vec<ViewGeometry>,
    /// What the case's views disagree on (a k that differs from its DICOM tags by over 1 %).
    pub warnings: Vec<String>,
    /// Per view, the points of its contours marked `clicked`, as given (the method meets the
    /// curve through them, `Curve::clicked`; the overlay marks them); empty where none is.
    pub clicks: Vec<Vec<Point2<f64>>>,
}

/// Where a view's intrinsics came from, and the magnification they imply at the object.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ViewGeometry {
    /// The view's name.
    pub view: String,
    /// The intrinsics used.
    pub k: [f64; 4],
    /// Per value of `k` (fx, fy, cx, cy): "case", "dicom" (SID / spacing) or "image centre".
    pub k_source: [&'static str; 4],
    /// The DICOM image, when the view's image is one.
    pub dicom_file: Option<String>,
    /// What the DICOM file says.
    pub dicom: Option<crate::io::DicomGeometry>,
    /// fx, fy from the DICOM tags, when they give them.
    pub dicom_focal_px: Option<[f64; 2]>,
    /// Magnification at the object: SID / SOD from the DICOM tags, when both are there.
    pub magnification_dicom: Option<f64>,
    /// Pixels per mm at the template's centre as the views place it (fx / depth).
    pub px_per_mm_at_object: f64,
    /// The magnification at the template's centre: pixel spacing x pixels per mm, when the
    /// spacing is known.
    pub magnification_at_object: Option<f64>,
}

/// A case file is unusable.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CaseError {
    /// The case file cannot be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The case file is not valid JSON of the case format.
    #[error("{path}: invalid JSON: {message}")]
    Json {
        /// The file.
        path: PathBuf,
        /// serde_json's message (with line and column).
        message: String,
    },
    /// A field holds a value the method cannot use.
    #[error("{path}: field {field} = {value}: {reason}")]
    Field {
        /// The file.
        path: PathBuf,
        /// The field, as a path (`views[1].k.fx`).
        field: String,
        /// Its value.
        value: String,
        /// What it must be.
        reason: String,
    },
    /// A view's DICOM image cannot give what the view needs.
    #[error("{path}: field {field}: {source}")]
    Dicom {
        /// The case file.
        path: PathBuf,
        /// The field (`views[0].image`).
        field: String,
        /// What the DICOM file lacks.
        source: Box<crate::io::DicomError>,
    },
}

fn field_err(
    path: &Path,
    field: impl Into<String>,
    value: impl std::fmt::Display,
    reason: impl Into<String>,
) -> CaseError {
    CaseError::Field {
        path: path.to_path_buf(),
        field: field.into(),
        value: crate::io::shown(&value.to_string()),
        reason: reason.into(),
    }
}

// The least share of its convex hull a closed contour must enclose, and the other outline rules
// the library holds every caller to (`pipeline::check_input`).
pub use crate::pipeline::MIN_HULL_FILL;

pub use contour::{open_arc, OpenArc, OPEN_ARC_RATIO, OPEN_ARC_SHARE};

impl Case {
    /// The reconstruction's input: this case's views, outlines and start, with `template`.
    pub fn input<'a>(&'a self, template: &'a Template) -> Input<'a> {
        Input::new(&self.cameras, &self.observed, &self.init, template)
    }
}

impl CaseFile {
    /// Read and validate.
    pub fn load(path: &Path) -> Result<Case, CaseError> {
        let text = std::fs::read_to_string(path).map_err(|source| CaseError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let file: CaseFile = crate::io::parse_json(&text).map_err(|message| CaseError::Json {
            path: path.to_path_buf(),
            message,
        })?;
        file.validate(path)
    }

    /// Check every field and build the cameras, curves and placement.
    pub fn validate(&self, path: &Path) -> Result<Case, CaseError> {
        self.check_view_count(path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        let mut case = Case {
            cameras: Vec::new(),
            observed: Vec::new(),
            init: self.placement(path)?,
            images: Vec::new(),
            names: Vec::new(),
            geometry: Vec::new(),
            warnings: Vec::new(),
            clicks: Vec::new(),
        };
        for (vi, v) in self.views.iter().enumerate() {
            let view = camera::view_camera(path, base, vi, v, &case.init)?;
            let cam = view.cam;
            let contours = contour::view_contours(path, vi, v, (cam.width, cam.height))?;
            let name = v.name.clone().unwrap_or_else(|| format!("view{vi}"));
            let px_per_mm = cam.pixels_per_mm_at(&case.init.center);
            case.geometry.push(ViewGeometry {
                view: name.clone(),
                k: [cam.k.fx, cam.k.fy, cam.k.cx, cam.k.cy],
                k_source: view.k_source,
                dicom_file: view
                    .dicom
                    .as_ref()
                    .and(view.image.as_ref())
                    .map(|i| i.path.display().to_string()),
                magnification_dicom: view.dicom.as_ref().and_then(|d| d.magnification()),
                magnification_at_object: view
                    .dicom
                    .as_ref()
                    .and_then(|d| d.spacing_mm)
                    .map(|s| px_per_mm * 0.5 * (s[0] + s[1])),
                dicom_focal_px: view.dicom_focal.map(|(a, b)| [a, b]),
                dicom: view.dicom,
                px_per_mm_at_object: px_per_mm,
            });
            case.warnings.extend(view.warnings);
            case.warnings.extend(contours.warnings);
            case.cameras.push(cam);
            case.observed.push(contours.curves);
            case.clicks.push(contours.clicks);
            case.images.push(view.image.map(|i| i.path));
            case.names.push(name);
        }
        views_agree(path, &case)?;
        Ok(case)
    }

    /// `MIN_VIEWS` to `MAX_VIEWS` views.
    fn check_view_count(&self, path: &Path) -> Result<(), CaseError> {
        if self.views.len() < MIN_VIEWS {
            return Err(field_err(
                path,
                "views",
                self.views.len(),
                format!("at least {MIN_VIEWS} views are needed (3 recommended)"),
            ));
        }
        if self.views.len() > MAX_VIEWS {
            return Err(field_err(
                path,
                "views",
                self.views.len(),
                format!("at most {MAX_VIEWS} views"),
            ));
        }
        Ok(())
    }

    /// The template's start: a finite centre, a radius within `START_RADIUS_MM`, a finite
    /// non-zero axis.
    fn placement(&self, path: &Path) -> Result<Placement, CaseError> {
        let tp = &self.template;
        for (i, v) in tp.center.iter().enumerate() {
            if !v.is_finite() || v.abs() > ABSURD {
                return Err(field_err(
                    path,
                    format!("template.center[{i}]"),
                    v,
                    "must be a finite number of mm",
                ));
            }
        }
        let (lo, hi) = START_RADIUS_MM;
        if !(tp.radius.is_finite() && tp.radius > lo && tp.radius < hi) {
            return Err(field_err(
                path,
                "template.radius",
                tp.radius,
                format!("must be between {lo} and {hi} mm"),
            ));
        }
        let axis = Vector3::from(tp.axis);
        if !axis.iter().all(|v| v.is_finite()) || axis.norm() < 1e-9 {
            return Err(field_err(
                path,
                "template.axis",
                format!("{:?}", tp.axis),
                "must be a finite non-zero vector",
            ));
        }
        Ok(Placement {
            center: Point3::from(tp.center),
            radius: tp.radius,
            axis: Unit::new_normalize(axis),
        })
    }

    /// The case file for cameras, curves and a placement (inverse of `validate`).
    pub fn from_parts(cameras: &[Camera], observed: &[Vec<Curve>], init: &Placement) -> CaseFile {
        CaseFile {
            views: cameras
                .iter()
                .zip(observed)
                .enumerate()
                .map(|(i, (c, curves))| ViewFile {
                    name: Some(format!("view{i}")),
                    k: Some(IntrinsicsFile {
                        fx: Some(c.k.fx),
                        fy: Some(c.k.fy),
                        cx: Some(c.k.cx),
                        cy: Some(c.k.cy),
                    }),
                    r: [0, 1, 2].map(|row| [0, 1, 2].map(|col| c.r.matrix()[(row, col)])),
                    t: [c.t.x, c.t.y, c.t.z],
                    width: Some(c.width),
                    height: Some(c.height),
                    image: None,
                    contours: curves
                        .iter()
                        .map(|cv| ContourFile {
                            points: cv.points.iter().map(|p| [p.x, p.y]).collect(),
                            closed: Some(cv.closed),
                            kind: None,
                            clicked: None,
                        })
                        .collect(),
                })
                .collect(),
            template: TemplateFile {
                center: [init.center.x, init.center.y, init.center.z],
                radius: init.radius,
                axis: [init.axis.x, init.axis.y, init.axis.z],
            },
        }
    }
}

/// The views together: they look along directions far enough apart for the cap's depth, and
/// their outlines agree in span and centre.
fn views_agree(path: &Path, case: &Case) -> Result<(), CaseError> {
    // Depth comes from views that look along different directions: views that all look
    // the same way give the same outline, and the cap's distance along the ray is free.
    if let Some(widest) = cameras_too_narrow(&case.cameras) {
        return Err(field_err(
            path,
            "views[*].r".to_string(),
            format!("{} views, at most {widest:.2} degrees apart", case.cameras.len()),
            format!(
                "the views look along the same direction, or too nearly: at least two must differ by {MIN_VIEW_SPREAD_DEG} degrees or more for the cap's depth along them (simulated views 12 degrees apart or less ended runs over 3 mm off); the paper's span 40"
            ),
        ));
    }
    let px_per_mm: Vec<f64> = case
        .geometry
        .iter()
        .map(|g| g.px_per_mm_at_object)
        .collect();
    let views = Views {
        names: &case.names,
        cameras: &case.cameras,
        observed: &case.observed,
        px_per_mm: &px_per_mm,
    };
    if let Some(d) = outline_span_mismatch(&views).or_else(|| outline_centre_mismatch(&views)) {
        return Err(field_err(path, d.field, d.value, d.reason));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{phantom, simulate_case, NoiseLevel, PhantomParams, XrayGeometry};
    use nalgebra::Rotation3;

    /// The phantom's antero-posterior view and two copies of it turned `deg` each way about the
    /// body's long axis through the cup's centre (which so stays at the same pixel), each with
    /// the AP view's outline, through a case file.
    fn ap_turned(deg: f64) -> Result<Case, CaseError> {
        let truth = phantom(&PhantomParams::default()).mesh;
        let geometry = XrayGeometry {
            views: vec!["z:0".parse().unwrap(), "z:20".parse().unwrap()],
            ..Default::default()
        };
        let sim = simulate_case(&truth, &geometry, 2.0, &NoiseLevel::level(1).unwrap(), 3).unwrap();
        let ap = &sim.cameras[0];
        let centre = Vector3::from(sim.truth_sphere.center);
        let turned = |a: f64| {
            let q_inv = Rotation3::from_axis_angle(&Vector3::z_axis(), -a.to_radians());
            Camera {
                r: ap.r * q_inv,
                t: ap.t + ap.r * (centre - q_inv * centre),
                ..ap.clone()
            }
        };
        let cameras = [ap.clone(), turned(deg), turned(-deg)];
        let observed = vec![sim.observed[0].clone(); 3];
        CaseFile::from_parts(&cameras, &observed, &sim.init).validate(Path::new("near.json"))
    }

    /// Views 12 degrees apart leave the cap's depth open (runs over 3 mm off in simulation):
    /// refused, the spread and the field named. Companion: the same views 16 degrees apart pass.
    #[test]
    fn views_too_near_one_direction_are_refused_with_their_spread() {
        let e = ap_turned(6.0).expect_err("views 12 degrees apart refused");
        let msg = e.to_string();
        assert!(
            msg.contains("near.json")
                && msg.contains("views[*].r")
                && msg.contains("at most 12.00 degrees apart")
                && msg.contains("too nearly"),
            "{msg}"
        );
        if let Err(e) = ap_turned(8.0) {
            panic!("views 16 degrees apart refused: {e}");
        }
    }
}
