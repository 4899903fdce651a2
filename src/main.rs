//! The `acetab` command line: parses arguments and calls the library.

use acetab::case::CaseFile;
use acetab::correspond::Method;
use acetab::demo::{run_demo, write_error_ply};
use acetab::fsutil::write_atomic;
use acetab::mesh::io::write_ply;
use acetab::pipeline::{reconstruct, ReconParams};
use acetab::report::CupCatalogue;
use clap::{Parser, Subcommand};
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
        /// Output folder.
        #[arg(long, default_value = "acetab-out")]
        out: PathBuf,
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
        #[arg(long)]
        json: bool,
    },
}

fn create_dir(out: &Path) -> Result<(), String> {
    std::fs::create_dir_all(out)
        .map_err(|e| format!("{}: cannot create output folder: {e}", out.display()))
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.command {
        Command::Demo {
            json,
            seed,
            level,
            method,
            out,
        } => {
            let prm = ReconParams {
                method,
                ..Default::default()
            };
            let (report, truth, rec) = run_demo(seed, level, &prm).map_err(|e| e.to_string())?;
            let report_json = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
            create_dir(&out)?;
            write_error_ply(&rec.mesh, &truth, &out.join("reconstruction.ply"))
                .map_err(|e| e.to_string())?;
            write_ply(&truth, None, &out.join("truth.ply")).map_err(|e| e.to_string())?;
            write_atomic(&out.join("report.json"), report_json.as_bytes())
                .map_err(|e| format!("{}: {e}", out.display()))?;
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
        Command::Reconstruct {
            case,
            out,
            method,
            catalogue,
            json,
        } => {
            let catalogue =
                CupCatalogue::parse(&catalogue).map_err(|e| format!("--catalogue: {e}"))?;
            let c = CaseFile::load(&case).map_err(|e| e.to_string())?;
            let prm = ReconParams {
                method,
                catalogue,
                ..Default::default()
            };
            let t = std::time::Instant::now();
            let rec = reconstruct(&c.cameras, &c.observed, &c.init, &prm)
                .map_err(|e| format!("{}: {e}", case.display()))?;
            let seconds = t.elapsed().as_secs_f64();
            let report = serde_json::json!({
                "case": case.display().to_string(),
                "method": method.name(),
                "cup_diameter_mm": rec.sphere.diameter(),
                "cup_catalogue_mm": rec.cup.catalogue_mm,
                "sphere": rec.sphere,
                "log": rec.log,
                "seconds": seconds,
            });
            let text = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
            create_dir(&out)?;
            write_ply(&rec.mesh, None, &out.join("reconstruction.ply"))
                .map_err(|e| e.to_string())?;
            write_atomic(&out.join("report.json"), text.as_bytes())
                .map_err(|e| format!("{}: {e}", out.display()))?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string(&report).map_err(|e| e.to_string())?
                );
            } else {
                println!(
                    "cup {:.2} mm -> catalogue {:.0} mm ({:.2} s, {} correspondences, reprojection RMS {:.2} px)",
                    rec.sphere.diameter(),
                    rec.cup.catalogue_mm,
                    seconds,
                    rec.log.correspondences,
                    rec.log.reprojection_rms_px
                );
            }
            Ok(())
        }
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
