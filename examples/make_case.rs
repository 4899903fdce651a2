//! Writes the example case in examples/case/: three simulated X-ray-like images of the built-in
//! phantom (grey levels from how many surface layers each ray crosses, blurred), the annotated
//! rim contours (two closed, one open where the blurred wall is left out), the cameras and a
//! perturbed template placement. Seeded (seed 1), so the files are reproducible.
//!
//! With `--dicom` the images are Digital X-Ray DICOM files (12-bit, Deflated Explicit VR Little
//! Endian) carrying the pixel spacing and the source distances, and the case file leaves out `k`
//! and the image size: they are read from the tags (examples/case-dicom/).
//!
//! Run: cargo run --release --example make_case [-- OUT_DIR] [--dicom]

use acetab::case::CaseFile;
use acetab::engine::cpu::project::{project, ViewRows};
use acetab::engine::cpu::silhouette::for_each_covered;
use acetab::geom::Curve;
use acetab::io::{write_dicom_xray, DicomXray, SpacingTag};
use acetab::sim::XrayGeometry;
use acetab::sim::{phantom, PhantomParams};
use acetab::sim::{simulate_case, NoiseLevel};
use std::path::PathBuf;
use std::process::ExitCode;

/// How many triangles of the mesh cover each pixel (a crude line integral through the surface).
fn layers(proj: &[[f32; 4]], tris: &[[u32; 3]], w: usize, h: usize) -> Vec<f32> {
    let mut acc = vec![0f32; w * h];
    for t in tris {
        let c = t.map(|i| [proj[i as usize][0], proj[i as usize][1]]);
        for_each_covered(c, w, h, |x, y, _| acc[y * w + x] += 1.0);
    }
    acc
}

/// Separable box blur of radius r.
fn blur(v: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        let mut out = vec![0f32; src.len()];
        for a in 0..(if horizontal { h } else { w }) {
            for b in 0..(if horizontal { w } else { h }) {
                let (mut s, mut n) = (0f32, 0f32);
                for d in b.saturating_sub(r)..(b + r + 1).min(if horizontal { w } else { h }) {
                    s += if horizontal {
                        src[a * w + d]
                    } else {
                        src[d * w + a]
                    };
                    n += 1.0;
                }
                let at = if horizontal { a * w + b } else { b * w + a };
                out[at] = s / n;
            }
        }
        out
    };
    pass(&pass(v, true), false)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dicom = args.iter().any(|a| a == "--dicom");
    let out: PathBuf = args
        .iter()
        .find(|a| !a.starts_with("--"))
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            if dicom {
                "examples/case-dicom"
            } else {
                "examples/case"
            }
            .into()
        });
    let geometry = XrayGeometry::default();
    let run = || -> Result<(), String> {
        std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
        let truth = phantom(&PhantomParams::default()).mesh;
        let sim = simulate_case(
            &truth,
            &geometry,
            2.0,
            &NoiseLevel::level(2).ok_or("level")?,
            1,
        )
        .map_err(|e| e.to_string())?;
        let verts: Vec<[f32; 4]> = truth
            .vertices
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.0])
            .collect();
        let mut observed: Vec<Vec<Curve>> = sim.observed.clone();
        // The third view's annotator left out a quarter of the rim where the wall is blurred.
        if let Some(c) = observed.get_mut(2).and_then(|v| v.first_mut()) {
            let keep = c.points.len() * 3 / 4;
            c.points.truncate(keep);
            c.closed = false;
        }
        let mut file = CaseFile::from_parts(&sim.cameras, &observed, &sim.init);
        for (k, cam) in sim.cameras.iter().enumerate() {
            let (w, h) = (cam.width as usize, cam.height as usize);
            let proj = project(&verts, verts.len(), &[ViewRows::from_camera(cam)]);
            let acc = blur(&layers(&proj, &truth.triangles, w, h), w, h, 4);
            let img = image::GrayImage::from_fn(w as u32, h as u32, |x, y| {
                // Soft tissue background with a vertical gradient, bone brighter.
                let bg = 50.0 + 30.0 * (y as f32 / h as f32);
                image::Luma([(bg + 70.0 * acc[y as usize * w + x as usize]).min(255.0) as u8])
            });
            let view = ["AP", "oblique +20", "oblique -20"]
                .get(k)
                .unwrap_or(&"view")
                .to_string();
            let name = if dicom {
                let name = format!("view{k}.dcm");
                let x = DicomXray {
                    columns: w as u32,
                    rows: h as u32,
                    // 8-bit grey to 12 bits.
                    pixels: img.pixels().map(|p| u16::from(p.0[0]) * 16).collect(),
                    spacing: Some((
                        [geometry.pixel_size, geometry.pixel_size],
                        SpacingTag::Imager,
                    )),
                    sid_mm: Some(geometry.source_to_detector),
                    sod_mm: Some(geometry.source_to_object),
                    view: view.clone(),
                    uid_seed: 1 + k as u64,
                };
                write_dicom_xray(&out.join(&name), &x).map_err(|e| e.to_string())?;
                // The intrinsics and the size come from the tags.
                file.views[k].k = None;
                file.views[k].width = None;
                file.views[k].height = None;
                name
            } else {
                let name = format!("view{k}.png");
                img.save(out.join(&name))
                    .map_err(|e| format!("{name}: {e}"))?;
                name
            };
            file.views[k].image = Some(PathBuf::from(&name));
            file.views[k].name = Some(view);
        }
        let text = serde_json::to_string_pretty(&file).map_err(|e| e.to_string())?;
        std::fs::write(out.join("case.json"), text).map_err(|e| e.to_string())?;
        println!(
            "wrote {}/case.json and view0..2.{} (seed 1)",
            out.display(),
            if dicom { "dcm" } else { "png" }
        );
        Ok(())
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("make_case: {e}");
            ExitCode::FAILURE
        }
    }
}
