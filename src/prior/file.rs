//! The prior file (`acetab prior build`): every training acetabulum's deviation field, so that a
//! study can leave a subject out (both hips together) and learn the prior from the rest.

use super::field::{deviation_field, GRID_POINTS, KERNEL_DEG};
use super::model::{meshes_needed, PriorError, ShapePrior, MAX_MODES};
use crate::geom::{fit_sphere, Mesh};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The format tag the file carries.
pub const FORMAT: &str = "acetab-shape-prior-1";

/// Modes a prior carries unless told otherwise.
pub const DEFAULT_MODES: usize = 4;

/// One training acetabulum.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorMesh {
    /// Its name (the file's, without the extension).
    pub name: String,
    /// Its subject: both hips of one person share it, and leave together.
    pub subject: String,
    /// Its sphere's radius, mm.
    pub radius_mm: f64,
    /// Whether it opened towards +x and was mirrored.
    pub mirrored: bool,
    /// Relative radial deviation per grid direction; null where the mesh does not reach.
    pub deviation: Vec<Option<f64>>,
}

/// A prior file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorFile {
    /// `FORMAT`.
    pub format: String,
    /// Directions of the grid (a Fibonacci sphere).
    pub grid_points: usize,
    /// The kernel's SD, degrees.
    pub kernel_deg: f64,
    /// Principal modes the prior uses.
    pub modes: usize,
    /// What it was learned from, for people (data, attribution).
    pub learned_from: String,
    /// The training acetabula.
    pub meshes: Vec<PriorMesh>,
}

/// Why a prior file cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PriorFileError {
    /// The file cannot be read.
    #[error("{path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a prior.
    #[error("{path}: not a shape prior: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// A field holds a value that cannot be used.
    #[error("{path}: {field} = {value}: must be {expected}")]
    Field {
        /// The file.
        path: PathBuf,
        /// The field.
        field: String,
        /// Its value.
        value: String,
        /// What it must be.
        expected: String,
    },
    /// A leave-one-subject-out prior was asked for without a prior to leave the subject out of.
    #[error(
        "a prior left without subject {0} needs a prior (\"default\" or a file), not \"none\""
    )]
    NothingToLeaveOut(String),
    /// No prior can be learned from what is left.
    #[error("{path}: {source}")]
    Learn {
        /// The file.
        path: PathBuf,
        /// Why.
        source: PriorError,
    },
}

/// The prior built from the shared populations (8 LibHip cartilage shells, MIT; 39 bone-side
/// acetabula of the JHU I-STAR pelvis atlas, CC BY 4.0; see README.md), shipped with the program.
pub const SHIPPED_JSON: &str = include_str!("../../priors/default.json");

/// Round a deviation for the file (1e-5 of the radius: a fraction of a micrometre).
fn rounded(v: f64) -> f64 {
    (v * 1e5).round() / 1e5
}

/// A prior by the name users give it: "none" (no prior), "default" (the shipped one) or the path
/// of a file from `acetab prior build`; with `leave_out`, learned without that subject's meshes.
/// The prior (None for "none") and a line saying where it came from, for reports.
pub fn choose_prior(
    choice: &str,
    leave_out: Option<&str>,
) -> Result<(Option<ShapePrior>, String), PriorFileError> {
    let file = match (choice, leave_out) {
        ("none", None) => return Ok((None, "none".into())),
        ("none", Some(s)) => return Err(PriorFileError::NothingToLeaveOut(s.into())),
        ("default", _) => PriorFile::shipped(),
        (path, _) => PriorFile::read(Path::new(path))?,
    };
    let (file, what) = match leave_out {
        Some(s) => (
            file.without_subject(s),
            format!("{choice} without subject {s}"),
        ),
        None => (file, choice.to_string()),
    };
    let prior = file.prior().map_err(|e| match e {
        PriorFileError::Learn { source, .. } => PriorFileError::Learn {
            path: PathBuf::from(&what),
            source,
        },
        other => other,
    })?;
    let what = format!(
        "{what} ({} meshes, {} modes)",
        file.meshes.len(),
        prior.mode_count()
    );
    Ok((Some(prior), what))
}

/// A field that is wrong: its name, its value and what it must be.
type Bad = (String, String, String);

impl PriorMesh {
    /// The training entry of surface `mesh` (an acetabulum in body axes, mm).
    pub fn of(name: &str, subject: &str, mesh: &Mesh) -> Result<PriorMesh, String> {
        let s = fit_sphere(&mesh.vertices).map_err(|e| format!("{name}: sphere fit: {e}"))?;
        let (field, mirrored) = deviation_field(&mesh.vertices, &s);
        if field.iter().all(Option::is_none) {
            return Err(format!("{name}: no direction is covered"));
        }
        Ok(PriorMesh {
            name: name.to_string(),
            subject: subject.to_string(),
            radius_mm: (s.radius * 1e6).round() / 1e6,
            mirrored,
            deviation: field.into_iter().map(|v| v.map(rounded)).collect(),
        })
    }

    /// The `i`-th mesh's fields, the meshes before it being `before`: a name and a subject, a
    /// name no earlier mesh has, an acetabulum's radius, and a deviation for every grid direction
    /// within +-1.
    fn check(&self, i: usize, before: &[PriorMesh]) -> Result<(), Bad> {
        // A mesh without a name cannot be told apart, one without a subject never leaves with
        // its subject (`--prior-leave-out` would keep it in its own prior).
        for (key, value) in [("name", &self.name), ("subject", &self.subject)] {
            if value.trim().is_empty() {
                return Err((
                    format!("meshes[{i}].{key}"),
                    format!("{value:?}"),
                    format!("a mesh's {key}, not empty"),
                ));
            }
        }
        // One mesh twice would weigh twice in the mean and the modes (`prior build` refuses two
        // meshes of one name).
        if let Some(first) = before.iter().position(|o| o.name == self.name) {
            return Err((
                format!("meshes[{i}].name"),
                self.name.clone(),
                format!("a name no other mesh has (meshes[{first}] has it too)"),
            ));
        }
        if !(self.radius_mm.is_finite() && (10.0..=80.0).contains(&self.radius_mm)) {
            return Err((
                format!("meshes[{i}].radius_mm ({})", self.name),
                self.radius_mm.to_string(),
                "an acetabulum's radius, 10 to 80 mm".into(),
            ));
        }
        if self.deviation.len() != GRID_POINTS {
            return Err((
                format!("meshes[{i}].deviation ({})", self.name),
                format!("{} values", self.deviation.len()),
                format!("{GRID_POINTS} values"),
            ));
        }
        if let Some(v) = self
            .deviation
            .iter()
            .flatten()
            .find(|v| !(v.is_finite() && v.abs() <= 1.0))
        {
            return Err((
                format!("meshes[{i}].deviation ({})", self.name),
                v.to_string(),
                "within +-1 (a share of the radius)".into(),
            ));
        }
        Ok(())
    }
}

impl PriorFile {
    /// A prior file of `meshes` with `modes` modes.
    pub fn new(meshes: Vec<PriorMesh>, modes: usize, learned_from: String) -> PriorFile {
        PriorFile {
            format: FORMAT.to_string(),
            grid_points: GRID_POINTS,
            kernel_deg: KERNEL_DEG,
            modes,
            learned_from,
            meshes,
        }
    }

    /// The shipped prior.
    pub fn shipped() -> PriorFile {
        Self::parse(SHIPPED_JSON, Path::new("priors/default.json"))
            .expect("the shipped prior is valid (tested)")
    }

    /// Read and check a prior file.
    pub fn read(path: &Path) -> Result<PriorFile, PriorFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| PriorFileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parse and check prior JSON (`path` names it in errors): the format, the grid, the modes,
    /// every mesh's field, and that there are enough meshes for the modes.
    pub fn parse(text: &str, path: &Path) -> Result<PriorFile, PriorFileError> {
        let f: PriorFile = crate::io::parse_json(text).map_err(|reason| PriorFileError::Parse {
            path: path.to_path_buf(),
            reason,
        })?;
        let bad = |(field, value, expected): Bad| PriorFileError::Field {
            path: path.to_path_buf(),
            field,
            value: crate::io::shown(&value),
            expected,
        };
        f.check_settings().map_err(bad)?;
        for (i, m) in f.meshes.iter().enumerate() {
            m.check(i, &f.meshes[..i]).map_err(bad)?;
        }
        // Enough meshes for the modes (the fields were checked above; the prior itself is
        // learned when it is used, from whatever a leave-out keeps).
        let need = meshes_needed(f.modes);
        if f.meshes.len() < need {
            return Err(PriorFileError::Learn {
                path: path.to_path_buf(),
                source: PriorError::TooFewMeshes {
                    modes: f.modes,
                    need,
                    got: f.meshes.len(),
                },
            });
        }
        Ok(f)
    }

    /// The file's settings: its format, the grid, the kernel and the number of modes this code
    /// reads.
    fn check_settings(&self) -> Result<(), Bad> {
        if self.format != FORMAT {
            return Err((
                "format".into(),
                self.format.clone(),
                format!("\"{FORMAT}\""),
            ));
        }
        if self.grid_points != GRID_POINTS {
            return Err((
                "grid_points".into(),
                self.grid_points.to_string(),
                GRID_POINTS.to_string(),
            ));
        }
        if self.kernel_deg != KERNEL_DEG {
            return Err((
                "kernel_deg".into(),
                self.kernel_deg.to_string(),
                KERNEL_DEG.to_string(),
            ));
        }
        if self.modes > MAX_MODES {
            return Err((
                "modes".into(),
                self.modes.to_string(),
                format!("0 to {MAX_MODES}"),
            ));
        }
        Ok(())
    }

    /// The same file without the meshes of `subject` (leave-one-subject-out).
    pub fn without_subject(&self, subject: &str) -> PriorFile {
        let mut f = self.clone();
        f.meshes.retain(|m| m.subject != subject);
        f
    }

    /// The subjects it was learned from, in order, once each.
    pub fn subjects(&self) -> Vec<String> {
        let mut s: Vec<String> = Vec::new();
        for m in &self.meshes {
            if !s.contains(&m.subject) {
                s.push(m.subject.clone());
            }
        }
        s
    }

    /// The prior the reconstruction uses.
    pub fn prior(&self) -> Result<ShapePrior, PriorFileError> {
        let fields: Vec<(String, Vec<Option<f64>>)> = self
            .meshes
            .iter()
            .map(|m| (m.name.clone(), m.deviation.clone()))
            .collect();
        ShapePrior::learn(&fields, self.modes).map_err(|source| PriorFileError::Learn {
            path: PathBuf::from("the prior"),
            source,
        })
    }

    /// The file as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a prior file serialises")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::template::hemisphere;
    use nalgebra::Point3;

    fn cap(flat: f64, x_sign: f64) -> Mesh {
        let mut m = hemisphere(25.0, 1200);
        for p in &mut m.vertices {
            *p = Point3::new(x_sign * p.z, p.y * (1.0 - flat), -x_sign * p.x);
        }
        m
    }

    fn file() -> PriorFile {
        let meshes = [
            (0.02, -1.0),
            (0.05, 1.0),
            (0.08, -1.0),
            (0.03, 1.0),
            (0.06, -1.0),
            (0.04, 1.0),
        ]
        .iter()
        .enumerate()
        .map(|(i, &(f, s))| {
            PriorMesh::of(
                &format!("s{}_{}hip", i / 2, ["l", "r"][i % 2]),
                &format!("s{}", i / 2),
                &cap(f, s),
            )
            .unwrap()
        })
        .collect();
        PriorFile::new(meshes, 1, "test caps".into())
    }

    #[test]
    fn a_prior_file_reads_back_as_written_and_leaves_a_subject_out() {
        let f = file();
        let back = PriorFile::parse(&f.to_json(), Path::new("p.json")).unwrap();
        // (Compared without printing: a failure would dump thousands of values.)
        assert!(back == f, "the file read back differs from the one written");
        assert_eq!(f.subjects(), ["s0", "s1", "s2"]);
        let left = f.without_subject("s0");
        assert_eq!(left.meshes.len(), 4);
        assert!(left.meshes.iter().all(|m| m.subject != "s0"));
        assert!(left.prior().unwrap() != f.prior().unwrap());
        assert!(PriorFile::shipped().prior().is_ok());
    }

    #[test]
    fn a_prior_is_chosen_by_name_and_a_subject_left_out_of_it() {
        assert!(choose_prior("none", None).unwrap().0.is_none());
        assert!(matches!(
            choose_prior("none", Some("a02")),
            Err(PriorFileError::NothingToLeaveOut(_))
        ));
        let (all, what) = choose_prior("default", None).unwrap();
        let shipped = PriorFile::shipped();
        assert!(
            what.contains(&format!("({} meshes, ", shipped.meshes.len())),
            "{what}"
        );
        let (loso, what) = choose_prior("default", Some("a02")).unwrap();
        let left = shipped.without_subject("a02").meshes.len();
        assert_eq!(left + 2, shipped.meshes.len());
        assert!(
            what.contains(&format!("default without subject a02 ({left} meshes")),
            "{what}"
        );
        assert!(all.unwrap() != loso.unwrap());
        let e = choose_prior("/nonexistent/p.json", None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/p.json"), "{e}");
    }

    #[test]
    fn a_bad_prior_file_names_the_field_and_value() {
        let f = file();
        let p = Path::new("bad.json");
        let mut g = f.clone();
        g.meshes[1].radius_mm = 250.0;
        let e = PriorFile::parse(&g.to_json(), p).unwrap_err().to_string();
        assert!(
            e.contains("bad.json") && e.contains("meshes[1].radius_mm") && e.contains("250"),
            "{e}"
        );
        let mut g = f.clone();
        g.meshes[0].deviation[5] = Some(3.0);
        let e = PriorFile::parse(&g.to_json(), p).unwrap_err().to_string();
        assert!(e.contains("meshes[0].deviation") && e.contains('3'), "{e}");
        // One mesh listed twice (it would weigh twice); the companion: the file as written,
        // every name once, reads.
        assert!(PriorFile::parse(&f.to_json(), p).is_ok());
        let mut g = f.clone();
        g.meshes.push(g.meshes[0].clone());
        let e = PriorFile::parse(&g.to_json(), p).unwrap_err().to_string();
        let last = g.meshes.len() - 1;
        assert!(
            e.contains(&format!("meshes[{last}].name = {}", g.meshes[0].name))
                && e.contains("meshes[0] has it too"),
            "{e}"
        );
        // A mesh with no name, or no subject to leave out with, is refused naming the field.
        for blank in ["name", "subject"] {
            let mut g = f.clone();
            match blank {
                "name" => g.meshes[2].name = " ".into(),
                _ => g.meshes[2].subject = String::new(),
            }
            let e = PriorFile::parse(&g.to_json(), p).unwrap_err().to_string();
            assert!(
                e.contains(&format!("meshes[2].{blank}")) && e.contains("not empty"),
                "{e}"
            );
        }
        let mut g = f.clone();
        g.modes = 12;
        let e = PriorFile::parse(&g.to_json(), p).unwrap_err().to_string();
        assert!(e.contains("modes = 12"), "{e}");
        let mut g = f.clone();
        g.meshes.truncate(2);
        let e = PriorFile::parse(&g.to_json(), p).unwrap_err().to_string();
        assert!(e.contains("bad.json") && e.contains("at least 3"), "{e}");
        let e = PriorFile::parse("{\"format\": 1}", p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a shape prior"), "{e}");
        let e = PriorFile::read(Path::new("/nonexistent/prior.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/prior.json"), "{e}");
    }
}
