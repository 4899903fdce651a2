//! `acetab demo`: simulate three X-rays of the built-in phantom, reconstruct, and report accuracy.

use crate::common::{engine_on, io_msg, open_device};
use acetab::contours::ContourSource;
use acetab::correspond::Method;
use acetab::engine::{BackendChoice, Kernels};
use acetab::io::fill_dir_atomically;
use acetab::io::write_ply;
use acetab::pipeline::ReconParams;
use acetab::report::{vertex_errors, write_errors_ply};
use acetab::sim::run_demo;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct DemoArgs {
    /// Print one JSON object instead of the text summary.
    #[arg(long)]
    pub json: bool,
    /// Seed of every random draw (contour noise and initial pose).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Initialisation noise level 0..5.
    #[arg(long, visible_alias = "levels", default_value_t = 3)]
    pub level: u32,
    /// Correspondence method: srvf (ours), icp or icp-normvec.
    #[arg(long, visible_alias = "methods", value_enum, default_value_t = Method::Srvf)]
    pub method: Method,
    /// Where the kernels run: cpu, gpu, or auto (the GPU when an adapter exists).
    #[arg(long, value_enum, default_value_t = BackendChoice::Cpu)]
    pub backend: BackendChoice,
    /// Model contours from alpha shapes or rasterised silhouettes.
    #[arg(long, value_enum, default_value_t = ContourSource::AlphaShape)]
    pub contours: ContourSource,
    /// Output folder.
    #[arg(long, default_value = "acetab-out")]
    pub out: PathBuf,
    /// Population shape prior: "none" (the bare sphere prior), "default" (the shipped one) or
    /// a file from `acetab prior build`.
    #[arg(long, default_value = "none")]
    pub prior: String,
}

pub fn run(args: DemoArgs) -> Result<(), String> {
    let DemoArgs {
        json,
        seed,
        level,
        method,
        backend,
        contours,
        out,
        prior,
    } = args;
    crate::common::check_writable_out(&out, &out)?;
    let (shape_prior, _) = crate::prior::choose(&prior, None)?;
    let mut prm = ReconParams {
        method,
        contour_source: contours,
        ..Default::default()
    };
    prm.deformation.shape_prior = shape_prior;
    let dev = open_device(backend)?;
    let engine = engine_on(&dev)?;
    let kernels = engine.as_ref().map_or(Kernels::Cpu, Kernels::Gpu);
    let (report, truth, rec) = run_demo(seed, level, &prm, kernels).map_err(|e| e.to_string())?;
    let report_json = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
    fill_dir_atomically(
        &out,
        |d| {
            let err = vertex_errors(&rec.mesh, &truth);
            write_errors_ply(&rec.mesh, &err, &d.join("reconstruction.ply"))
                .map_err(|e| e.to_string())?;
            write_ply(&truth, None, &d.join("truth.ply")).map_err(|e| e.to_string())?;
            // The result from two viewpoints, coloured by its error (a warning if not drawn).
            let axis = acetab::report::plots::opening_axis(&rec.mesh, &rec.sphere);
            if let Err(e) = acetab::report::plots::surface_views(
                &rec.mesh,
                &err,
                &axis,
                3.0,
                "error (mm)",
                &d.join("reconstruction.png"),
                &|p| kernels.render_surface(p).0,
            ) {
                eprintln!("acetab: warning: reconstruction.png not drawn: {e}");
            }
            std::fs::write(d.join("report.json"), report_json.as_bytes())
                .map_err(|e| format!("{}: {e}", d.join("report.json").display()))
        },
        io_msg,
    )
    .map_err(|e| crate::common::unstage(&e, &out))?;
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
        if let Some(note) = report.log.restart_note() {
            println!("  note: {note}");
        }
        if let (Some(f), Some(g)) = (report.log.fallback, &report.log.guard) {
            println!(
                "  note: the method's own result was refused ({g}); this one is the {f} fallback's"
            );
        }
    }
    Ok(())
}
