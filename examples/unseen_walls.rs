//! Twins the study's X-rays cannot tell apart. The three views all turn about z (0 and +-20
//! degrees), so a part of the acetabulum whose radial direction d (from the truth's sphere
//! centre) has |d.y| above tan(20 deg) * |d.x| never forms an outline. This example pushes those
//! walls (|d.y| >= 0.6, blended in from 0.4, and only away from the surface's border, whose rim
//! can form outlines) radially out by +delta and in by -delta, then measures:
//!
//! - how far the twins' outlines, traced as the study traces the annotation (same views, same
//!   alpha), lie from the truth's, in pixels (the study adds 2 px of noise to every point);
//! - the twins' ground-truth cup diameters (the sphere fitted to the whole surface);
//! - the mean distance between the twins (truth -> result, as `mae_mm` measures).
//!
//! Both twins give the same outlines to within a fraction of a pixel, so any method returns the
//! same cup for both, and for one of them it is off by at least half the gap between their
//! diameters. A gap over 2 mm means the study's cup bar (within 1 mm) cannot hold on both; the
//! same holds for the surface: on one twin the error is at least half their distance.
//!
//! Run: cargo run --release --example unseen_walls -- [--delta 1.0] [--write DIR] MESH|phantom...
//! (`--write DIR` saves each twin as DIR/<name>_plus.obj and _minus.obj for `acetab simulate`.)

use acetab::contours::model_contour;
use acetab::correspond::icp_matches;
use acetab::geom::Mesh;
use acetab::io::{read_mesh, write_obj};
use acetab::report::{accuracy_from, accuracy_samples};
use acetab::sim::XrayGeometry;
use acetab::sim::{fit_placement, ground_truth_surface, observed_alpha, SimSetup};
use acetab::sim::{phantom, PhantomParams};
use nalgebra::{Point2, Point3};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

fn smoothstep(lo: f64, hi: f64, x: f64) -> f64 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// How much of the push each vertex takes: 1 in the walls no view sees, 0 in the belt that forms
/// the outlines and within 2 mm of the border, smooth in between.
fn wall_weights(truth: &Mesh, c: &Point3<f64>) -> Vec<f64> {
    let border: Vec<Point3<f64>> = {
        let mut ids: Vec<u32> = truth.boundary_edges().into_iter().flatten().collect();
        ids.sort_unstable();
        ids.dedup();
        ids.iter().map(|&i| truth.vertices[i as usize]).collect()
    };
    truth
        .vertices
        .iter()
        .map(|v| {
            let dy = (v - c).normalize().y.abs();
            let to_border = border
                .iter()
                .map(|b| (v - b).norm())
                .fold(f64::INFINITY, f64::min);
            smoothstep(0.4, 0.6, dy) * smoothstep(2.0, 5.0, to_border)
        })
        .collect()
}

fn twin(truth: &Mesh, c: &Point3<f64>, w: &[f64], delta: f64) -> Mesh {
    let moved = truth
        .vertices
        .iter()
        .zip(w)
        .map(|(v, wi)| v + (v - c).normalize() * (delta * wi))
        .collect();
    truth.with_vertices(moved)
}

/// Symmetric Hausdorff distance between two closed outlines, pixels (closest points on the
/// other polyline by `icp_matches`, the ICP baseline's rule).
fn hausdorff(a: &[Point2<f64>], b: &[Point2<f64>]) -> f64 {
    let one = |x: &[Point2<f64>], y: &[Point2<f64>]| {
        x.iter()
            .zip(icp_matches(x, true, y))
            .map(|(p, m)| m.map_or(f64::INFINITY, |(q, _)| (p - q).norm()))
            .fold(0.0, f64::max)
    };
    one(a, b).max(one(b, a))
}

fn study(p: &str, delta: f64, write: Option<&Path>) -> Result<String, String> {
    let raw = if p == "phantom" {
        phantom(&PhantomParams::default()).mesh
    } else {
        read_mesh(Path::new(p)).map_err(|e| e.to_string())?
    };
    let truth = ground_truth_surface(&raw).map_err(|e| e.to_string())?;
    let setup = SimSetup::new(&truth, &XrayGeometry::default()).map_err(|e| e.to_string())?;
    let c = setup.sphere.center_point();
    let w = wall_weights(&truth, &c);
    let samples = accuracy_samples(&truth);
    let name = Path::new(p)
        .file_stem()
        .map_or(p.to_string(), |s| s.to_string_lossy().into());
    let mut cells = Vec::new();
    let mut twins = Vec::new();
    for (tag, d) in [("plus", delta), ("minus", -delta)] {
        let t = twin(&truth, &c, &w, d);
        let mut worst = 0.0f64;
        for (cam, outline) in setup.cameras.iter().zip(&setup.outlines) {
            let alpha = observed_alpha(&truth, cam, &setup.placement);
            let tc = model_contour(&t, cam, Some(alpha)).map_err(|e| e.to_string())?;
            worst = worst.max(hausdorff(&tc.points, outline));
        }
        let dia = fit_placement(&t).map_err(|e| e.to_string())?.1.diameter();
        let mae = accuracy_from(&samples, &t).mae_mm;
        cells.push(format!(
            "{tag}: outlines within {worst:.2} px, cup {dia:.2} mm ({:+.2}), MAE from truth {mae:.2} mm",
            dia - setup.sphere.diameter()
        ));
        if let Some(dir) = write {
            let path: PathBuf = dir.join(format!("{name}_{tag}.obj"));
            write_obj(&t, &path).map_err(|e| e.to_string())?;
        }
        twins.push((t, dia));
    }
    let gap = (twins[0].1 - twins[1].1).abs();
    let between = accuracy_from(&accuracy_samples(&twins[0].0), &twins[1].0).mae_mm;
    let moved = w.iter().filter(|x| **x > 0.5).count() as f64 / w.len() as f64;
    Ok(format!(
        "{name}: truth cup {:.2} mm, {:.0} % of vertices in the unseen walls | {} | twins' cups {gap:.2} mm apart, {between:.2} mm apart (MAE)",
        setup.sphere.diameter(),
        100.0 * moved,
        cells.join(" | ")
    ))
}

fn main() -> ExitCode {
    let usage = "usage: unseen_walls [--delta MM] [--write DIR] MESH|phantom...";
    let mut delta = 1.0;
    let mut write: Option<PathBuf> = None;
    let mut paths = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let ok = match a.as_str() {
            "--delta" => args
                .next()
                .and_then(|v| v.parse::<f64>().ok().filter(|d| d.is_finite() && *d > 0.0))
                .map(|d| delta = d),
            "--write" => args.next().map(|d| write = Some(PathBuf::from(d))),
            _ => {
                paths.push(a);
                Some(())
            }
        };
        if ok.is_none() {
            eprintln!("{usage}");
            return ExitCode::from(2);
        }
    }
    if paths.is_empty() {
        eprintln!("{usage}");
        return ExitCode::from(2);
    }
    for p in &paths {
        match study(p, delta, write.as_deref()) {
            Ok(line) => println!("{line}"),
            Err(e) => {
                eprintln!("{p}: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}
