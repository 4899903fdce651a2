//! Running the study's runs, in parallel, in a fixed order.

use super::method::StudyMethod;
use super::task::{run_seed, Task};
use super::Row;
use crate::engine::Kernels;
use crate::geom::pool_map;
use crate::geom::{Curve, Mesh};
use crate::pipeline::{cup_report, reconstruct, GuardFailure, ReconParams, Reconstruction};
use crate::pipeline::{RestartCause, UncertaintyParams};
use crate::report::{accuracy_and_shift, accuracy_samples};
use crate::report::{DistanceStats, InteriorQuery};
use crate::sim::XrayGeometry;
use crate::sim::{NoiseLevel, Protocol, SimCase, SimError, SimSetup};
use crate::solve::rim_orientation;
use crate::template::{Template, TemplateParams};

/// What to run.
#[derive(Clone, Debug)]
pub struct StudyConfig {
    /// Noise levels of the start.
    pub levels: Vec<u32>,
    /// Runs per level and method.
    pub runs: usize,
    /// Methods.
    pub methods: Vec<StudyMethod>,
    /// Study seed (each run's is derived from it).
    pub seed: u64,
    /// Worker threads (the results do not depend on it).
    pub threads: usize,
    /// (index, count): this process runs the tasks whose position modulo count is index.
    pub shard: (usize, usize),
    /// Contour noise SD, pixels (the ideal protocol's).
    pub noise_px: f64,
    /// How each run's case is made: ideal (default) or realistic (pose and magnification
    /// errors, partial outlines, annotation drift; `noise_px` then unused).
    pub protocol: Protocol,
    /// The simulated views.
    pub geometry: XrayGeometry,
    /// The standard template every run starts from.
    pub template: TemplateParams,
    /// The reconstruction settings (each method turns stages off).
    pub params: ReconParams,
    /// The cup's uncertainty for every run (`cup_report`, as `acetab reconstruct` gives it; the
    /// seed is each run's own), or None. Default: 16 resamples.
    pub uncertainty: Option<UncertaintyParams>,
}

impl StudyConfig {
    /// What a study cannot run with, before any run: a contour noise that is not a finite
    /// SD >= 0, a level outside 0..=5, a level or method listed twice (its runs would come
    /// twice, one runs.csv line each, which `read_csv` refuses), a shard index not below a shard
    /// count >= 1, and the reconstruction settings `ReconParams::validate` refuses. (No levels,
    /// runs or methods is an empty study, not an error.)
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |field, value: String, expected| SimError::Setting {
            field,
            value,
            expected,
        };
        if !(self.noise_px.is_finite() && self.noise_px >= 0.0) {
            return Err(bad(
                "noise_px",
                self.noise_px.to_string(),
                "a finite SD >= 0",
            ));
        }
        if let Some(l) = self
            .levels
            .iter()
            .find(|l| NoiseLevel::level(**l).is_none())
        {
            return Err(bad("levels", l.to_string(), "0 to 5"));
        }
        let twice = |names: Vec<String>| {
            (1..names.len())
                .find(|&k| names[..k].contains(&names[k]))
                .map(|k| names[k].clone())
        };
        if let Some(l) = twice(self.levels.iter().map(u32::to_string).collect()) {
            return Err(bad("levels", l, "each level listed once"));
        }
        if let Some(m) = twice(self.methods.iter().map(|m| m.name().to_string()).collect()) {
            return Err(bad("methods", m, "each method listed once"));
        }
        if let Protocol::Realistic(e) = &self.protocol {
            e.validate()?;
        }
        let (i, n) = self.shard;
        if n == 0 || i >= n {
            return Err(bad("shard", format!("{i}/{n}"), "I/N with 0 <= I < N"));
        }
        if let Some(u) = &self.uncertainty {
            u.validate()?;
        }
        // The methods' settings are these with stages turned off: checking these covers them.
        self.params.validate()?;
        Template::cap(&self.template).map_err(crate::pipeline::ReconError::from)?;
        Ok(())
    }
}

impl Default for StudyConfig {
    fn default() -> Self {
        StudyConfig {
            levels: vec![1, 2, 3, 4, 5],
            runs: 10,
            methods: vec![StudyMethod::Srvf, StudyMethod::Icp, StudyMethod::IcpNormvec],
            seed: 1,
            threads: 1,
            shard: (0, 1),
            noise_px: 2.0,
            protocol: Protocol::Ideal,
            geometry: XrayGeometry::default(),
            template: TemplateParams::default(),
            params: ReconParams::default(),
            uncertainty: Some(UncertaintyParams::default()),
        }
    }
}

/// Every task of the study in its canonical order (method, level, run), then this shard's share.
pub fn tasks(cfg: &StudyConfig) -> Vec<Task> {
    let mut all = Vec::new();
    for &method in &cfg.methods {
        for &level in &cfg.levels {
            for run in 0..cfg.runs {
                all.push(Task {
                    method,
                    level,
                    run,
                    seed: run_seed(cfg.seed, level, run),
                });
            }
        }
    }
    let (i, n) = cfg.shard;
    all.into_iter()
        .enumerate()
        .filter(|(k, _)| k % n.max(1) == i)
        .map(|(_, t)| t)
        .collect()
}

/// A run kept for its pictures and mesh.
pub struct ExampleRun {
    /// The run.
    pub task: Task,
    /// Its simulated case.
    pub sim: SimCase,
    /// Its reconstruction.
    pub recon: Reconstruction,
}

/// Run one task. A failed reconstruction is a row with `converged = false` and the error.
pub fn run_one(
    truth: &Mesh,
    task: &Task,
    cfg: &StudyConfig,
    kernels: Kernels,
) -> (Row, Option<ExampleRun>) {
    match Prepared::new(truth, &cfg.geometry, &cfg.template) {
        Ok(prep) => run_prepared(&prep, task, cfg, kernels),
        Err(e) => (Row::failed(task, &e.to_string()), None),
    }
}

/// What every run of a study shares, computed once: the simulation set-up, the accuracy samples
/// on the truth and the truth prepared for `recon_mae_mm`.
pub(super) struct Prepared {
    pub(super) truth: Mesh,
    pub(super) setup: SimSetup,
    pub(super) template: Template,
    pub(super) samples: Vec<nalgebra::Point3<f64>>,
    interior: Option<InteriorQuery>,
    /// The truth's own (inclination, anteversion): the rim fit on its noise-free outlines and
    /// its sphere; None when they trace no rim.
    truth_orientation: Option<(f64, f64)>,
}

impl Prepared {
    /// Fails when the truth cannot be simulated at all (no sphere fits it, the views cannot
    /// project it): every run would fail alike.
    pub(super) fn new(
        truth: &Mesh,
        geometry: &XrayGeometry,
        template: &TemplateParams,
    ) -> Result<Prepared, SimError> {
        // The simulation set-up and the truth's rim fit beside the accuracy's samples and query.
        let (setup, (samples, interior)) = rayon::join(
            || -> Result<_, SimError> {
                let setup = SimSetup::new(truth, geometry)?;
                let orientation = NoiseLevel::level(0)
                    .and_then(|l| setup.case(0.0, &l, 0).ok())
                    .and_then(|exact| {
                        rim_orientation(&exact.cameras, &exact.observed, &exact.truth_sphere).ok()
                    })
                    .map(|o| (o.inclination_deg, o.anteversion_deg));
                Ok((setup, orientation))
            },
            || (accuracy_samples(truth), InteriorQuery::new(truth)),
        );
        let (setup, truth_orientation) = setup?;
        Ok(Prepared {
            template: Template::cap(template).map_err(crate::pipeline::ReconError::from)?,
            setup,
            truth: truth.clone(),
            samples,
            interior,
            truth_orientation,
        })
    }
}

fn run_prepared(
    prep: &Prepared,
    task: &Task,
    cfg: &StudyConfig,
    kernels: Kernels,
) -> (Row, Option<ExampleRun>) {
    let mut row = Row::failed(task, "");
    let Some(level) = NoiseLevel::level(task.level) else {
        row.error = format!("no noise level {}", task.level);
        return (row, None);
    };
    let sim = match &cfg.protocol {
        Protocol::Ideal => prep.setup.case(cfg.noise_px, &level, task.seed),
        Protocol::Realistic(e) => prep.setup.realistic_case(&prep.truth, e, &level, task.seed),
    };
    let sim = match sim {
        Ok(sim) => sim,
        Err(e) => {
            row.error = e.to_string();
            return (row, None);
        }
    };
    row.gt_cup_diameter_mm = sim.truth_sphere.diameter();
    let prm = task.method.params(&cfg.params);
    let start = std::time::Instant::now();
    let input = sim.input(&prep.template);
    let rec = match reconstruct(&input, &prm, kernels) {
        Ok(r) => r,
        Err(e) => {
            row.seconds = start.elapsed().as_secs_f64();
            row.error = e.to_string();
            return (row, None);
        }
    };
    row.seconds = start.elapsed().as_secs_f64();
    row.fill_accuracy(prep, &rec);
    row.fill_log(&rec);
    row.fill_cup(
        prep,
        &rec,
        input.observed,
        &prm,
        kernels,
        cfg.uncertainty.as_ref(),
        task.seed,
    );
    (
        row,
        Some(ExampleRun {
            task: *task,
            sim,
            recon: rec,
        }),
    )
}

impl Row {
    /// The result's accuracy against the truth's samples and interior (`prep`): its MAE and
    /// spread, the frame shift that best lays it on the truth and what is left after it, the
    /// depth offset along the views.
    fn fill_accuracy(&mut self, prep: &Prepared, rec: &Reconstruction) {
        let (acc, shifted) = accuracy_and_shift(&prep.samples, &rec.mesh);
        (self.frame_shift_mm, self.shifted_mae_mm) = (shifted.shift_mm(), shifted.mae_mm);
        [
            self.frame_shift_x_mm,
            self.frame_shift_y_mm,
            self.frame_shift_z_mm,
        ] = shifted.shift;
        self.depth_offset_mm = depth_offset_mm(&shifted.shift, &rec.log);
        self.mae_mm = acc.mae_mm;
        self.sd_mm = acc.sd_mm;
        self.p95_mm = acc.p95_mm;
        let interior = prep
            .interior
            .as_ref()
            .map_or_else(Vec::new, |q| q.distances(&rec.mesh));
        self.recon_mae_mm = DistanceStats::from(&interior).mean;
    }

    /// The result's spheres and what its log says: convergence, rounds, fallback, restart and
    /// guard, outline distance, largest pose correction.
    fn fill_log(&mut self, rec: &Reconstruction) {
        self.cup_diameter_mm = rec.sphere.diameter();
        self.surface_fit_diameter_mm = rec.surface_sphere.diameter();
        self.limb_diameter_mm = rec.log.limb_sphere.map_or(f64::NAN, |l| 2.0 * l[3]);
        self.converged = rec.log.converged;
        self.iterations = rec.log.gn_iterations;
        self.correspondence_updates = rec.log.correspondence_updates;
        self.fallback = rec.log.fallback.unwrap_or_default().to_string();
        self.restart = rec.log.restart.unwrap_or_default().to_string();
        self.restart_cause = rec
            .log
            .restart_cause
            .as_ref()
            .map_or_else(String::new, RestartCause::name);
        self.fallback_guard = rec
            .log
            .guard
            .as_ref()
            .map_or("", GuardFailure::name)
            .to_string();
        self.outline_px = rec.log.outline_px;
        if let Some(largest) = largest_pose_correction(&rec.log.pose_corrections) {
            (self.pose_turn_deg, self.pose_shift_mm) = (largest[0], largest[1]);
        }
    }

    /// The cup's uncertainty when the study resamples (`uncertainty`, seeded by the run's
    /// `seed`) and its orientation: the report's when the run resampled (it fits the same rim),
    /// else fitted here from the `observed` outlines; the orientation's error against the
    /// truth's (`prep`).
    #[allow(clippy::too_many_arguments)]
    fn fill_cup(
        &mut self,
        prep: &Prepared,
        rec: &Reconstruction,
        observed: &[Vec<Curve>],
        prm: &ReconParams,
        kernels: Kernels,
        uncertainty: Option<&UncertaintyParams>,
        seed: u64,
    ) {
        let mut orientation = None;
        if let Some(up) = uncertainty {
            let up = UncertaintyParams { seed, ..up.clone() };
            // A run whose resampling fails keeps its result; its uncertainty columns stay NaN.
            if let Ok(rep) = cup_report(rec, observed, prm, kernels, &up) {
                orientation = Some(rep.orientation.clone());
                let truth = prm
                    .cup
                    .catalogue
                    .nearest(self.gt_cup_diameter_mm)
                    .catalogue_mm;
                self.cup_sd_mm = rep.sd_mm;
                self.size_probability = rep.probability_of(rep.catalogue_mm);
                self.brier = rep.brier(truth);
            }
        }
        let orientation = orientation
            .unwrap_or_else(|| rim_orientation(&rec.cameras, observed, &rec.fitted_sphere).ok());
        if let Some(o) = orientation {
            self.inclination_deg = o.inclination_deg;
            self.anteversion_deg = o.anteversion_deg;
            if let Some((ti, ta)) = prep.truth_orientation {
                self.inclination_err_deg = o.inclination_deg - ti;
                self.anteversion_err_deg = o.anteversion_deg - ta;
            }
        }
    }
}

/// Run the tasks on `cfg.threads` threads. Rows come back in task order; `examples` receives the
/// first run of each method (the lowest level's run 0 in this shard). `tick` is called after
/// each run (progress). A truth that cannot be simulated at all is an error before any run.
pub fn run_study(
    truth: &Mesh,
    cfg: &StudyConfig,
    tick: &(dyn Fn() + Sync),
    kernels: Kernels,
) -> Result<(Vec<Row>, Vec<ExampleRun>), SimError> {
    let (rows, ex, ()) = study_with(truth, cfg, tick, kernels, |_| ())?;
    Ok((rows, ex))
}

/// The truth's cup sphere, and the sphere through its own outline-forming vertices: how far a
/// cup read from these outlines alone is off for this truth before any noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruthSpheres {
    /// The truth's cup diameter, mm.
    pub cup_mm: f64,
    /// The outline-forming vertices' sphere's diameter, mm (None when no sphere fits them).
    pub outline_mm: Option<f64>,
}

/// `run_study`, and the truth's spheres from the study's own set-up, found beside the runs.
pub fn run_study_and_truth(
    truth: &Mesh,
    cfg: &StudyConfig,
    tick: &(dyn Fn() + Sync),
    kernels: Kernels,
) -> Result<(Vec<Row>, Vec<ExampleRun>, TruthSpheres), SimError> {
    study_with(truth, cfg, tick, kernels, |prep| TruthSpheres {
        cup_mm: prep.setup.sphere.diameter(),
        outline_mm: prep.setup.outline_sphere(truth).ok().map(|o| o.diameter()),
    })
}

/// `run_study`, with `beside` run on the prepared truth beside the runs.
fn study_with<B: Send>(
    truth: &Mesh,
    cfg: &StudyConfig,
    tick: &(dyn Fn() + Sync),
    kernels: Kernels,
    beside: impl FnOnce(&Prepared) -> B + Send,
) -> Result<(Vec<Row>, Vec<ExampleRun>, B), SimError> {
    cfg.validate()?;
    let list = tasks(cfg);
    let prep = Prepared::new(truth, &cfg.geometry, &cfg.template)?;
    let first_of_method =
        |k: usize| list.iter().position(|t| t.method == list[k].method) == Some(k);
    let (done, b) = rayon::join(
        || {
            pool_map(cfg.threads, &list, |k, task| {
                // On the batched GPU the runs in flight advance in lock-step.
                let _lockstep = match kernels {
                    Kernels::Batched(b) => Some(b.run()),
                    _ => None,
                };
                let (row, ex) = run_prepared(&prep, task, cfg, kernels);
                tick();
                (row, ex.filter(|_| first_of_method(k)))
            })
        },
        || beside(&prep),
    );
    let mut rows = Vec::with_capacity(done.len());
    let mut ex = Vec::new();
    for (row, example) in done {
        rows.push(row);
        ex.extend(example);
    }
    ex.sort_by_key(|e| e.task.method);
    Ok((rows, ex, b))
}

/// The result's translation to the truth `shift` along its depth axis, as it was before the
/// depth offset it was given (moving a result moves its translation to the truth by as much);
/// NaN without an axis.
fn depth_offset_mm(shift: &[f64; 3], log: &crate::pipeline::SolveLog) -> f64 {
    log.depth_axis
        .map(nalgebra::Vector3::from)
        .map_or(f64::NAN, |a| {
            nalgebra::Vector3::from(*shift).dot(&a) + log.depth_moved_mm * a.norm_squared()
        })
}

/// The largest turn (degrees) and the largest shift (mm) any view's pose correction has, each
/// over the views on its own; None when no pose was refined.
fn largest_pose_correction(corrections: &[[f64; 2]]) -> Option<[f64; 2]> {
    corrections
        .iter()
        .copied()
        .reduce(|a, b| [a[0].max(b[0]), a[1].max(b[1])])
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn a_study_that_cannot_run_is_refused_before_any_run() {
        assert!(StudyConfig::default().validate().is_ok());
        let field = |cfg: StudyConfig| match cfg.validate() {
            Err(SimError::Setting { field, .. }) => field,
            Err(SimError::Params(_)) => "params",
            other => panic!("expected a setting error, got {other:?}"),
        };
        for noise in [f64::NAN, f64::INFINITY, -2.0] {
            let cfg = StudyConfig {
                noise_px: noise,
                ..Default::default()
            };
            assert_eq!(field(cfg), "noise_px");
        }
        let level6 = StudyConfig {
            levels: vec![1, 6],
            ..Default::default()
        };
        assert_eq!(field(level6), "levels");
        let level_twice = StudyConfig {
            levels: vec![1, 3, 1],
            ..Default::default()
        };
        assert_eq!(field(level_twice), "levels");
        let method_twice = StudyConfig {
            methods: vec![StudyMethod::Icp, StudyMethod::Srvf, StudyMethod::Icp],
            ..Default::default()
        };
        assert_eq!(field(method_twice), "methods");
        let shard = StudyConfig {
            shard: (2, 2),
            ..Default::default()
        };
        assert_eq!(field(shard), "shard");
        let realistic = StudyConfig {
            protocol: Protocol::Realistic(crate::sim::RealisticErrors {
                left_out: 0.9,
                ..Default::default()
            }),
            ..Default::default()
        };
        assert_eq!(field(realistic), "realistic left_out");
        let mut params = StudyConfig::default();
        params.params.placement.limb_scale_mm = f64::NAN;
        assert_eq!(field(params), "params");
        // One resample has no spread; the command line and Python take 2 to 1000.
        let one_resample = StudyConfig {
            uncertainty: Some(UncertaintyParams {
                samples: 1,
                ..Default::default()
            }),
            ..Default::default()
        };
        assert_eq!(field(one_resample), "params");
        // The runner refuses it too, before any run (no tick).
        let truth = crate::sim::phantom(&Default::default()).mesh;
        let bad = StudyConfig {
            noise_px: f64::INFINITY,
            ..Default::default()
        };
        let ticks = AtomicUsize::new(0);
        let tick = || {
            ticks.fetch_add(1, Ordering::Relaxed);
        };
        assert!(run_study(&truth, &bad, &tick, Kernels::Cpu).is_err());
        assert_eq!(ticks.load(Ordering::Relaxed), 0);
        // Companion: level 0, no noise and an empty study are allowed.
        let edge = StudyConfig {
            levels: vec![0],
            noise_px: 0.0,
            runs: 0,
            ..Default::default()
        };
        assert!(edge.validate().is_ok());
    }

    /// The truth's spheres are those of the study's own set-up, equal to a set-up made apart
    /// from it. Companion: the truth scaled by 1.1 gives another cup.
    #[test]
    fn the_truth_spheres_come_from_the_studys_own_set_up() {
        let truth = crate::sim::phantom(&Default::default()).mesh;
        let cfg = StudyConfig {
            levels: vec![1],
            runs: 0,
            ..Default::default()
        };
        let spheres = |t: &Mesh| {
            run_study_and_truth(t, &cfg, &|| {}, Kernels::Cpu)
                .unwrap()
                .2
        };
        let got = spheres(&truth);
        let apart = SimSetup::new(&truth, &cfg.geometry).unwrap();
        assert_eq!(got.cup_mm, apart.sphere.diameter());
        assert_eq!(
            got.outline_mm,
            apart.outline_sphere(&truth).ok().map(|o| o.diameter())
        );
        assert!(got.outline_mm.is_some());
        let mut bigger = truth.clone();
        for v in &mut bigger.vertices {
            *v = nalgebra::Point3::from(v.coords * 1.1);
        }
        assert!((spheres(&bigger).cup_mm - got.cup_mm * 1.1).abs() < 1e-6 * got.cup_mm);
    }

    #[test]
    fn shards_partition_the_tasks_and_seeds_ignore_the_method() {
        let cfg = StudyConfig {
            runs: 3,
            levels: vec![1, 4],
            ..Default::default()
        };
        let all = tasks(&cfg);
        assert_eq!(all.len(), 18);
        let mut joined: Vec<Task> = (0..4)
            .flat_map(|i| {
                tasks(&StudyConfig {
                    shard: (i, 4),
                    ..cfg.clone()
                })
            })
            .collect();
        joined.sort_by_key(|t| (t.method, t.level, t.run));
        assert_eq!(joined, all);
        let srvf = all
            .iter()
            .find(|t| t.method == StudyMethod::Srvf && t.level == 4 && t.run == 2)
            .unwrap();
        let icp = all
            .iter()
            .find(|t| t.method == StudyMethod::Icp && t.level == 4 && t.run == 2)
            .unwrap();
        assert_eq!(srvf.seed, icp.seed);
        assert_ne!(run_seed(1, 4, 2), run_seed(1, 4, 1));
        assert_ne!(run_seed(1, 4, 2), run_seed(2, 4, 2));
    }

    /// The largest turn and the largest shift are each taken over the views on their own (the
    /// reference view's zero correction included); companion: no refinement gives none, not
    /// zeros.
    #[test]
    fn the_largest_pose_correction_takes_turn_and_shift_apart() {
        let c = [[0.0, 0.0], [6.6, 2.0], [1.5, 14.3]];
        assert_eq!(largest_pose_correction(&c), Some([6.6, 14.3]));
        assert_ne!(largest_pose_correction(&c), Some([1.5, 14.3]));
        assert_eq!(largest_pose_correction(&[]), None);
    }
}
