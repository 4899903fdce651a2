//! `acetab bench`: each kernel on its CPU twin and on the GPU at several sizes, and the study's
//! throughput on both backends. Times are medians of repeated calls, including upload and
//! read-back on the GPU side (what a caller pays). On lavapipe the "GPU" is the CPU, so the
//! ratios show dispatch overhead and batching, not GPU speed.

use crate::correspond::srvf::{coprime_steps, srvf, Anchor, BandProblem};
use crate::engine::cpu::{
    deform as cdeform, project as cproject, silhouette as csil, srvf_band as cband, srvf_dp as cdp,
};
use crate::engine::gpu::{Gpu, GpuError};
use crate::engine::Kernels;
use crate::sim::{phantom, PhantomParams};
use crate::sim::{simulated_views, XrayGeometry};
use crate::solve::{DeformationGraph, GraphParams};
use crate::study::{run_study, StudyConfig, StudyMethod};
use crate::template::hemisphere;
use nalgebra::{Point2, Point3, Vector2};
use std::time::Instant;

/// One line of the table.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchRow {
    /// The kernel.
    pub kernel: String,
    /// The problem size.
    pub size: String,
    /// The CPU twin's median, ms.
    pub cpu_ms: f64,
    /// The GPU's median, ms.
    pub gpu_ms: f64,
    /// cpu_ms / gpu_ms (above 1: the GPU path is faster).
    pub ratio: f64,
}

/// Study throughput on one backend.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Throughput {
    /// Where the kernels ran.
    pub backend: String,
    /// Runs in flight at once (the study's threads; on the GPU also the batcher's lanes).
    pub batch: usize,
    /// Kernel requests per dispatch on the GPU with runs batched (the mean merge), or None.
    pub requests_per_dispatch: Option<f64>,
    /// Seconds the runs waited for the device (batched GPU only), or None.
    pub device_seconds: Option<f64>,
    /// Runs.
    pub runs: usize,
    /// Seconds.
    pub seconds: f64,
    /// Runs per second.
    pub runs_per_second: f64,
}

/// What `acetab bench` measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchReport {
    /// The adapter.
    pub adapter: String,
    /// Each kernel against its twin.
    pub kernels: Vec<BenchRow>,
    /// Study throughput per backend.
    pub study: Vec<Throughput>,
}

/// What to measure.
#[derive(Clone, Debug)]
pub struct BenchParams {
    /// Template sizes (vertices) for deform, project and silhouette.
    pub mesh_sizes: Vec<usize>,
    /// DP batch sizes (problems of `dp_samples` samples).
    pub dp_batches: Vec<usize>,
    /// Samples per DP problem.
    pub dp_samples: usize,
    /// Study runs per backend (phantom, srvf, level 3); 0 skips the study.
    pub study_runs: usize,
    /// Worker threads of the study.
    pub threads: usize,
    /// Batch sizes (runs in flight) of the study on both backends, the GPU's requests merged
    /// (default 1, 8, 32, 128); empty: one, at `threads`.
    pub study_batches: Vec<usize>,
    /// Repetitions per timing (the median is reported).
    pub repeats: usize,
    /// Time the batched GPU study with its SRVF DPs on the host.
    pub dp_host: bool,
    /// Time the batched GPU study with its SRVF DPs on the device.
    pub dp_device: bool,
}

impl Default for BenchParams {
    fn default() -> Self {
        BenchParams {
            mesh_sizes: vec![1_000, 10_000, 100_000],
            dp_batches: vec![1, 16, 256, 1024],
            dp_samples: 64,
            study_runs: 6,
            threads: 2,
            study_batches: vec![1, 8, 32, 128],
            repeats: 5,
            dp_host: true,
            dp_device: true,
        }
    }
}

/// The median of `repeats` timings of `f` in milliseconds, after one warm-up call.
fn median_ms(repeats: usize, mut f: impl FnMut() -> Result<(), GpuError>) -> Result<f64, GpuError> {
    f()?; // warm-up: pipelines, pools, caches
    let mut t: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            let s = Instant::now();
            f().map(|_| s.elapsed().as_secs_f64() * 1e3)
        })
        .collect::<Result<_, _>>()?;
    t.sort_by(f64::total_cmp);
    Ok(t[t.len() / 2])
}

/// One kernel's row: its CPU twin and its GPU kernel each timed (`median_ms`).
fn timed_row(
    repeats: usize,
    kernel: &str,
    size: String,
    mut cpu: impl FnMut(),
    gpu: impl FnMut() -> Result<(), GpuError>,
) -> Result<BenchRow, GpuError> {
    let cpu_ms = median_ms(repeats, || {
        cpu();
        Ok(())
    })?;
    let gpu_ms = median_ms(repeats, gpu)?;
    Ok(BenchRow {
        kernel: kernel.into(),
        size,
        cpu_ms,
        gpu_ms,
        ratio: cpu_ms / gpu_ms.max(1e-9),
    })
}

/// Why the bench stopped.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BenchError {
    /// A kernel failed on the device (or its batch was refused).
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// The study on the phantom could not run.
    #[error("the study on the phantom: {0}")]
    Study(#[from] crate::sim::SimError),
}

/// Run every measurement; `progress` gets one line per finished row.
pub fn run_bench(
    gpu: &Gpu,
    adapter: &str,
    p: &BenchParams,
    progress: &dyn Fn(&str),
) -> Result<BenchReport, BenchError> {
    let mut rows = Vec::new();
    for &nv in &p.mesh_sizes {
        rows.extend(mesh_kernel_rows(gpu, p, nv, progress)?);
    }
    rows.extend(dp_rows(gpu, p, progress)?);
    rows.extend(band_rows(gpu, p, progress)?);
    let study = if p.study_runs > 0 {
        study_throughput(gpu, p, progress)?
    } else {
        Vec::new()
    };
    Ok(BenchReport {
        adapter: adapter.into(),
        kernels: rows,
        study,
    })
}

/// The deformation, projection and silhouette kernels on a hemisphere of about `nv` vertices.
fn mesh_kernel_rows(
    gpu: &Gpu,
    p: &BenchParams,
    nv: usize,
    progress: &dyn Fn(&str),
) -> Result<Vec<BenchRow>, BenchError> {
    let mut rows = Vec::new();
    let mesh = hemisphere(26.0, nv);
    let graph = DeformationGraph::new(&mesh, &GraphParams::default());
    let mut x = graph.identity();
    for (k, v) in x.iter_mut().enumerate() {
        *v += 0.01 * ((k % 7) as f64 - 3.0);
    }
    let batch = cdeform::DeformBatch::from_graphs(&[(&graph, &x)]).map_err(GpuError::from)?;
    let size = format!("{} vertices", mesh.vertex_count());
    rows.push(timed_row(
        p.repeats,
        "deform",
        size.clone(),
        || {
            std::hint::black_box(cdeform::deform(&batch));
        },
        || gpu.deform(&batch).map(|_| ()),
    )?);
    progress(&format!("deform {size}"));

    let verts: Vec<[f32; 4]> = mesh
        .vertices
        .iter()
        .map(|q| [q.x as f32, q.y as f32, q.z as f32, 0.0])
        .collect();
    let cams = simulated_views(&XrayGeometry::default(), &Point3::origin());
    let views: Vec<cproject::ViewRows> = cams.iter().map(cproject::ViewRows::from_camera).collect();
    rows.push(timed_row(
        p.repeats,
        "project",
        format!("{size} x 3 views"),
        || {
            std::hint::black_box(cproject::project(&verts, verts.len(), &views));
        },
        || gpu.project(&verts, verts.len(), &views).map(|_| ()),
    )?);
    progress(&format!("project {size}"));

    let tris: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let proj = cproject::project(&verts, verts.len(), &views[..1]);
    let window = csil::Window::around(&proj, 512).ok_or(GpuError::Input {
        kernel: "silhouette",
        message: "nothing in front of the source".into(),
    })?;
    rows.push(timed_row(
        p.repeats,
        "silhouette",
        format!("{size}, 512^2 texels"),
        || {
            let ids = csil::rasterise(&proj, &tris, &window);
            std::hint::black_box(csil::trace(&csil::edges(&ids, window.size), window.size));
        },
        || {
            gpu.silhouette_of_projected(&proj, &tris, &window)
                .map(|_| ())
        },
    )?);
    progress(&format!("silhouette {size}"));
    Ok(rows)
}

/// The SRVFs of one alignment problem's two curves.
type SrvfPair = (Vec<Vector2<f64>>, Vec<Vector2<f64>>);

/// `count` alignment problems: `samples` points of a sine wave over 3 units against a second
/// wave a little faster (by 0.01 per problem) and shifted in phase.
fn sine_pairs(count: usize, samples: usize) -> Vec<SrvfPair> {
    let wave = |f: f64, ph: f64| -> Vec<Point2<f64>> {
        (0..samples)
            .map(|i| {
                let u = i as f64 / (samples - 1) as f64 * 3.0;
                Point2::new(u, (f * u + ph).sin())
            })
            .collect()
    };
    (0..count)
        .map(|k| {
            (
                srvf(&wave(2.0, 0.0), false),
                srvf(&wave(2.0 + 0.01 * k as f64, 0.3), false),
            )
        })
        .collect()
}

/// The full SRVF DP tables, batches of `p.dp_batches` problems of `p.dp_samples` samples.
fn dp_rows(
    gpu: &Gpu,
    p: &BenchParams,
    progress: &dyn Fn(&str),
) -> Result<Vec<BenchRow>, BenchError> {
    let steps = coprime_steps(5);
    let n = p.dp_samples.max(8);
    let curves = sine_pairs(p.dp_batches.iter().copied().max().unwrap_or(0), n);
    let mut rows = Vec::new();
    for &bsz in &p.dp_batches {
        let pairs: Vec<_> = curves[..bsz]
            .iter()
            .map(|(a, b)| (&a[..], &b[..]))
            .collect();
        let batch = cdp::DpBatch::new(&pairs, &steps).map_err(GpuError::from)?;
        rows.push(timed_row(
            p.repeats,
            "srvf_dp",
            format!("{bsz} problems, T = {n}"),
            || {
                std::hint::black_box(cdp::dp_tables(&batch));
            },
            || gpu.srvf_dp_tables(&batch).map(|_| ()),
        )?);
        progress(&format!("srvf_dp {bsz}"));
    }
    Ok(rows)
}

/// The study's own DP: T = 200 samples, a band of +-6 cells about a gently bent path, the
/// position term (weight 3), as `srvf_band` runs it for a study's alignments.
fn band_rows(
    gpu: &Gpu,
    p: &BenchParams,
    progress: &dyn Fn(&str),
) -> Result<Vec<BenchRow>, BenchError> {
    let steps = coprime_steps(5);
    let t = 200;
    let band = sine_pairs(p.dp_batches.iter().copied().max().unwrap_or(0), t);
    let (mut lo, mut hi) = (vec![0usize; t], vec![0usize; t]);
    for i in 1..t {
        let c = i as f64 + 3.0 * (i as f64 * std::f64::consts::PI / (t - 1) as f64).sin();
        lo[i] = ((c - 6.0).floor().max(1.0) as usize).min(t - 1);
        hi[i] = ((c + 6.0).ceil() as usize).clamp(lo[i], t - 1);
    }
    hi[t - 1] = t - 1;
    let mut rows = Vec::new();
    for &bsz in &p.dp_batches {
        let problems: Vec<BandProblem> = band[..bsz]
            .iter()
            .map(|(a, b)| BandProblem {
                q1: a,
                q2: b,
                steps: &steps,
                lo: &lo,
                hi: &hi,
                anchor: Some(Anchor {
                    a: b,
                    b: a,
                    weight: 3.0,
                }),
            })
            .collect();
        let batch = cband::BandBatch::new(&problems).map_err(GpuError::from)?;
        rows.push(timed_row(
            p.repeats,
            "srvf_band",
            format!("{bsz} problems, T = {t}, band +-6"),
            || {
                std::hint::black_box(cband::band_tables(&batch));
            },
            || gpu.srvf_band_tables(&batch).map(|_| ()),
        )?);
        progress(&format!("srvf_band {bsz}"));
    }
    Ok(rows)
}

/// Whole studies' throughput (srvf, level 3, the phantom): on the CPU and the GPU with the
/// study's threads, then per batch of runs in flight on the CPU and on the GPU with the runs
/// batched (their SRVF DPs on the host and on the device, as asked).
fn study_throughput(
    gpu: &Gpu,
    p: &BenchParams,
    progress: &dyn Fn(&str),
) -> Result<Vec<Throughput>, BenchError> {
    let mut study = Vec::new();
    let truth = phantom(&PhantomParams::default()).mesh;
    let cfg = StudyConfig {
        levels: vec![3],
        runs: p.study_runs,
        methods: vec![StudyMethod::Srvf],
        threads: p.threads.max(1),
        // The reconstructions alone, as the bench has always timed them.
        uncertainty: None,
        ..Default::default()
    };
    let timed = |cfg: &StudyConfig, kernels: Kernels| -> Result<(usize, f64), BenchError> {
        let s = Instant::now();
        let (rows, _) = run_study(&truth, cfg, &|| {}, kernels)?;
        Ok((rows.len(), s.elapsed().as_secs_f64()))
    };
    let through = |backend: &str, batch, (runs, seconds): (usize, f64)| Throughput {
        backend: backend.into(),
        batch,
        requests_per_dispatch: None,
        device_seconds: None,
        runs,
        seconds,
        runs_per_second: runs as f64 / seconds,
    };
    for kernels in [Kernels::Cpu, Kernels::Gpu(gpu)] {
        study.push(through(kernels.name(), cfg.threads, timed(&cfg, kernels)?));
        progress(&format!("study on {}", kernels.name()));
    }
    let batches = if p.study_batches.is_empty() {
        vec![cfg.threads]
    } else {
        p.study_batches.clone()
    };
    for b in batches {
        // b runs in flight: on the CPU b threads; on the GPU also their requests merged b
        // at a time.
        let cfg = StudyConfig {
            threads: b.max(1),
            runs: p.study_runs.max(b),
            ..cfg.clone()
        };
        study.push(through("cpu", cfg.threads, timed(&cfg, Kernels::Cpu)?));
        progress(&format!("study on the cpu, batch {b}"));
        for (wanted, on_device, label) in [
            (p.dp_host, false, "gpu, runs batched"),
            (p.dp_device, true, "gpu, runs batched, DP on the device"),
        ] {
            if !wanted {
                continue;
            }
            let batcher = crate::engine::gpu::GpuBatcher::new(
                gpu,
                cfg.threads,
                crate::engine::gpu::batcher::STUDY_WAIT,
            )
            .with_dp_on_device(on_device);
            let mut t = through(label, cfg.threads, timed(&cfg, Kernels::Batched(&batcher))?);
            let all = batcher.stats().total();
            t.requests_per_dispatch =
                (all.dispatches > 0).then(|| all.requests as f64 / all.dispatches as f64);
            t.device_seconds = Some(all.device_seconds);
            study.push(t);
            progress(&format!("study on the {label}, batch {b}"));
        }
    }
    Ok(study)
}
