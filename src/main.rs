//! The `acetab` command line: parses arguments and calls the library.

use acetab::backend::{BackendChoice, ContourSource, Kernels};
use acetab::case_run::run_case;
use acetab::contours::read_curve_csv;
use acetab::correspond::srvf::{align, aligned_b, CurveKind, SrvfParams, MAX_SAMPLES, MIN_SAMPLES};
use acetab::correspond::Method;
use acetab::demo::{run_demo_with, write_error_ply};
use acetab::fsutil::fill_dir_atomically;
use acetab::gpu::{GpuBatcher, GpuDevice};
use acetab::mesh::io::read_mesh;
use acetab::mesh::io::write_ply;
use acetab::pipeline::ReconParams;
use acetab::report::{fit_sphere, CupCatalogue};
use acetab::simulate::ground_truth_surface;
use acetab::study::{
    merge_dirs, merge_meta, run_study_with, summarize, tasks, write_examples, write_tables,
    StudyConfig, StudyMethod,
};
use acetab::template::{phantom, PhantomParams};
use acetab::uncertainty::UncertaintyParams;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "acetab",
    version,
    about = "Acetabular surface reconstruction from pelvic X-rays and cup sizing"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate three X-rays of the built-in phantom, reconstruct, and report accuracy.
    Demo {
        /// Print one JSON object instead of the text summary.
        #[arg(long)]
        json: bool,
        /// Seed of every random draw (contour noise and initial pose).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Initialisation noise level 0..5.
        #[arg(long, default_value_t = 3)]
        level: u32,
        #[arg(long, value_enum, default_value_t = Method::Srvf)]
        method: Method,
        /// Where the kernels run: cpu, gpu, or auto (the GPU when an adapter exists).
        #[arg(long, value_enum, default_value_t = BackendChoice::Cpu)]
        backend: BackendChoice,
        /// Model contours from alpha shapes or rasterised silhouettes.
        #[arg(long, value_enum, default_value_t = ContourSource::AlphaShape)]
        contours: ContourSource,
        /// Output folder.
        #[arg(long, default_value = "acetab-out")]
        out: PathBuf,
    },
    /// The simulation study: levels x runs x methods on a ground-truth surface.
    Simulate {
        /// Ground truth: a mesh file (STL/PLY/OBJ; a closed shell is reduced to its outer side)
        /// or "phantom".
        #[arg(long)]
        gt: String,
        #[arg(long, default_value = "1,2,3,4,5")]
        levels: String,
        #[arg(long, default_value_t = 10)]
        runs: usize,
        /// Methods: srvf, icp, icp-normvec (every stage of ours, each on its own
        /// correspondences), and srvf-paper, icp-paper, icp-normvec-paper (the seed paper's
        /// protocol: the deformation alone, from the perturbed template).
        #[arg(long, default_value = "srvf,icp,icp-normvec")]
        methods: String,
        /// Study seed; each run's seed is derived from it, the level and the run number.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads (default: all cores). Results do not depend on it.
        #[arg(long)]
        threads: Option<usize>,
        /// Run only shard I of N (0 <= I < N), for job arrays; join with `acetab merge`.
        #[arg(long, default_value = "0/1")]
        shard: String,
        /// Where the kernels run: cpu, gpu, or auto (the GPU when an adapter exists).
        #[arg(long, value_enum, default_value_t = BackendChoice::Cpu)]
        backend: BackendChoice,
        /// Model contours from alpha shapes or rasterised silhouettes.
        #[arg(long, value_enum, default_value_t = ContourSource::AlphaShape)]
        contours: ContourSource,
        /// ED energy weights w_rot, w_reg, w_obs (defaults: the published 1, 10, 100).
        #[arg(long, default_value_t = 1.0)]
        w_rot: f64,
        #[arg(long, default_value_t = 10.0)]
        w_reg: f64,
        #[arg(long, default_value_t = 100.0)]
        w_obs: f64,
        /// Coarse-to-fine deformation: a graph of this many nodes in every correspondence round
        /// but the last (default: the full graph throughout; see README).
        #[arg(long)]
        coarse_nodes: Option<usize>,
        #[arg(long)]
        out: PathBuf,
    },
    /// Join the runs of several `acetab simulate --shard` folders.
    Merge {
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        #[arg(long)]
        out: PathBuf,
    },
    /// SRVF elastic alignment of two curves (CSV files of x,y; header optional).
    Align {
        a: PathBuf,
        b: PathBuf,
        /// Both curves closed (default).
        #[arg(long, conflicts_with_all = ["open", "partial"])]
        closed: bool,
        /// Both open, ends corresponding.
        #[arg(long, conflicts_with = "partial")]
        open: bool,
        /// A is an open arc matched against the best sub-arc of the closed curve B.
        #[arg(long)]
        partial: bool,
        /// Arc-length samples per curve.
        #[arg(long, default_value_t = 200)]
        samples: usize,
        #[arg(long)]
        json: bool,
    },
    /// Each GPU kernel against its CPU twin at several sizes, and the study's throughput on both
    /// backends (needs a GPU adapter; lavapipe counts).
    Bench {
        #[arg(long)]
        json: bool,
        /// Study runs per backend (0 skips the study).
        #[arg(long, default_value_t = 6)]
        study_runs: usize,
        /// Repetitions per timing (the median is reported).
        #[arg(long, default_value_t = 5)]
        repeats: usize,
        /// A quick pass (one small mesh, DP batches of 1 and 4): checks the bench runs, not speed.
        #[arg(long)]
        quick: bool,
    },
    /// Pose refinement in simulation: cases whose oblique views' poses are off by --deg and
    /// --mm, reconstructed with and without the per-view pose refinement.
    PoseStudy {
        /// Ground truth mesh or "phantom".
        #[arg(long, default_value = "phantom")]
        gt: String,
        #[arg(long, default_value_t = 10)]
        runs: usize,
        #[arg(long, default_value_t = 2.0)]
        deg: f64,
        #[arg(long, default_value_t = 5.0)]
        mm: f64,
        /// Initialisation noise level 1..5.
        #[arg(long, default_value_t = 1)]
        level: u32,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long)]
        threads: Option<usize>,
        #[arg(long)]
        json: bool,
    },
    /// Reconstruct a case file.
    Reconstruct {
        case: PathBuf,
        #[arg(long)]
        out: PathBuf,
        #[arg(long, value_enum, default_value_t = Method::Srvf)]
        method: Method,
        /// Cup catalogue: "min:max:step" or a list "44,46,48".
        #[arg(long, default_value = "40:70:2")]
        catalogue: String,
        /// Refine small per-view pose corrections with the deformation (prior SD 2 deg, 5 mm;
        /// the first view fixes the frame).
        #[arg(long)]
        refine_poses: bool,
        /// Resamples for the cup size's uncertainty (contour noise + bootstrap weights).
        #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u64).range(1..=1000))]
        uncertainty_samples: u64,
        /// Seed of the resampling draws.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Where the kernels run: cpu, gpu, or auto (the GPU when an adapter exists).
        #[arg(long, value_enum, default_value_t = BackendChoice::Cpu)]
        backend: BackendChoice,
        /// Model contours from alpha shapes or rasterised silhouettes.
        #[arg(long, value_enum, default_value_t = ContourSource::AlphaShape)]
        contours: ContourSource,
        #[arg(long)]
        json: bool,
    },
}

/// The device for `--backend`: none for cpu; for auto, none (with one line saying so) when no
/// adapter can be had.
fn open_device(choice: BackendChoice) -> Result<Option<GpuDevice>, String> {
    match choice {
        BackendChoice::Cpu => Ok(None),
        BackendChoice::Gpu => GpuDevice::from_env()
            .map(Some)
            .map_err(|e| format!("--backend gpu: {e}")),
        BackendChoice::Auto => match GpuDevice::from_env() {
            Ok(d) => Ok(Some(d)),
            Err(e) => {
                eprintln!("--backend auto: {e}; running on the CPU");
                Ok(None)
            }
        },
    }
}

/// An I/O error on an output path, for `fill_dir_atomically`.
fn io_msg(p: &Path, e: std::io::Error) -> String {
    format!("{}: cannot write: {e}", p.display())
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.command {
        Command::Demo {
            json,
            seed,
            level,
            method,
            backend,
            contours,
            out,
        } => {
            let prm = ReconParams {
                method,
                contour_source: contours,
                ..Default::default()
            };
            let dev = open_device(backend)?;
            let engine = engine_on(&dev)?;
            let kernels = engine.as_ref().map_or(Kernels::Cpu, Kernels::Gpu);
            let (report, truth, rec) =
                run_demo_with(seed, level, &prm, kernels).map_err(|e| e.to_string())?;
            let report_json = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
            fill_dir_atomically(
                &out,
                |d| {
                    write_error_ply(&rec.mesh, &truth, &d.join("reconstruction.ply"))
                        .map_err(|e| e.to_string())?;
                    write_ply(&truth, None, &d.join("truth.ply")).map_err(|e| e.to_string())?;
                    std::fs::write(d.join("report.json"), report_json.as_bytes())
                        .map_err(|e| format!("{}: {e}", d.display()))
                },
                io_msg,
            )?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string(&report).map_err(|e| e.to_string())?
                );
            } else {
                println!("acetab demo: phantom, 3 views, 2 px contour noise, level {level} start, seed {seed}, method {}", method.name());
                println!(
                    "  MAE  {:.3} mm   SD {:.3} mm   p95 {:.3} mm   (start: MAE {:.2} mm)",
                    report.mae_mm, report.sd_mm, report.p95_mm, report.initial_mae_mm
                );
                println!(
                    "  cup  {:.2} mm (catalogue {:.0} mm)   truth {:.2} mm   error {:+.2} mm",
                    report.cup_diameter_mm,
                    report.cup_catalogue_mm,
                    report.gt_cup_diameter_mm,
                    report.cup_error_mm
                );
                println!(
                    "  {:.2} s   {} GN iterations   outputs in {}",
                    report.seconds,
                    report.log.gn_iterations,
                    out.display()
                );
            }
            Ok(())
        }
        Command::Simulate {
            gt,
            levels,
            runs,
            methods,
            seed,
            threads,
            shard,
            backend,
            contours,
            w_rot,
            w_reg,
            w_obs,
            coarse_nodes,
            out,
        } => {
            let full_graph = acetab::solve::GraphParams::default().nodes;
            if let Some(n) = coarse_nodes {
                within("--coarse-nodes", n, 2, full_graph)?;
            }
            within("--runs", runs, 1, MAX_RUNS)?;
            for (flag, w) in [("--w-rot", w_rot), ("--w-reg", w_reg), ("--w-obs", w_obs)] {
                if !(w.is_finite() && w >= 0.0) {
                    return Err(format!("{flag} {w}: must be a finite non-negative weight"));
                }
            }
            let method_names = StudyMethod::ALL.map(StudyMethod::name).join(", ");
            let cfg = StudyConfig {
                levels: parse_list(&levels, "--levels", "levels 1 to 5", |x| {
                    x.parse::<u32>().ok().filter(|l| (1..=5).contains(l))
                })?,
                runs,
                methods: parse_list(&methods, "--methods", &method_names, |x| {
                    StudyMethod::from_name(&x.to_ascii_lowercase())
                })?,
                seed,
                threads: threads_or_all(threads)?,
                shard: parse_shard(&shard)?,
                params: ReconParams {
                    contour_source: contours,
                    weights: acetab::solve::EdWeights {
                        rot: w_rot,
                        reg: w_reg,
                        obs: w_obs,
                        ..Default::default()
                    },
                    coarse_graph_nodes: coarse_nodes,
                    ..Default::default()
                },
                ..Default::default()
            };
            let truth = load_truth(&gt)?;
            let total = tasks(&cfg).len();
            let bar = ProgressBar::new(total as u64);
            bar.set_style(
                ProgressStyle::with_template(
                    "{bar:40} {pos}/{len} runs, {elapsed} elapsed, ~{eta} left",
                )
                .map_err(|e| e.to_string())?,
            );
            let start = std::time::Instant::now();
            let dev = open_device(backend)?;
            let engine = engine_on(&dev)?;
            // On the GPU, runs in flight together share dispatches (one submit per kernel).
            let batcher = engine
                .as_ref()
                .map(|g| GpuBatcher::new(g, cfg.threads, std::time::Duration::from_millis(2)));
            let kernels = batcher.as_ref().map_or(Kernels::Cpu, Kernels::Batched);
            let (rows, examples) = run_study_with(&truth, &cfg, &|| bar.inc(1), kernels)
                .map_err(|e| format!("--gt {gt}: {e}"))?;
            if let Some(b) = &batcher {
                let (req, disp) = b.counts();
                eprintln!(
                    "GPU: {req} kernel requests in {disp} dispatches ({:.2} runs per submit)",
                    req as f64 / disp.max(1) as f64
                );
            }
            bar.finish_and_clear();
            // A study in which every run failed (a solver diverging for want of regularisation,
            // say) has no result to write: it is an error, not a folder of NaN with exit 0.
            if !rows.is_empty() && rows.iter().all(|r| !r.error.is_empty()) {
                return Err(format!(
                    "simulate: all {} runs failed, nothing written (the first, {} level {} run {}: {})",
                    rows.len(),
                    rows[0].method.name(),
                    rows[0].level,
                    rows[0].run,
                    rows[0].error
                ));
            }
            let meta = serde_json::json!({
                "gt": gt, "levels": cfg.levels, "runs": runs, "methods": cfg.methods, "seed": seed,
                "shard": shard, "contour_noise_px": cfg.noise_px, "seconds": start.elapsed().as_secs_f64(),
                "contours": format!("{:?}", cfg.params.contour_source),
                "w_rot": cfg.params.weights.rot, "w_reg": cfg.params.weights.reg,
                "w_obs": cfg.params.weights.obs, "coarse_nodes": cfg.params.coarse_graph_nodes,
            });
            fill_dir_atomically(
                &out,
                |d| {
                    write_tables(&rows, d, &meta).map_err(|e| e.to_string())?;
                    write_examples(&examples, &truth, d).map_err(|e| e.to_string())
                },
                io_msg,
            )?;
            eprintln!(
                "{} runs in {:.1} s (seed {seed}); results in {}",
                rows.len(),
                start.elapsed().as_secs_f64(),
                out.display()
            );
            print_summary(&rows);
            Ok(())
        }
        Command::Align {
            a,
            b,
            closed: _,
            open,
            partial,
            samples,
            json,
        } => {
            let kind = if open {
                CurveKind::Open
            } else if partial {
                CurveKind::Partial
            } else {
                CurveKind::Closed
            };
            if !(MIN_SAMPLES..=MAX_SAMPLES).contains(&samples) {
                return Err(format!(
                    "--samples {samples}: must be {MIN_SAMPLES} to {MAX_SAMPLES}"
                ));
            }
            let ca = read_curve_csv(&a).map_err(|e| e.to_string())?;
            let cb = read_curve_csv(&b).map_err(|e| e.to_string())?;
            let prm = SrvfParams {
                samples,
                ..Default::default()
            };
            let t = std::time::Instant::now();
            let al = align(&ca, &cb, kind, &prm)
                .map_err(|e| format!("{} / {}: {e}", a.display(), b.display()))?;
            let seconds = t.elapsed().as_secs_f64();
            if json {
                let v = serde_json::json!({
                    "distance": al.distance,
                    "rotation_deg": al.rotation.to_degrees(),
                    "seed": al.seed,
                    "reversed": al.reversed,
                    "samples": samples,
                    "gamma": al.gamma,
                    "seconds": seconds,
                    "aligned": aligned_b(&al).iter().map(|p| [p.x, p.y]).collect::<Vec<_>>(),
                });
                println!("{v}");
            } else {
                println!(
                    "distance {:.6}  rotation {:.3} deg  seed {}{}  {:.2} ms",
                    al.distance,
                    al.rotation.to_degrees(),
                    al.seed,
                    if al.reversed { "  (A reversed)" } else { "" },
                    seconds * 1e3
                );
            }
            Ok(())
        }
        Command::Merge { dirs, out } => {
            // Merging into one of the shards would overwrite the shard's own tables.
            let same = |d: &PathBuf| match (d.canonicalize(), out.canonicalize()) {
                (Ok(a), Ok(b)) => a == b,
                _ => false,
            };
            if let Some(d) = dirs.iter().find(|d| same(d)) {
                return Err(format!(
                    "--out {}: is the shard folder {} being merged; choose another folder",
                    out.display(),
                    d.display()
                ));
            }
            let rows = merge_dirs(&dirs).map_err(|e| e.to_string())?;
            let meta = merge_meta(&dirs).map_err(|e| e.to_string())?;
            fill_dir_atomically(
                &out,
                |d| write_tables(&rows, d, &meta).map_err(|e| e.to_string()),
                io_msg,
            )?;
            eprintln!("{} runs merged into {}", rows.len(), out.display());
            print_summary(&rows);
            Ok(())
        }
        Command::Bench {
            json,
            study_runs,
            repeats,
            quick,
        } => {
            within("--study-runs", study_runs, 0, MAX_RUNS)?;
            within("--repeats", repeats, 1, 1000)?;
            let dev = GpuDevice::from_env().map_err(|e| format!("acetab bench: {e}"))?;
            let gpu = dev.engine().map_err(|e| e.to_string())?;
            let mut prm = acetab::bench::BenchParams {
                study_runs,
                repeats,
                ..Default::default()
            };
            if quick {
                prm.mesh_sizes = vec![500];
                prm.dp_batches = vec![1, 4];
            }
            let report = acetab::bench::run_bench(&gpu, &dev.describe(), &prm, &|s| {
                if !json {
                    eprintln!("  measured {s}")
                }
            })
            .map_err(|e| e.to_string())?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string(&report).map_err(|e| e.to_string())?
                );
            } else {
                println!("adapter: {}", report.adapter);
                println!(
                    "{:<11} {:<30} {:>10} {:>10} {:>8}",
                    "kernel", "size", "cpu ms", "gpu ms", "cpu/gpu"
                );
                for r in &report.kernels {
                    println!(
                        "{:<11} {:<30} {:>10.3} {:>10.3} {:>8.2}",
                        r.kernel, r.size, r.cpu_ms, r.gpu_ms, r.ratio
                    );
                }
                for s in &report.study {
                    println!(
                        "study ({} runs, phantom, srvf, level 3) on {}: {:.2} runs/s ({:.1} s)",
                        s.runs, s.backend, s.runs_per_second, s.seconds
                    );
                }
            }
            Ok(())
        }
        Command::PoseStudy {
            gt,
            runs,
            deg,
            mm,
            level,
            seed,
            threads,
            json,
        } => {
            if !(deg.is_finite() && mm.is_finite() && deg >= 0.0 && mm >= 0.0) {
                return Err(format!(
                    "--deg {deg} / --mm {mm}: must be finite and non-negative"
                ));
            }
            within("--runs", runs, 1, MAX_RUNS)?;
            within("--level", level as usize, 1, 5)?;
            let truth = load_truth(&gt)?;
            let cfg = acetab::study::pose::PoseStudy {
                runs,
                seed,
                level,
                deg,
                mm,
                threads: threads_or_all(threads)?,
                ..Default::default()
            };
            let t = std::time::Instant::now();
            let rows = acetab::study::pose::run_pose_study(&truth, &cfg)
                .map_err(|e| format!("--gt {gt}: {e}"))?;
            let ok: Vec<_> = rows.iter().filter(|r| r.error.is_empty()).collect();
            if ok.is_empty() {
                return Err(format!(
                    "pose-study: all {} runs failed (run 0: {})",
                    rows.len(),
                    rows.first().map_or("", |r| r.error.as_str())
                ));
            }
            let mean = |f: &dyn Fn(&acetab::study::pose::PoseRow) -> f64| {
                ok.iter().map(|r| f(r)).sum::<f64>() / ok.len() as f64
            };
            let (without, with) = (mean(&|r| r.mae_without_mm), mean(&|r| r.mae_with_mm));
            let summary = serde_json::json!({
                "gt": gt, "runs": runs, "deg": deg, "mm": mm, "level": level, "seed": seed,
                "reference_view": cfg.pose.reference_view,
                "mae_without_mm": without, "mae_with_mm": with,
                "reduction": 1.0 - with / without,
                "cup_abs_error_without_mm": mean(&|r| r.cup_error_without_mm.abs()),
                "cup_abs_error_with_mm": mean(&|r| r.cup_error_with_mm.abs()),
                "failed": rows.len() - ok.len(),
                "seconds": t.elapsed().as_secs_f64(),
                "rows": rows,
            });
            if json {
                println!(
                    "{}",
                    serde_json::to_string(&summary).map_err(|e| e.to_string())?
                );
            } else {
                println!("run  seed                  MAE without  MAE with  cup err without  cup err with");
                for r in &rows {
                    println!(
                        "{:>3}  {:<20}  {:>11.3}  {:>8.3}  {:>15.2}  {:>12.2}  {}",
                        r.run,
                        r.seed,
                        r.mae_without_mm,
                        r.mae_with_mm,
                        r.cup_error_without_mm,
                        r.cup_error_with_mm,
                        r.error
                    );
                }
                println!(
                    "mean MAE {without:.3} mm without, {with:.3} mm with pose refinement ({:.0} % lower); poses off by {deg} deg and {mm} mm (all views but view {}), seed {seed}",
                    100.0 * (1.0 - with / without),
                    cfg.pose.reference_view
                );
            }
            Ok(())
        }
        Command::Reconstruct {
            case,
            out,
            method,
            catalogue,
            backend,
            contours,
            refine_poses,
            uncertainty_samples,
            seed,
            json,
        } => {
            let catalogue =
                CupCatalogue::parse(&catalogue).map_err(|e| format!("--catalogue: {e}"))?;
            let prm = ReconParams {
                method,
                catalogue,
                contour_source: contours,
                pose: refine_poses.then(acetab::solve::PoseParams::default),
                ..Default::default()
            };
            let dev = open_device(backend)?;
            let engine = engine_on(&dev)?;
            let kernels = engine.as_ref().map_or(Kernels::Cpu, Kernels::Gpu);
            let up = UncertaintyParams {
                samples: uncertainty_samples as usize,
                seed,
                noise_px: None,
            };
            let report = run_case(&case, &out, &prm, kernels, &up).map_err(|e| e.to_string())?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string(&report).map_err(|e| e.to_string())?
                );
            } else {
                println!(
                    "{} ({:.1} s, {} correspondences, reprojection RMS {:.2} px, {} resamples, seed {}); outputs in {}",
                    report.cup.line(),
                    report.seconds,
                    report.log.correspondences,
                    report.log.reprojection_rms_px,
                    report.cup.samples,
                    report.cup.seed,
                    out.display()
                );
            }
            Ok(())
        }
    }
}

/// Sphere diameters (mm) an acetabulum can have; outside them `--gt` is warned about (a mesh in
/// metres or centimetres still runs, but the solver's tolerances are in millimetres).
const PLAUSIBLE_CUP_MM: (f64, f64) = (20.0, 100.0);

/// The study's ground truth from `--gt` (a mesh file or `phantom`). A surface no sphere fits, or
/// one the simulated views cannot see, is refused by the study itself before any run.
fn load_truth(gt: &str) -> Result<acetab::mesh::Mesh, String> {
    let truth = if gt == "phantom" {
        phantom(&PhantomParams::default()).mesh
    } else {
        let mesh = read_mesh(Path::new(gt)).map_err(|e| format!("--gt: {e}"))?;
        ground_truth_surface(&mesh).map_err(|e| format!("--gt {gt}: {e}"))?
    };
    let d = fit_sphere(&truth.vertices)
        .map_err(|e| format!("--gt {gt}: ground truth sphere fit: {e}"))?
        .diameter();
    if !(PLAUSIBLE_CUP_MM.0..=PLAUSIBLE_CUP_MM.1).contains(&d) {
        eprintln!(
            "acetab: warning: --gt {gt}: the fitted sphere is {d:.3} mm across, outside the {}-{} mm \
             of an acetabulum; is the mesh in millimetres? (the solver's tolerances are in mm)",
            PLAUSIBLE_CUP_MM.0, PLAUSIBLE_CUP_MM.1
        );
    }
    Ok(truth)
}

/// The engine on the device, if any (its pipelines compile here).
fn engine_on(dev: &Option<GpuDevice>) -> Result<Option<acetab::gpu::Gpu<'_>>, String> {
    dev.as_ref()
        .map(|d| d.engine())
        .transpose()
        .map_err(|e| e.to_string())
}

/// `--threads` (1 to `MAX_THREADS`), or every core.
fn threads_or_all(threads: Option<usize>) -> Result<usize, String> {
    match threads {
        Some(n) => within("--threads", n, 1, MAX_THREADS),
        None => Ok(std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)),
    }
}

/// Most worker threads a study takes.
const MAX_THREADS: usize = 1024;
/// Most runs per level a study takes (a study's tasks are listed up front).
const MAX_RUNS: usize = 100_000;

/// `value` when `lo <= value <= hi`, else an error naming the flag and its range.
fn within(flag: &str, value: usize, lo: usize, hi: usize) -> Result<usize, String> {
    if (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err(format!("{flag} {value}: must be {lo} to {hi}"))
    }
}

/// A comma-separated list without repeats; `allowed` (what the flag takes) goes into the error
/// naming an entry that cannot be read.
fn parse_list<T: PartialEq>(
    s: &str,
    flag: &str,
    allowed: &str,
    f: impl Fn(&str) -> Option<T>,
) -> Result<Vec<T>, String> {
    let mut list: Vec<T> = Vec::new();
    for x in s.split(',').map(str::trim) {
        let v =
            f(x).ok_or_else(|| format!("{flag} {s:?}: cannot read {x:?} (expected {allowed})"))?;
        if list.contains(&v) {
            return Err(format!("{flag} {s:?}: {x:?} is listed twice"));
        }
        list.push(v);
    }
    Ok(list)
}

fn parse_shard(s: &str) -> Result<(usize, usize), String> {
    let bad = || format!("--shard: expected I/N with 0 <= I < N, got {s:?}");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n): (usize, usize) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 || i >= n {
        return Err(bad());
    }
    Ok((i, n))
}

fn print_summary(rows: &[acetab::study::Row]) {
    println!(
        "{:<17} {:>5} {:>5} {:>9} {:>9} {:>11} {:>9} {:>9} {:>9} {:>9}",
        "method",
        "level",
        "runs",
        "MAE mm",
        "SD",
        "cup err mm",
        "|cup|<=1",
        "surface",
        "limb",
        "median s"
    );
    for s in summarize(rows) {
        println!(
            "{:<17} {:>5} {:>5} {:>9.3} {:>9.3} {:>+11.2} {:>6}/{:<2} {:>6}/{:<2} {:>9} {:>9.2}",
            s.method.name(),
            s.level,
            s.runs,
            s.mae_mean,
            s.mae_sd,
            s.cup_error_mean,
            s.cup_within_1mm,
            s.runs,
            s.surface_fit_within_1mm,
            s.runs,
            s.limb_within_1mm
                .map_or_else(|| "-".to_string(), |k| format!("{k:>6}/{:<2}", s.runs)),
            s.median_seconds
        );
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("acetab: error: {e}");
            ExitCode::FAILURE
        }
    }
}
