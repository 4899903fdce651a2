//! `acetab simulate`: the simulation study, levels x runs x methods on a ground-truth surface
//! (one mesh's: `study`; on many, a population sweep: `sweep`).

mod study;
mod sweep;

use crate::common::{
    count_in, engine_on, levels, methods, open_device, print_summary_as, shard, threads_or_all,
    views, Levels, Methods, Views, MAX_RUNS, MAX_THREADS,
};
use acetab::contours::ContourSource;
use acetab::engine::gpu::GpuBatcher;
use acetab::engine::{BackendChoice, Kernels};
use acetab::pipeline::{DeformationParams, ReconParams, UncertaintyParams};
use acetab::sim::{Protocol, RealisticErrors, XrayGeometry};
use acetab::study::StudyConfig;
use std::path::PathBuf;
use study::{Loso, PriorChoice, Study};
use sweep::{population_meshes, sweep};

/// `--protocol`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ProtocolArg {
    Ideal,
    Realistic,
}

#[derive(clap::Args)]
pub struct SimulateArgs {
    /// Ground truth: a mesh file (STL/PLY/OBJ; a closed shell is reduced to its outer side)
    /// or "phantom". Several files, or a folder of them, run a population sweep: one study per
    /// mesh in --out/<mesh name> (meshes already done there are skipped, so a sweep resumes),
    /// then population.csv, population.json and population.png over all of them.
    #[arg(long, num_args = 1.., required = true)]
    pub gt: Vec<String>,
    /// Start-noise levels 1 to 5 (the paper's: rotation, translation and scale of the template's start).
    #[arg(long, visible_alias = "level", default_value = "1,2,3,4,5", value_parser = levels)]
    pub levels: Levels,
    /// The X-ray views: each the antero-posterior view turned about body axes, x left-right
    /// (inlet/outlet tilts), y antero-posterior, z longitudinal (obliques); a view may chain
    /// turns ("z:20+x:-15")
    #[arg(long, default_value = "z:0,z:20,z:-20", value_parser = views)]
    pub views: Views,
    /// Runs per level and method.
    #[arg(long, default_value_t = 10, value_parser = count_in(1, MAX_RUNS))]
    pub runs: usize,
    /// How each run's X-rays are made: ideal (the nominal views, whole outlines, 2 px noise per
    /// point) or realistic (per-view pose errors of SD 1 degree and 2 mm, 2 % magnification
    /// error, the quarter of each outline over the femoral head left out, annotation drift of
    /// 2 px over about 20 px plus 1 px jitter; the reconstruction is told the nominal views).
    #[arg(long, value_enum, default_value_t = ProtocolArg::Ideal)]
    pub protocol: ProtocolArg,
    /// The realistic protocol's errors, KEY=VALUE over the defaults above: pose_deg, pose_mm,
    /// magnification (relative SD), left_out (share of each outline), drift_px,
    /// drift_length_px, jitter_px, click_px (the annotation as clicks this far apart along the
    /// outline; 0, the default, keeps the outline's own points), raster_px (the annotation as a
    /// segmentation mask's boundary: the cells of a grid this fine that the traced line passes
    /// through, a staircase; 0, the default, keeps the traced points); e.g. "left_out=0" for
    /// whole outlines, "click_px=20" for a rim clicked every 20 px, "raster_px=1" for an outline
    /// read off a mask pixel by pixel. Needs --protocol realistic.
    #[arg(long, value_parser = crate::common::realistic)]
    pub realistic: Option<Box<crate::common::Realistic>>,
    /// Refine small per-view pose corrections with the deformation (as `acetab reconstruct
    /// --refine-poses`; prior SD 2 deg, 5 mm; the first view defines the frame).
    #[arg(long)]
    pub refine_poses: bool,
    /// The pose refinement's prior SDs, "DEG,MM": how far each view's rotation (degrees, about
    /// the object) and translation (mm) may be off relative to the first view (default 2,5).
    /// Set it to your setup's pose accuracy. Needs --refine-poses.
    #[arg(long, requires = "refine_poses", value_parser = crate::common::pose_prior)]
    pub pose_prior: Option<acetab::solve::PoseParams>,
    /// Methods: srvf, icp, icp-normvec (every stage of ours, each on its own
    /// correspondences), and srvf-paper, icp-paper, icp-normvec-paper (the seed paper's
    /// protocol: the deformation alone, from the perturbed template).
    #[arg(long, visible_alias = "method", default_value = "srvf,icp,icp-normvec", value_parser = methods)]
    pub methods: Methods,
    /// Study seed; each run's seed is derived from it, the level and the run number.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long, value_parser = count_in(1, MAX_THREADS))]
    pub threads: Option<usize>,
    /// Run only shard I of N (0 <= I < N), for job arrays; join with `acetab merge`.
    #[arg(long, default_value = "0/1", value_parser = shard)]
    pub shard: (usize, usize),
    /// Where the kernels run: cpu, gpu, or auto (the GPU when an adapter exists).
    #[arg(long, value_enum, default_value_t = BackendChoice::Cpu)]
    pub backend: BackendChoice,
    /// With --backend gpu: runs in flight at once (default: --threads), each on its own
    /// thread, their kernel requests (deformation, and with --dp device every SRVF DP) merged
    /// into shared dispatches. Results do not depend on it.
    #[arg(long, value_parser = count_in(1, MAX_THREADS))]
    pub batch: Option<usize>,
    /// With --backend gpu, where the SRVF DPs run: on the device (the runs in flight share
    /// one dispatch), on the host, or auto (the device unless the adapter is a CPU, where the
    /// device is the host's own cores behind a driver).
    #[arg(long, value_enum, default_value_t = DpChoice::Auto)]
    pub dp: DpChoice,
    /// Model contours from alpha shapes or rasterised silhouettes.
    #[arg(long, value_enum, default_value_t = ContourSource::AlphaShape)]
    pub contours: ContourSource,
    /// ED energy weights w_rot, w_reg, w_obs (defaults: the published 1, 10, 100).
    #[arg(long, default_value_t = 1.0)]
    pub w_rot: f64,
    /// See --w-rot.
    #[arg(long, default_value_t = 10.0)]
    pub w_reg: f64,
    /// See --w-rot.
    #[arg(long, default_value_t = 100.0)]
    pub w_obs: f64,
    /// Weight of a pair's reprojection error along the observed outline, relative to across
    /// it: SRVF's pairs (default 0.3; docs/population.md, "How much the pairs hold along the
    /// outline") ...
    #[arg(long, default_value_t = acetab::pipeline::ReconParams::default().tangential_srvf)]
    pub w_along_srvf: f64,
    /// ... and the ICP baselines' (default 0.1).
    #[arg(long, default_value_t = acetab::solve::EdWeights::default().tangential)]
    pub w_along: f64,
    /// SRVF's pairs the rim makes: a pair whose observed point's ray passes the surface's
    /// sphere centre closer than this share of its radius, on a model vertex away from the
    /// model's border, weighs 0.3 of its weight (default 0.93; 0 turns it off: docs/population.md, "Pairs
    /// the rim makes").
    #[arg(long, default_value_t = acetab::pipeline::RimPairs::default().within)]
    pub rim_pairs: f64,
    /// Coarse-to-fine deformation: a graph of this many nodes in every correspondence round
    /// but the last (default: the full graph throughout; see docs/study.md).
    #[arg(long, value_parser = count_in(2, acetab::solve::GraphParams::default().nodes))]
    pub coarse_nodes: Option<usize>,
    /// SRVF's correspondence rounds in stage B, each solved until the deformation settles
    /// (default 3, the paper's 1-3; see docs/population.md on what more rounds do).
    #[arg(long, default_value_t = DeformationParams::default().correspondence_updates, value_parser = count_in(1, 50))]
    pub correspondence_updates: usize,
    /// SRVF's stage B ends after a round, from the second on, that moved the surface by less
    /// than this RMS, mm, unless the poses are refined (default 0: every
    /// --correspondence-updates round runs; docs/population.md, "Stage B's rounds ended where
    /// they settle", measured 1.0).
    #[arg(long, default_value_t = DeformationParams::default().settled_round_mm)]
    pub settled_round_mm: f64,
    /// Arc-length samples per curve of the deformation's SRVF alignments (default 200; stage A
    /// takes at most 100).
    #[arg(long, default_value_t = acetab::correspond::CorrespondParams::default().srvf.samples, value_parser = count_in(acetab::correspond::srvf::MIN_SAMPLES, 2000))]
    pub srvf_samples: usize,
    /// Rotation/DP alternations at most in each SRVF alignment, in every stage (default 3; 1
    /// makes a study about a fifth faster and moves every result: docs/gpu.md).
    #[arg(long, default_value_t = acetab::correspond::CorrespondParams::default().srvf.max_alternations, value_parser = count_in(1, 10))]
    pub srvf_alternations: usize,
    /// The SRVF DP's step neighbourhood: the steps (a, b) with a, b <= N and coprime, in every
    /// stage (default 5: 19 step directions; 3: 7, a cheaper DP that moves every result:
    /// docs/gpu.md).
    #[arg(long, default_value_t = acetab::correspond::CorrespondParams::default().srvf.neighbourhood, value_parser = count_in(2, 7))]
    pub srvf_neighbourhood: usize,
    /// Resamples for every run's cup uncertainty (cup_sd_mm, size_probability and brier in
    /// runs.csv; the same resampling as `acetab reconstruct`, seeded by the run's seed); 0
    /// turns it off.
    #[arg(long, default_value_t = 16, value_parser = crate::common::study_samples)]
    pub uncertainty_samples: u64,
    /// Cup calibration (JSON from `acetab calibrate`: the cup estimator's bias and shrink and
    /// the model-error SD added to the resamples' spread), or "none" (the resamples alone, no
    /// correction). Default: the shipped calibration of the protocol and cup estimator learned
    /// on the study's --views (calibration/ideal.json, realistic.json, ideal-prior-region.json
    /// or realistic-prior-region.json, learned on the paper's views; ideal-judet.json and
    /// realistic-judet.json for z:0,z:45,z:-45), with a warning when none was learned on them.
    /// A file learned on other views is used with a warning.
    #[arg(long)]
    pub calibration: Option<String>,
    /// Leave-one-subject-out calibration: each mesh's study uses a calibration learned (as
    /// `acetab calibrate` does) from the studies under this folder, less those of the mesh's
    /// subject (its file name up to the first '_'), so no study is calibrated on its own
    /// subject.
    #[arg(long, conflicts_with = "calibration")]
    pub calibrate_loso: Option<PathBuf>,
    /// With --calibrate-loso: learn each mesh's calibration with a shrink (as `acetab
    /// calibrate --shrink` does).
    #[arg(long, requires = "calibrate_loso")]
    pub calibrate_shrink: bool,
    /// With --calibrate-loso: learn each mesh's calibration without a depth offset (as `acetab
    /// calibrate --no-depth` does): the results stay where the method puts them along the
    /// views.
    #[arg(long, requires = "calibrate_loso")]
    pub calibrate_no_depth: bool,
    /// Population shape prior for the walls no outline watches: "none" (the bare sphere
    /// prior), "default" (the shipped prior, priors/default.json) or a file from `acetab prior
    /// build`.
    #[arg(long, default_value = "none")]
    pub prior: String,
    /// The cup estimator: "observed-part" (the sphere of the part the outlines hold) or, with a
    /// --prior, "prior-region" (the sphere of the part most of the prior's training acetabula
    /// cover). The calibration must have been learned for it (its bias is subtracted).
    #[arg(long, default_value = "observed-part", value_parser = crate::common::cup_estimator)]
    pub cup_estimator: acetab::pipeline::CupEstimator,
    /// Leave-one-subject-out prior: each mesh's study uses the --prior learned without the
    /// meshes of its subject (its file name up to the first '_').
    #[arg(long)]
    pub prior_leave_out: bool,
    /// Where the study is written (a sweep: one folder per mesh under it).
    #[arg(long)]
    pub out: PathBuf,
    /// Write into an --out that is not empty (same-named files are replaced, others stay).
    #[arg(long)]
    pub force: bool,
    /// Print the summary (a single study: summary.json's `summary`; a sweep: population.json's
    /// rows) as one JSON line on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: SimulateArgs) -> Result<(), String> {
    // The prior is checked before any run (with --prior-leave-out, each mesh's own is made
    // when its study starts).
    let (shape_prior, prior_from) = crate::prior::choose(&args.prior, None)?;
    if args.prior_leave_out && shape_prior.is_none() {
        return Err("--prior-leave-out needs a prior (--prior default or a file)".into());
    }
    let (cal, calibration) = calibration_of(&args, shape_prior.is_some())?;
    check_settings(&args)?;
    let mut cfg = study_config(&args, shape_prior, &cal);
    let dev = open_device(args.backend)?;
    let engine = engine_on(&dev)?;
    let dp_on_device = device_work(&args, dev.as_ref(), &mut cfg)?;
    let batcher = engine.as_ref().map(|g| {
        GpuBatcher::new(g, cfg.threads, acetab::engine::gpu::batcher::STUDY_WAIT)
            .with_dp_on_device(dp_on_device)
    });
    let kernels = batcher.as_ref().map_or(Kernels::Cpu, Kernels::Batched);
    let SimulateArgs {
        gt,
        runs,
        seed,
        shard,
        calibrate_loso,
        calibrate_shrink,
        calibrate_no_depth,
        prior,
        prior_leave_out,
        out,
        force,
        json,
        ..
    } = args;
    let study = Study {
        cfg: &cfg,
        calibration,
        adapter: dev.as_ref().map(|d| d.describe()),
        adapter_json: dev.as_ref().map(|d| d.adapter_json()),
        loso: calibrate_loso.map(|train| Loso {
            train,
            what: crate::calibrate::what(false, calibrate_shrink),
            depth: !calibrate_no_depth,
        }),
        prior: PriorChoice {
            arg: prior,
            leave_out: prior_leave_out,
            from: prior_from,
        },
        runs,
        seed,
        shard,
        kernels,
        batcher: batcher.as_ref(),
    };
    let meshes = population_meshes(&gt)?;
    if meshes.is_empty() {
        // A single study's folder must be new (a sweep's is resumed: its meshes' folders are
        // checked one by one).
        crate::common::check_out(&out, force)?;
        let rows = study.run(&gt[0], &out, false)?;
        return print_summary_as(&rows, json);
    }
    sweep(&study, &meshes, &out, json)
}

/// The cup calibration the study's runs apply and where it came from (summary.json): the
/// shipped one learned on the study's views (the paper's views' when none was) or the file
/// given, with a warning when it was learned on other views; none under --calibrate-loso, where
/// each mesh's own is learned when its study starts, from studies made under this protocol.
fn calibration_of(
    args: &SimulateArgs,
    has_prior: bool,
) -> Result<(acetab::pipeline::CupCalibration, String), String> {
    let realistic_protocol = args.protocol == ProtocolArg::Realistic;
    let views = &args.views.0;
    let (shipped_or_file, calibration) = crate::common::calibration(
        &args.calibration,
        realistic_protocol,
        args.cup_estimator,
        has_prior,
        views,
    )?;
    let Some(train) = &args.calibrate_loso else {
        let directions: Vec<_> = views.iter().map(|v| v.source_direction()).collect();
        let theirs = views
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(",");
        if let Some(w) = shipped_or_file.view_warning(&calibration, &directions, &theirs) {
            eprintln!("acetab: warning: {w}");
        }
        return Ok((shipped_or_file, calibration));
    };
    let ours = match args.protocol {
        ProtocolArg::Ideal => "ideal",
        ProtocolArg::Realistic => "realistic",
    };
    if let Some((theirs, d)) = crate::calibrate::protocols_in(std::slice::from_ref(train))
        .map_err(|e| e.replacen("--study", "--calibrate-loso", 1))?
        .into_iter()
        .find(|(k, _)| *k != ours)
    {
        return Err(format!(
            "--calibrate-loso {}: {} was made under the {theirs} protocol, this study is {ours}: a calibration learned under one protocol does not describe the other's errors",
            train.display(),
            d.display()
        ));
    }
    Ok((
        acetab::pipeline::CupCalibration::none(args.cup_estimator),
        calibration,
    ))
}

/// The flags no parser checks alone: --realistic needs its protocol, the weights are finite
/// and non-negative, --rim-pairs a share in [0, 1].
fn check_settings(args: &SimulateArgs) -> Result<(), String> {
    if args.realistic.is_some() && args.protocol != ProtocolArg::Realistic {
        return Err(
            "--realistic sets the realistic protocol's errors: add --protocol realistic".into(),
        );
    }
    for (flag, w) in [
        ("--w-rot", args.w_rot),
        ("--w-reg", args.w_reg),
        ("--w-obs", args.w_obs),
        ("--w-along-srvf", args.w_along_srvf),
        ("--w-along", args.w_along),
    ] {
        if !(w.is_finite() && w >= 0.0) {
            return Err(format!("{flag} {w}: must be a finite non-negative weight"));
        }
    }
    let rim_pairs = args.rim_pairs;
    if !(rim_pairs.is_finite() && (0.0..=1.0).contains(&rim_pairs)) {
        return Err(format!(
            "--rim-pairs {rim_pairs}: must be a share of the sphere's radius in [0, 1] (0: off)"
        ));
    }
    Ok(())
}

/// The study's settings from the flags: protocol, levels, runs, methods, the reconstruction's
/// parameters (with `cal`'s cup correction), the views and the cup's resamples.
fn study_config(
    args: &SimulateArgs,
    shape_prior: Option<std::sync::Arc<acetab::prior::ShapePrior>>,
    cal: &acetab::pipeline::CupCalibration,
) -> StudyConfig {
    let correspond = {
        let d = acetab::correspond::CorrespondParams::default();
        acetab::correspond::CorrespondParams {
            srvf: acetab::correspond::srvf::SrvfParams {
                samples: args.srvf_samples,
                max_alternations: args.srvf_alternations,
                neighbourhood: args.srvf_neighbourhood,
                ..d.srvf.clone()
            },
            ..d
        }
    };
    let params = ReconParams {
        contour_source: args.contours,
        weights: acetab::solve::EdWeights {
            rot: args.w_rot,
            reg: args.w_reg,
            obs: args.w_obs,
            tangential: args.w_along,
        },
        tangential_srvf: args.w_along_srvf,
        rim_pairs: (args.rim_pairs > 0.0).then(|| acetab::pipeline::RimPairs {
            within: args.rim_pairs,
            ..Default::default()
        }),
        deformation: DeformationParams {
            coarse_graph_nodes: args.coarse_nodes,
            correspondence_updates: args.correspondence_updates,
            settled_round_mm: args.settled_round_mm,
            shape_prior,
            ..Default::default()
        },
        correspond,
        pose: args
            .refine_poses
            .then(|| args.pose_prior.clone().unwrap_or_default()),
        cup: cal.correcting(acetab::pipeline::CupParams {
            estimator: args.cup_estimator,
            ..Default::default()
        }),
        ..Default::default()
    };
    StudyConfig {
        protocol: match args.protocol {
            ProtocolArg::Ideal => Protocol::Ideal,
            ProtocolArg::Realistic => Protocol::Realistic(
                args.realistic
                    .as_ref()
                    .map_or_else(RealisticErrors::default, |r| r.0.clone()),
            ),
        },
        levels: args.levels.0.clone(),
        runs: args.runs,
        methods: args.methods.0.clone(),
        seed: args.seed,
        threads: threads_or_all(args.threads),
        shard: args.shard,
        params,
        geometry: XrayGeometry {
            views: args.views.0.clone(),
            ..Default::default()
        },
        uncertainty: (args.uncertainty_samples > 0).then(|| UncertaintyParams {
            samples: args.uncertainty_samples as usize,
            model_sd_mm: cal.model_sd_mm,
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// What the device does: under --batch the runs in flight together share its dispatches (one
/// submit per kernel), so `cfg.threads` becomes the batch; whether the SRVF DPs go to it.
fn device_work(
    args: &SimulateArgs,
    dev: Option<&acetab::engine::gpu::GpuDevice>,
    cfg: &mut StudyConfig,
) -> Result<bool, String> {
    match (args.batch, dev) {
        (Some(b), Some(_)) => cfg.threads = b,
        (Some(b), None) => {
            return Err(format!(
                "--batch {b}: runs are batched on the device only with --backend gpu (or auto with an adapter); on the CPU use --threads"
            ))
        }
        (None, _) => {}
    }
    match (args.dp, dev) {
        (DpChoice::Host, _) => Ok(false),
        (DpChoice::Device, Some(_)) => Ok(true),
        (DpChoice::Device, None) => Err("--dp device: the SRVF DPs go to the device only with --backend gpu (or auto with an adapter)".into()),
        (DpChoice::Auto, d) => Ok(d.is_some_and(|d| !d.is_software())),
    }
}

/// `--dp`: where a GPU study's SRVF DPs run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DpChoice {
    /// The host's f64 DP (the reference).
    Host,
    /// The `srvf_band` kernel (f32), the runs in flight sharing dispatches.
    Device,
    /// The device unless the adapter is a CPU.
    Auto,
}
