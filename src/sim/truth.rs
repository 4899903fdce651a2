//! A study's ground truth from its name: `phantom` (the built-in one) or a mesh file, checked to
//! be an acetabulum in millimetres before any run.

use crate::geom::{quantile_sorted, Mesh, Sphere};
use crate::io::read_mesh;
use crate::sim::{fit_placement, ground_truth_surface, phantom, PhantomParams};
use crate::template::Placement;
use std::path::Path;

/// Sphere radii (mm) an acetabulum can have; a truth outside them is refused (in metres or
/// centimetres it would run, but the solver's tolerances and the guards are in millimetres).
pub const PLAUSIBLE_RADIUS_MM: (f64, f64) = (15.0, 60.0);

/// Largest angle from the dome's pole (the 99th percentile over the vertices) a socket may
/// reach, degrees: no vertex of the 47 acetabula of ../shared/data lies farther than 110 from
/// it, none of the deep ones made from them (docs/population.md, "Shallow, deep and flattened
/// acetabula") farther than 121; a whole sphere (a femoral head given by mistake) reaches 171.
pub const MAX_COVERAGE_DEG: f64 = 140.0;

/// Largest RMS distance of the surface (its triangles' centres, weighted by area) from its
/// sphere, mm: the acetabula of ../shared/data and those made from them are within 1.3; a cube
/// is 12.5 from its sphere.
pub const MAX_SPHERE_RMS_MM: f64 = 4.0;

/// The truth cannot be used; the message names it (as `--gt NAME`) and says why.
#[derive(Debug, thiserror::Error)]
#[error("--gt {gt}: {reason}")]
pub struct TruthError {
    /// The truth as given.
    pub gt: String,
    /// Why it is refused.
    pub reason: String,
}

/// The truth `gt` (a mesh file or `phantom`). A surface no sphere fits, one whose sphere's
/// radius is outside `PLAUSIBLE_RADIUS_MM`, one that covers more of its sphere than a socket
/// (`MAX_COVERAGE_DEG`) or lies far from it (`MAX_SPHERE_RMS_MM`), or one the simulated views
/// cannot see is refused; when the mesh is several pieces, the refusal says so.
pub fn load_truth(gt: &str) -> Result<Mesh, TruthError> {
    let err = |reason: String| TruthError {
        gt: gt.to_string(),
        reason,
    };
    let mut pieces = Vec::new();
    let truth = if gt == "phantom" {
        phantom(&PhantomParams::default()).mesh
    } else {
        let mesh = read_mesh(Path::new(gt)).map_err(|e| err(e.to_string()))?;
        pieces = mesh.piece_sizes();
        ground_truth_surface(&mesh).map_err(|e| err(e.to_string()))?
    };
    // A mesh of several pieces is taken as it is (an acetabulum's surface may come in parts);
    // when it is refused, the pieces are named, as they are the likely cause.
    let err = |reason: String| err(format!("{reason}{}", pieces_note(&pieces)));
    let (placement, sphere) =
        fit_placement(&truth).map_err(|e| err(format!("ground truth sphere fit: {e}")))?;
    let r = sphere.radius;
    let (lo, hi) = PLAUSIBLE_RADIUS_MM;
    if !(lo..=hi).contains(&r) {
        // Too small, the likely cause is the unit; too large, a surface of more than the
        // socket (a whole hemipelvis fits a sphere of about 150-200 mm) unless it is far larger.
        let hint = if r < lo || r > 50.0 * hi {
            "is the mesh in millimetres?"
        } else {
            "is it the acetabulum alone (the socket cut from the pelvis, not a whole hemipelvis \
             or femur), and is the mesh in millimetres?"
        };
        return Err(err(format!(
            "the fitted sphere's radius is {r:.3} mm, outside the {lo}-{hi} mm of an \
             acetabulum: {hint}"
        )));
    }
    let coverage = coverage_deg(&truth, &placement);
    if !(coverage <= MAX_COVERAGE_DEG) {
        return Err(err(format!(
            "the surface reaches {coverage:.0} degrees from its dome's pole (an acetabulum \
             about 80-120, at most {MAX_COVERAGE_DEG:.0}): a whole sphere or a femoral head is \
             not a socket"
        )));
    }
    let rms = surface_sphere_rms_mm(&truth, &sphere);
    if !(rms <= MAX_SPHERE_RMS_MM) {
        return Err(err(format!(
            "the surface lies {rms:.1} mm RMS from its fitted sphere (radius {r:.1} mm; an \
             acetabulum within about 1.3, at most {MAX_SPHERE_RMS_MM:.0}): it is not a socket"
        )));
    }
    Ok(truth)
}

/// For a refusal of a mesh of several pieces: how many, and their sizes (at most five listed);
/// empty for one piece.
fn pieces_note(pieces: &[usize]) -> String {
    if pieces.len() < 2 {
        return String::new();
    }
    let shown: Vec<String> = pieces.iter().take(5).map(|n| n.to_string()).collect();
    let more = if pieces.len() > 5 { ", ..." } else { "" };
    format!(
        "; the mesh is {} separate pieces ({}{more} triangles): a truth is one acetabulum's \
         surface; cut away anything else (the other hip, stray fragments of a segmentation)",
        pieces.len(),
        shown.join(", ")
    )
}

/// How far round its fitted hemisphere (`fit_placement`) a surface reaches: the 99th percentile
/// over its vertices of the angle from the dome's pole (opposite the opening axis), degrees.
fn coverage_deg(mesh: &Mesh, placement: &Placement) -> f64 {
    let c = placement.center;
    let pole = -placement.axis.into_inner();
    let mut angles: Vec<f64> = mesh
        .vertices
        .iter()
        .filter_map(|v| (v - c).try_normalize(1e-12))
        .map(|d| d.dot(&pole).clamp(-1.0, 1.0).acos().to_degrees())
        .collect();
    angles.sort_by(f64::total_cmp);
    quantile_sorted(&angles, 0.99)
}

/// RMS distance of a surface from `sphere`: its triangles' centres, weighted by their areas, mm.
fn surface_sphere_rms_mm(mesh: &Mesh, sphere: &Sphere) -> f64 {
    let c = sphere.center_point();
    let (mut sum, mut area) = (0.0, 0.0);
    for t in &mesh.triangles {
        let [a, b, d] = t.map(|i| mesh.vertices[i as usize]);
        let w = 0.5 * (b - a).cross(&(d - a)).norm();
        let mid = nalgebra::Point3::from((a.coords + b.coords + d.coords) / 3.0);
        sum += w * ((mid - c).norm() - sphere.radius).powi(2);
        area += w;
    }
    (sum / area).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::write_stl_binary;
    use crate::template::hemisphere;
    use nalgebra::Point3;

    /// A whole sphere: the hemisphere and its mirror image through the equator.
    fn whole_sphere(r: f64) -> Mesh {
        let h = hemisphere(r, 600);
        let n = h.vertices.len() as u32;
        let mut vertices = h.vertices.clone();
        vertices.extend(h.vertices.iter().map(|p| Point3::new(p.x, p.y, -p.z)));
        let mut triangles = h.triangles.clone();
        triangles.extend(h.triangles.iter().map(|t| [t[0] + n, t[2] + n, t[1] + n]));
        Mesh::new(vertices, triangles).unwrap()
    }

    /// A cube of side `a`: its eight corners lie on one sphere, its faces far inside it.
    fn cube(a: f64) -> Mesh {
        let v: Vec<Point3<f64>> = (0..8)
            .map(|k| {
                Point3::new(
                    (k & 1) as f64 * a,
                    (k >> 1 & 1) as f64 * a,
                    (k >> 2) as f64 * a,
                )
            })
            .collect();
        let f = [
            [0, 2, 3],
            [0, 3, 1],
            [4, 5, 7],
            [4, 7, 6],
            [0, 1, 5],
            [0, 5, 4],
            [2, 6, 7],
            [2, 7, 3],
            [0, 4, 6],
            [0, 6, 2],
            [1, 3, 7],
            [1, 7, 5],
        ];
        Mesh::new(v, f.to_vec()).unwrap()
    }

    /// A truth whose sphere is too small is asked about its unit; one too large, as a whole
    /// hemipelvis would be, whether it is the socket alone; one far too large, about its unit
    /// again.
    #[test]
    fn a_truth_of_the_wrong_size_is_asked_the_likely_question() {
        let dir = tempfile::tempdir().unwrap();
        let refuse = |name: &str, radius: f64| {
            let p = dir.path().join(name);
            write_stl_binary(&hemisphere(radius, 600), &p).unwrap();
            load_truth(&p.to_string_lossy()).unwrap_err().reason
        };
        let cm = refuse("cm.stl", 2.5);
        assert!(
            cm.contains("is the mesh in millimetres?") && !cm.contains("alone"),
            "{cm}"
        );
        let pelvis = refuse("pelvis.stl", 180.0);
        assert!(
            pelvis.contains("radius is 180.0") && pelvis.contains("the acetabulum alone"),
            "{pelvis}"
        );
        let microns = refuse("microns.stl", 25_000.0);
        assert!(!microns.contains("alone"), "{microns}");
        // Companion: the same cap at a socket's size is taken.
        let p = dir.path().join("cap.stl");
        write_stl_binary(&hemisphere(25.0, 600), &p).unwrap();
        assert!(load_truth(&p.to_string_lossy()).is_ok());
    }

    /// A hemisphere is a socket; a whole sphere (a femoral head given by mistake) reaches too
    /// far round its sphere and a cube lies too far from its sphere, each refused with the
    /// reason and the file named; the companions pass: a hemisphere reaches 90 degrees and lies
    /// on its sphere.
    #[test]
    fn a_whole_sphere_or_a_cube_is_not_taken_for_a_socket() {
        let h = hemisphere(25.0, 600);
        let (p, s) = fit_placement(&h).unwrap();
        assert!(
            (coverage_deg(&h, &p) - 90.0).abs() < 3.0,
            "{}",
            coverage_deg(&h, &p)
        );
        assert!(surface_sphere_rms_mm(&h, &s) < 0.5);
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, m: &Mesh| {
            let p = dir.path().join(name);
            write_stl_binary(m, &p).unwrap();
            p.to_string_lossy().into_owned()
        };
        assert!(load_truth(&write("cap.stl", &h)).is_ok());
        let e = load_truth(&write("head.stl", &whole_sphere(25.0))).unwrap_err();
        assert!(
            e.to_string().contains("head.stl") && e.reason.contains("not a socket"),
            "{e}"
        );
        assert!(e.reason.contains("degrees from its dome's pole"), "{e}");
        // Two caps 150 mm apart (both hips in one file): their sphere is no acetabulum's,
        // and the refusal names the two pieces as the likely cause.
        let other = h.with_vertices(
            h.vertices
                .iter()
                .map(|p| p + nalgebra::Vector3::new(150.0, 0.0, 0.0))
                .collect(),
        );
        let e = load_truth(&write("both.stl", &h.joined(&other))).unwrap_err();
        assert!(
            e.to_string().contains("both.stl") && e.reason.contains("2 separate pieces"),
            "{e}"
        );
        // Companion: a fragment near the cap, inside its sphere's reach, leaves a socket that
        // is used as it is (several pieces alone are not refused).
        let near = h.joined(&Mesh::triangle([
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(0.5, 0.0, 1.0),
            Point3::new(0.0, 0.5, 1.0),
        ]));
        assert_eq!(near.piece_sizes().len(), 2);
        assert!(load_truth(&write("near.stl", &near)).is_ok());
        // A refusal of one piece names no pieces.
        assert!(pieces_note(&[10]).is_empty());
        let e = load_truth(&write("cube.stl", &cube(40.0))).unwrap_err();
        assert!(
            e.to_string().contains("cube.stl") && e.reason.contains("mm RMS"),
            "{e}"
        );
    }
}
