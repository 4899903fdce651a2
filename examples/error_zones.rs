//! Where a reconstruction's error sits, by how directly each part of the truth faces the AP view
//! (|radial direction . y| from the truth's sphere centre, the bands of `truth_shape`). The study's
//! views all turn about z, so only the belt near |d.y| = 0 forms outlines; elsewhere the surface
//! is what the deformation graph and its sphere prior make of it.
//!
//! For each mesh, seeded `srvf` study runs (seed 1, the study's cases) are reconstructed and
//! the points `mae_mm` is measured from (20,000 spread evenly over the truth) are matched to their
//! closest points on the result.
//! Per band: the mean signed offset (positive: the truth lies outside the result, away from the
//! truth's sphere centre) and the band's share of the mean absolute distance (`mae_mm`).
//!
//! Run: cargo run --release --example error_zones -- [--levels 1,3,5] [--runs 4] MESH...

use acetab::engine::Kernels;
use acetab::io::read_mesh;
use acetab::report::accuracy_samples;
use acetab::report::SurfaceQuery;
use acetab::sim::{fit_placement, ground_truth_surface};
use acetab::study::{run_one, tasks, StudyConfig, StudyMethod};
use std::path::Path;
use std::process::ExitCode;

const BANDS: usize = 5;

fn main() -> ExitCode {
    let mut levels = vec![1, 3, 5];
    let mut runs = 4;
    let mut paths = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let parsed = match a.as_str() {
            "--levels" => args.next().and_then(|v| {
                v.split(',')
                    .map(|x| x.parse().ok().filter(|l| (1..=5).contains(l)))
                    .collect::<Option<Vec<u32>>>()
                    .map(|l| levels = l)
            }),
            "--runs" => args
                .next()
                .and_then(|v| v.parse().ok().filter(|&r| r >= 1))
                .map(|r| runs = r),
            _ => {
                paths.push(a);
                Some(())
            }
        };
        if parsed.is_none() {
            eprintln!("usage: error_zones [--levels 1,3,5] [--runs 4] MESH...");
            return ExitCode::from(2);
        }
    }
    if paths.is_empty() {
        eprintln!("usage: error_zones [--levels 1,3,5] [--runs 4] MESH...");
        return ExitCode::from(2);
    }
    println!(
        "mesh: runs, mae | per |d.y| band [0,0.2) .. [0.8,1]: mean signed offset mm (share of mae)"
    );
    for p in &paths {
        match zones(p, &levels, runs) {
            Ok(line) => println!("{line}"),
            Err(e) => {
                eprintln!("{p}: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}

fn zones(path: &str, levels: &[u32], runs: usize) -> Result<String, String> {
    let mesh = read_mesh(Path::new(path)).map_err(|e| e.to_string())?;
    let truth = ground_truth_surface(&mesh).map_err(|e| e.to_string())?;
    let centre = fit_placement(&truth)
        .map_err(|e| format!("sphere fit: {e}"))?
        .1
        .center_point();
    let samples = accuracy_samples(&truth);
    let band_of: Vec<usize> = samples
        .iter()
        .map(|s| (((s - centre).normalize().y.abs() / 0.2) as usize).min(BANDS - 1))
        .collect();
    let cfg = StudyConfig {
        levels: levels.to_vec(),
        runs,
        methods: vec![StudyMethod::Srvf],
        ..Default::default()
    };
    let mut signed = [0.0f64; BANDS];
    let mut absolute = [0.0f64; BANDS];
    let mut count = [0usize; BANDS];
    let mut done = 0;
    for task in tasks(&cfg) {
        let (row, run) = run_one(&truth, &task, &cfg, Kernels::Cpu);
        let Some(run) = run else {
            return Err(format!(
                "level {} run {}: {}",
                task.level, task.run, row.error
            ));
        };
        let query = SurfaceQuery::new(&run.recon.mesh).ok_or("empty reconstruction")?;
        for (s, &b) in samples.iter().zip(&band_of) {
            let q = query.closest_point(s);
            let d = (s - q).norm();
            let outside = (s - centre).norm() >= (q - centre).norm();
            signed[b] += if outside { d } else { -d };
            absolute[b] += d;
            count[b] += 1;
        }
        done += 1;
    }
    let total: f64 = absolute.iter().sum();
    let n_all: usize = count.iter().sum();
    let cells: Vec<String> = (0..BANDS)
        .map(|b| {
            if count[b] == 0 {
                "-".into()
            } else {
                format!(
                    "{:+.2} ({:.0} %)",
                    signed[b] / count[b] as f64,
                    100.0 * absolute[b] / total.max(1e-300)
                )
            }
        })
        .collect();
    let name = Path::new(path)
        .file_stem()
        .map_or(path.to_string(), |s| s.to_string_lossy().into());
    Ok(format!(
        "{name}: {done}, {:.3} mm | {}",
        total / n_all.max(1) as f64,
        cells.join("  ")
    ))
}
