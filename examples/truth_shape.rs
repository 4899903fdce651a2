//! How far a ground-truth acetabulum is from its fitted sphere, by how directly each part faces
//! the simulated AP view (|radial direction . y|, y pointing at the AP source): the views of the
//! study all turn about z, so the parts facing them (the front and back walls, |d.y| near 1)
//! never form an outline, and a sphere from the outlines sees only the belt near |d.y| = 0.
//!
//! Run: cargo run --release --example truth_shape -- MESH...   (STL/PLY/OBJ, or `phantom` for the
//! built-in phantom; closed shells are reduced to their outer side as in `acetab simulate`)

use acetab::io::read_mesh;
use acetab::sim::XrayGeometry;
use acetab::sim::{fit_placement, ground_truth_surface, SimSetup};
use acetab::sim::{phantom, PhantomParams};
use std::path::Path;
use std::process::ExitCode;

fn main() -> ExitCode {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.is_empty() {
        eprintln!("usage: truth_shape MESH...");
        return ExitCode::from(2);
    }
    println!("mesh: sphere diameter | mean radial deviation (mm) by |d.y| in [0,0.2) .. [0.8,1] | rim | outline-vertex sphere - truth sphere");
    for p in &paths {
        let raw = if p == "phantom" {
            Ok(phantom(&PhantomParams::default()).mesh)
        } else {
            read_mesh(Path::new(p)).map_err(|e| e.to_string())
        };
        let truth = match raw.and_then(|m| ground_truth_surface(&m).map_err(|e| e.to_string())) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("{p}: {e}");
                return ExitCode::FAILURE;
            }
        };
        let (placement, sphere) = match fit_placement(&truth) {
            Ok(ps) => ps,
            Err(e) => {
                eprintln!("{p}: sphere fit: {e}");
                return ExitCode::FAILURE;
            }
        };
        let c = sphere.center_point();
        let mut bands = [(0.0f64, 0usize); 5];
        for v in &truth.vertices {
            let d = v - c;
            let b = ((d.normalize().y.abs() / 0.2) as usize).min(4);
            bands[b].0 += d.norm() - sphere.radius;
            bands[b].1 += 1;
        }
        let name = Path::new(p)
            .file_stem()
            .map_or(p.clone(), |s| s.to_string_lossy().into());
        let cells: Vec<String> = bands
            .iter()
            .map(|(s, n)| {
                if *n > 0 {
                    format!("{:+.2} ({n})", s / *n as f64)
                } else {
                    "-".into()
                }
            })
            .collect();
        // The oracle: the sphere through the truth's own vertices that form the three views'
        // outlines (as the study's annotation traces them), which is the most a sphere read from
        // the outlines can know (`SimSetup::outline_sphere`).
        let oracle = SimSetup::new(&truth, &XrayGeometry::default())
            .map_err(|e| e.to_string())
            .and_then(|setup| {
                setup
                    .outline_sphere(&truth)
                    .map(|s| (s.diameter(), setup.outline_vertices.len()))
                    .map_err(|e| e.to_string())
            });
        let oracle = match oracle {
            Ok((d, n)) => format!("{:+.2} mm ({n} vertices)", d - sphere.diameter()),
            Err(e) => format!("- ({e})"),
        };
        // The rim: border vertices more than 60 degrees from the pole (the inner border around
        // the fossa is nearer the pole), their mean radial offset from the sphere.
        let pole = -placement.axis.into_inner();
        let mut border: Vec<u32> = truth.boundary_edges().into_iter().flatten().collect();
        border.sort_unstable();
        border.dedup();
        let rim: Vec<f64> = border
            .iter()
            .map(|&i| truth.vertices[i as usize] - c)
            .filter(|d| d.normalize().dot(&pole) < 60f64.to_radians().cos())
            .map(|d| d.norm() - sphere.radius)
            .collect();
        let rim = if rim.is_empty() {
            "-".to_string()
        } else {
            format!(
                "{:+.2} mm ({})",
                rim.iter().sum::<f64>() / rim.len() as f64,
                rim.len()
            )
        };
        println!(
            "{name}: {:.2} mm | {} | rim {rim} | outline-vertex sphere {oracle}",
            sphere.diameter(),
            cells.join("  ")
        );
    }
    ExitCode::SUCCESS
}
