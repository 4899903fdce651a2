//! `acetab reconstruct`: reconstruct a case file.

use crate::common::{engine_on, open_device};
use acetab::case::{run_case_calibrated, CalibrationChoice};
use acetab::contours::ContourSource;
use acetab::correspond::Method;
use acetab::engine::{BackendChoice, Kernels};
use acetab::pipeline::{CupParams, ReconParams};
use acetab::pipeline::{UncertaintyParams, MAX_RESAMPLES, MIN_RESAMPLES};
use acetab::report::CupCatalogue;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ReconstructArgs {
    /// The case file(s) (JSON: views, outlines, start; see README, "The case file"). Several
    /// cases are written one folder each under --out (named after the file), with cases.csv, a
    /// line per case (a case that fails is a line with its error; the others still run).
    #[arg(required = true)]
    pub case: Vec<PathBuf>,
    /// Where the outputs are written (made in a staging folder and moved there at the end).
    #[arg(long)]
    pub out: PathBuf,
    /// Write into an --out that is not empty (same-named files are replaced, others stay).
    #[arg(long)]
    pub force: bool,
    /// Correspondence method: srvf (ours), icp or icp-normvec.
    #[arg(long, visible_alias = "methods", value_enum, default_value_t = Method::Srvf)]
    pub method: Method,
    /// Cup catalogue: "min:max:step" or a list "44,46,48".
    #[arg(long, default_value = "40:70:2")]
    pub catalogue: String,
    /// Refine small per-view pose corrections with the deformation (prior SD 2 deg, 5 mm;
    /// the first view fixes the frame).
    #[arg(long)]
    pub refine_poses: bool,
    /// The pose refinement's prior SDs, "DEG,MM": how far each view's rotation (degrees, about
    /// the object) and translation (mm) may be off relative to the first view (default 2,5).
    /// Set it to your setup's pose accuracy. Needs --refine-poses.
    #[arg(long, requires = "refine_poses", value_parser = crate::common::pose_prior)]
    pub pose_prior: Option<acetab::solve::PoseParams>,
    /// Resamples for the cup size's uncertainty (contour noise + bootstrap weights), 2 to 1000
    /// (one resample has no spread).
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u64).range(MIN_RESAMPLES as u64..=MAX_RESAMPLES as u64))]
    pub uncertainty_samples: u64,
    /// Cup calibration (JSON from `acetab calibrate`: the correction of the fitted cup, its
    /// bias and shrink, and the model-error SD added to the resamples' spread), or "none" (the
    /// fitted cup and the resamples alone). Default: the shipped calibration learned under the
    /// realistic protocol on the case's views: for the AP and the two Judet obliques (sources
    /// turned 0 and +-45 degrees about the long axis, each within 10)
    /// calibration/realistic-judet.json, otherwise the paper's views' calibration/realistic.json
    /// (with a warning when the case's views are not the paper's either). A file learned on
    /// other views than the case's is used with a warning.
    #[arg(long)]
    pub calibration: Option<String>,
    /// Population shape prior for the walls no outline watches: "none" (the bare sphere
    /// prior), "default" (the shipped one, priors/default.json) or a file from `acetab prior
    /// build`. The case's frame must be body axes (z the long axis, y antero-posterior).
    #[arg(long, default_value = "none")]
    pub prior: String,
    /// The cup estimator: "observed-part" (the sphere of the part the outlines hold) or, with a
    /// --prior, "prior-region" (the sphere of the part most of the prior's training acetabula
    /// cover). The calibration must have been learned for it (its bias is subtracted).
    #[arg(long, default_value = "observed-part", value_parser = crate::common::cup_estimator)]
    pub cup_estimator: acetab::pipeline::CupEstimator,
    /// Seed of the resampling draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where the kernels run: cpu, gpu, or auto (the GPU when an adapter exists).
    #[arg(long, value_enum, default_value_t = BackendChoice::Cpu)]
    pub backend: BackendChoice,
    /// Model contours from alpha shapes or rasterised silhouettes.
    #[arg(long, value_enum, default_value_t = ContourSource::AlphaShape)]
    pub contours: ContourSource,
    /// Print the report (report.json's content) as one JSON object instead of the line.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: ReconstructArgs) -> Result<(), String> {
    let (shape_prior, _) = crate::prior::choose(&args.prior, None)?;
    // The file (or "none") is checked up front; each case then gets the calibration learned on
    // its views (`CalibrationChoice::resolve`).
    let (cal, _) = crate::common::calibration(
        &args.calibration,
        true,
        args.cup_estimator,
        shape_prior.is_some(),
        &[],
    )?;
    let choice =
        CalibrationChoice::from_arg(args.calibration.as_deref(), true, args.cup_estimator, cal);
    crate::common::check_out(&args.out, args.force)?;
    let catalogue =
        CupCatalogue::parse(&args.catalogue).map_err(|e| format!("--catalogue: {e}"))?;
    let mut prm = ReconParams {
        method: args.method,
        cup: CupParams {
            catalogue,
            estimator: args.cup_estimator,
            ..Default::default()
        },
        contour_source: args.contours,
        pose: args
            .refine_poses
            .then(|| args.pose_prior.unwrap_or_default()),
        ..Default::default()
    };
    prm.deformation.shape_prior = shape_prior;
    let dev = open_device(args.backend)?;
    let engine = engine_on(&dev)?;
    let kernels = engine.as_ref().map_or(Kernels::Cpu, Kernels::Gpu);
    let runner = CaseRunner {
        up: UncertaintyParams {
            samples: args.uncertainty_samples as usize,
            seed: args.seed,
            ..Default::default()
        },
        provenance: acetab::report::Provenance::here(
            kernels.name(),
            dev.as_ref().map(|d| d.describe()),
            1,
            args.seed,
        ),
        prm,
        kernels,
        choice,
        json: args.json,
    };
    if let [one] = args.case.as_slice() {
        let report = runner
            .run(one, &args.out)
            .map_err(|e| crate::common::unstage(&e.to_string(), &args.out))?;
        return print_report(&report, args.json, &args.out);
    }
    runner.run_many(&args.case, &args.out)
}

/// What every case of one `acetab reconstruct` shares.
struct CaseRunner<'g> {
    prm: ReconParams,
    kernels: Kernels<'g>,
    up: UncertaintyParams,
    provenance: acetab::report::Provenance,
    choice: CalibrationChoice,
    /// Print each report as JSON.
    json: bool,
}

impl CaseRunner<'_> {
    /// The case file `case`, its outputs written to `out`.
    fn run(
        &self,
        case: &std::path::Path,
        out: &std::path::Path,
    ) -> Result<acetab::case::CaseRunReport, acetab::case::CaseRunError> {
        run_case_calibrated(
            case,
            out,
            &self.prm,
            self.kernels,
            &self.up,
            self.provenance.clone(),
            &self.choice,
        )
    }

    /// Several cases: one folder each under `out` (named after the file), then cases.csv, a
    /// line per case; an error when any failed (the others still run and are written).
    fn run_many(&self, cases: &[PathBuf], out: &std::path::Path) -> Result<(), String> {
        let names = case_names(cases)?;
        std::fs::create_dir_all(out).map_err(|e| crate::common::io_msg(out, e))?;
        let mut table = String::from(
            "case,file,diameter_mm,catalogue_mm,sd_mm,size_probability,reprojection_rms_px,fallback,error\n",
        );
        let mut failed = Vec::new();
        for (c, name) in cases.iter().zip(&names) {
            let dir = out.join(name);
            let (name_cell, file_cell) = (csv_text(name), csv_text(&c.display().to_string()));
            match self.run(c, &dir) {
                Ok(r) => {
                    print_report(&r, self.json, &dir)?;
                    table += &format!(
                        "{name_cell},{file_cell},{:.6},{},{:.6},{:.6},{:.6},{},\n",
                        r.cup.diameter_mm,
                        r.cup.catalogue_mm,
                        r.cup.sd_mm,
                        r.cup.probability_of(r.cup.catalogue_mm),
                        r.log.reprojection_rms_px,
                        r.log.fallback.map(|f| f.to_string()).unwrap_or_default(),
                    );
                }
                Err(e) => {
                    let e = acetab::io::printable(&crate::common::unstage(&e.to_string(), &dir));
                    eprintln!("acetab: error: {e}");
                    failed.push(name.clone());
                    table += &format!(
                        "{name_cell},{file_cell},NaN,NaN,NaN,NaN,NaN,,{}\n",
                        csv_text(&e)
                    );
                }
            }
        }
        acetab::io::write_atomic(&out.join("cases.csv"), table.as_bytes())
            .map_err(|e| crate::common::io_msg(&out.join("cases.csv"), e))?;
        eprintln!(
            "{} of {} cases reconstructed; cases.csv in {}",
            cases.len() - failed.len(),
            cases.len(),
            out.display()
        );
        // A case that failed fails the command too (the others' folders and cases.csv are
        // written), so a script that runs a batch sees it.
        if failed.is_empty() {
            Ok(())
        } else {
            Err(format!(
                "{} of {} cases failed: {} (cases.csv says why)",
                failed.len(),
                cases.len(),
                failed.join(", ")
            ))
        }
    }
}

/// Each case's folder name (its file's stem); an error when two collide.
fn case_names(cases: &[PathBuf]) -> Result<Vec<String>, String> {
    let mut names: Vec<String> = Vec::new();
    for c in cases {
        let stem = c
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "case".into());
        if names.contains(&stem) {
            return Err(format!(
                "{}: two cases are named {stem:?}; their folders would collide",
                c.display()
            ));
        }
        names.push(stem);
    }
    Ok(names)
}

/// One CSV cell: quoted when it holds a comma, a quote or a line break.
fn csv_text(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// A case's report: its warnings, then the JSON or the terminal line.
fn print_report(
    report: &acetab::case::CaseRunReport,
    json: bool,
    out: &std::path::Path,
) -> Result<(), String> {
    for w in &report.warnings {
        eprintln!("acetab: warning: {w}");
    }
    if json {
        println!(
            "{}",
            serde_json::to_string(report).map_err(|e| e.to_string())?
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
        if let Some(note) = report.log.restart_note() {
            println!("note: {note}");
        }
        if let (Some(f), Some(g)) = (report.log.fallback, &report.log.guard) {
            println!(
                "note: the method's own result was refused ({g}); this one is the {f} fallback's"
            );
        }
    }
    Ok(())
}
