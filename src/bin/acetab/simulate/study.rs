//! One mesh's simulation study, as `acetab simulate` runs it alone or for each mesh of a sweep:
//! its own settings (a calibration or prior learned without its subject), the runs, and its
//! folder (runs.csv, summary.json, the examples).

use crate::common::{io_msg, load_truth};
use acetab::engine::gpu::GpuBatcher;
use acetab::engine::Kernels;
use acetab::io::fill_dir_atomically;
use acetab::report::Provenance;
use acetab::study::{run_study_and_truth, tasks, write_examples, write_tables, StudyConfig};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};

/// `--prior` as given, `--prior-leave-out`, and where the prior came from (summary.json).
pub(super) struct PriorChoice {
    pub(super) arg: String,
    pub(super) leave_out: bool,
    pub(super) from: String,
}

/// One study's settings, shared by every mesh of a sweep.
pub(super) struct Study<'a> {
    pub(super) cfg: &'a StudyConfig,
    /// Where the cup calibration came from (summary.json).
    pub(super) calibration: String,
    /// The GPU adapter, when the kernels run on one (summary.json's provenance).
    pub(super) adapter: Option<String>,
    /// The adapter's name, driver, device type and API (summary.json's `engine`).
    pub(super) adapter_json: Option<serde_json::Value>,
    /// `--calibrate-loso`: the studies each mesh's calibration is learned from, and what is
    /// learned.
    pub(super) loso: Option<Loso>,
    /// The prior asked for.
    pub(super) prior: PriorChoice,
    pub(super) runs: usize,
    pub(super) seed: u64,
    pub(super) shard: (usize, usize),
    pub(super) kernels: Kernels<'a>,
    pub(super) batcher: Option<&'a GpuBatcher<'a>>,
}

/// `--calibrate-loso` and its companions: the studies each mesh's calibration is learned from
/// (less the mesh's subject), what of the cup is learned, and whether the depth offset is.
pub(super) struct Loso {
    pub(super) train: PathBuf,
    pub(super) what: acetab::pipeline::Learn,
    pub(super) depth: bool,
}

impl Study<'_> {
    /// The settings every mesh of a sweep shares and its runs depend on, as summary.json's
    /// `study` records them (the rest there is the mesh's own: its truth, its calibration and
    /// prior when learned without its subject, the time, the engine).
    pub(super) fn settings(&self) -> serde_json::Map<String, serde_json::Value> {
        let cfg = self.cfg;
        let mut m = serde_json::json!({
            "levels": cfg.levels, "runs": self.runs, "methods": cfg.methods, "seed": self.seed,
            "shard": format!("{}/{}", self.shard.0, self.shard.1),
            "views": cfg.geometry.views.iter().map(|v| v.to_string()).collect::<Vec<_>>(),
            "protocol": cfg.protocol, "contour_noise_px": cfg.noise_px,
            "contours": format!("{:?}", cfg.params.contour_source),
            "w_rot": cfg.params.weights.rot, "w_reg": cfg.params.weights.reg,
            "w_obs": cfg.params.weights.obs, "refine_poses": cfg.params.pose.is_some(),
            "w_along": cfg.params.weights.tangential,
            "w_along_srvf": cfg.params.tangential_srvf,
            "rim_pairs": cfg.params.rim_pairs.as_ref().map_or(0.0, |r| r.within),
            "pose_prior": cfg.params.pose.as_ref().map(acetab::solve::PoseParams::prior_sds),
            "cup_estimator": cfg.params.cup.estimator.name(),
            "coarse_nodes": cfg.params.deformation.coarse_graph_nodes,
            "correspondence_updates": cfg.params.deformation.correspondence_updates,
            "settled_round_mm": cfg.params.deformation.settled_round_mm,
            "srvf_samples": cfg.params.correspond.srvf.samples,
            "srvf_alternations": cfg.params.correspond.srvf.max_alternations,
            "srvf_neighbourhood": cfg.params.correspond.srvf.neighbourhood,
            // How each run's cup uncertainty was resampled (0 resamples: none).
            "uncertainty_samples": cfg.uncertainty.as_ref().map_or(0, |u| u.samples),
        })
        .as_object()
        .cloned()
        .unwrap_or_default();
        // The cup's calibration and the prior are shared too, unless each mesh learns its own
        // without its subject.
        // With --calibrate-loso the studies learned from and what is learned are shared, so a
        // sweep resumed or merged with other ones is refused.
        match &self.loso {
            None => {
                m.insert("calibration".into(), self.calibration.clone().into());
            }
            Some(l) => {
                let train = std::fs::canonicalize(&l.train)
                    .unwrap_or_else(|_| l.train.clone())
                    .display()
                    .to_string();
                m.insert(
                    "calibrate_loso".into(),
                    serde_json::json!({
                        "study": train,
                        "learn": format!("{:?}", l.what),
                        "depth": l.depth,
                    }),
                );
            }
        }
        if !self.prior.leave_out {
            m.insert("prior".into(), self.prior.from.clone().into());
        }
        m
    }

    /// One study on the truth `gt`, its folder written at `out`; its rows. A study in which
    /// every run failed is an error with nothing written, unless `keep_failed` (a sweep's mesh:
    /// its runs.csv records each run's reason, and the population table counts them).
    pub(super) fn run(
        &self,
        gt: &str,
        out: &Path,
        keep_failed: bool,
    ) -> Result<Vec<acetab::study::Row>, String> {
        let Study {
            ref adapter,
            ref adapter_json,
            seed,
            kernels,
            batcher,
            ..
        } = *self;
        let truth = load_truth(gt)?;
        let (own, calibration, prior_from) = self.own_settings(gt)?;
        let cfg = &own;
        let total = tasks(cfg).len();
        let bar = ProgressBar::new(total as u64);
        bar.set_style(
            ProgressStyle::with_template(
                "{bar:40} {pos}/{len} runs, {elapsed} elapsed, ~{eta} left",
            )
            .map_err(|e| e.to_string())?,
        );
        let start = std::time::Instant::now();
        let stats_before = batcher.map(|b| b.stats());
        // The truth's cup, and the sphere through its own outline-forming vertices (from the
        // study's own set-up, beside the runs).
        let (rows, examples, truth_spheres) =
            run_study_and_truth(&truth, cfg, &|| bar.inc(1), kernels)
                .map_err(|e| format!("--gt {gt}: {e}"))?;
        if let Some(b) = batcher {
            let (req, disp) = b.counts();
            eprintln!(
                "GPU: {req} kernel requests in {disp} dispatches ({:.2} runs per submit)",
                req as f64 / disp.max(1) as f64
            );
        }
        bar.finish_and_clear();
        // A study in which every run failed (a solver diverging for want of regularisation,
        // say) has no result to write: it is an error, not a folder of NaN with exit 0.
        if !keep_failed && !rows.is_empty() && rows.iter().all(|r| !r.error.is_empty()) {
            return Err(format!(
                "simulate: all {} runs failed, nothing written (the first, {} level {} run {}: {})",
                rows.len(),
                rows[0].method.name(),
                rows[0].level,
                rows[0].run,
                rows[0].error
            ));
        }
        let mut meta = self.settings();
        let own_keys = serde_json::json!({
            // A mesh by its canonical path, so shards given it relatively and absolutely agree.
            "gt": std::fs::canonicalize(gt).map_or_else(|_| gt.to_string(), |p| p.display().to_string()),
            "truth_cup_diameter_mm": truth_spheres.cup_mm,
            "truth_outline_sphere_diameter_mm": truth_spheres.outline_mm,
            "seconds": start.elapsed().as_secs_f64(),
            "cup_model_sd_mm": cfg.uncertainty.as_ref().map(|u| u.model_sd_mm),
            "cup_bias_mm": cfg.params.cup.bias_mm,
            "cup_shrink": cfg.params.cup.shrink,
            "cup_shrink_to_mm": cfg.params.cup.shrink_to_mm,
            "cup_depth_mm": cfg.params.cup.depth_mm,
            "calibration": calibration,
            "prior": prior_from,
            "provenance": Provenance::here(kernels.name(), adapter.clone(), cfg.threads, seed),
            // Where the kernels ran and, on the GPU, this study's kernel requests, the dispatches
            // they were merged into and the seconds the runs waited for the device.
            "engine": engine_json(kernels, batcher, stats_before, adapter_json),
            "resample_steps": cfg.uncertainty.as_ref().map(|u| u.resample_steps(&cfg.params)),
        });
        if let serde_json::Value::Object(own) = own_keys {
            meta.extend(own);
        }
        let meta = serde_json::Value::Object(meta);
        write_study(out, &rows, &examples, &truth, &meta)?;
        eprintln!(
            "{} runs in {:.1} s (seed {seed}); results in {}",
            rows.len(),
            start.elapsed().as_secs_f64(),
            out.display()
        );
        if let Some(o) = truth_spheres.outline_mm {
            let t = truth_spheres.cup_mm;
            eprintln!(
            "truth cup {t:.2} mm; the sphere through its outline-forming vertices {o:.2} mm \
             ({:+.2} mm: the cup error of a sphere fitted to the outlined part alone, before noise)",
            o - t
        );
        }
        Ok(rows)
    }

    /// The settings of the study of the mesh `gt`: the sweep's, with the calibration learned
    /// without its subject (`--calibrate-loso`) and the prior made without it
    /// (`--prior-leave-out`); and where the calibration and the prior came from (summary.json).
    fn own_settings(&self, gt: &str) -> Result<(StudyConfig, String, String), String> {
        let subject = crate::calibrate::subject_of(Path::new(gt));
        let mut own = self.cfg.clone();
        let calibration = match &self.loso {
            Some(loso) => loso.calibrate(&subject, &mut own)?,
            None => self.calibration.clone(),
        };
        let mut prior_from = self.prior.from.clone();
        if self.prior.leave_out {
            let (p, from) = crate::prior::choose(&self.prior.arg, Some(&subject))?;
            own.params.deformation.shape_prior = p;
            prior_from = from;
        }
        Ok((own, calibration, prior_from))
    }
}

/// A study's folder, written whole or not at all: the tables and the examples' meshes and
/// pictures, side by side, with their warnings on stderr.
fn write_study(
    out: &Path,
    rows: &[acetab::study::Row],
    examples: &[acetab::study::ExampleRun],
    truth: &acetab::geom::Mesh,
    meta: &serde_json::Value,
) -> Result<(), String> {
    fill_dir_atomically(
        out,
        |d| {
            let (tables, pictures) = rayon::join(
                || write_tables(rows, d, meta),
                || write_examples(examples, truth, d),
            );
            let mut warnings = tables.map_err(|e| e.to_string())?;
            warnings.extend(pictures.map_err(|e| e.to_string())?);
            for w in warnings {
                eprintln!("acetab: warning: {}", crate::common::unstage(&w, out));
            }
            Ok(())
        },
        io_msg,
    )
    .map_err(|e| crate::common::unstage(&e, out))
}

impl Loso {
    /// Learn the calibration without `subject` (the mesh's) and apply it to `cfg` (the cup's
    /// correction and the resamples' model SD); what it was learned from (summary.json).
    fn calibrate(&self, subject: &str, cfg: &mut StudyConfig) -> Result<String, String> {
        let Loso { train, what, depth } = self;
        let mut cal = crate::calibrate::learn(
            std::slice::from_ref(train),
            &[subject.to_string()],
            acetab::study::StudyMethod::Srvf,
            *what,
            None,
        )
        .map_err(|e| format!("--calibrate-loso: {e}"))?;
        if !depth {
            cal.depth_mm = 0.0;
        }
        let used = cfg.params.cup.estimator;
        if cal.cup_estimator() != Some(used) {
            return Err(format!(
                "--calibrate-loso {}: its studies used the {} cup estimator, this one {}",
                train.display(),
                cal.estimator,
                used.name()
            ));
        }
        cfg.params.cup = cal.correcting(cfg.params.cup.clone());
        if let Some(up) = cfg.uncertainty.as_mut() {
            up.model_sd_mm = cal.model_sd_mm;
        }
        let no_depth = if *depth { "" } else { " (no depth offset)" };
        Ok(format!(
            "leave-one-subject-out: {} without subject {subject}{no_depth}: {}",
            train.display(),
            cal.learned_from
        ))
    }
}

/// summary.json's `engine`: where the kernels ran and, on the GPU, this study's kernel requests,
/// the dispatches they were merged into and the seconds the runs waited for the device (the
/// batcher's counts since `before`).
fn engine_json(
    kernels: Kernels,
    batcher: Option<&GpuBatcher>,
    before: Option<acetab::engine::gpu::batcher::BatcherStats>,
    adapter_json: &Option<serde_json::Value>,
) -> serde_json::Value {
    match batcher.zip(before) {
        Some((b, before)) => {
            let k = b.stats().since(&before);
            serde_json::json!({
                "backend": kernels.name(),
                "adapter": adapter_json,
                "batch": b.lanes(),
                "dp": if b.dp_on_device() { "device" } else { "host" },
                "requests": k.total().requests,
                "dispatches": k.total().dispatches,
                "kernels": k,
            })
        }
        None => serde_json::json!({
            "backend": kernels.name(), "adapter": null, "batch": 1, "dp": "host"
        }),
    }
}
