//! `acetab bench`: each GPU kernel against its CPU twin at several sizes, and the study's
//! throughput on both backends (needs a GPU adapter; lavapipe counts).

use crate::common::{count_in, sizes, Sizes, MAX_RUNS, MAX_THREADS};
use acetab::engine::gpu::GpuDevice;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Print the report as one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Study runs per backend (0 skips the study).
    #[arg(long, default_value_t = 6, value_parser = count_in(0, MAX_RUNS))]
    pub study_runs: usize,
    /// Repetitions per timing (the median is reported).
    #[arg(long, default_value_t = 5, value_parser = count_in(1, 1000))]
    pub repeats: usize,
    /// A quick pass (one small mesh, DP batches of 1 and 4): checks the bench runs, not speed.
    #[arg(long)]
    pub quick: bool,
    /// Template sizes (vertices) for the deform, project and silhouette kernels (default
    /// 1000,10000,100000).
    #[arg(long, value_parser = sizes)]
    pub mesh_sizes: Option<Sizes>,
    /// SRVF DP batch sizes, problems per dispatch (default 1,16,256,1024).
    #[arg(long, value_parser = sizes)]
    pub dp_batches: Option<Sizes>,
    /// Worker threads of the study part (default 2).
    #[arg(long, default_value_t = 2, value_parser = count_in(1, MAX_THREADS))]
    pub threads: usize,
    /// Batch sizes of the study on both backends: runs in flight at once (threads), on the GPU
    /// their kernel requests merged (default 1,8,32,128; --quick: 1,2).
    #[arg(long, value_parser = sizes)]
    pub study_batches: Option<Sizes>,
    /// Where the batched GPU study's SRVF DPs run: host, device, both (a row each), or auto
    /// (both, but on a CPU adapter such as lavapipe only the host: there the device DPs take
    /// 13-15x as long and a default bench would run for many minutes).
    #[arg(long, value_enum, default_value_t = BenchDp::Auto)]
    pub dp: BenchDp,
}

/// `acetab bench --dp`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchDp {
    /// The DPs on the host.
    Host,
    /// The DPs on the device.
    Device,
    /// A row each.
    Both,
    /// Both, or the host alone on a CPU adapter.
    Auto,
}

pub fn run(args: BenchArgs) -> Result<(), String> {
    let BenchArgs {
        json,
        study_runs,
        repeats,
        quick,
        mesh_sizes,
        dp_batches,
        threads,
        study_batches,
        dp,
    } = args;
    let dev = GpuDevice::from_env().map_err(|e| format!("acetab bench: {e}"))?;
    let gpu = dev.engine().map_err(|e| e.to_string())?;
    let (dp_host, dp_device) = match dp {
        BenchDp::Host => (true, false),
        BenchDp::Device => (false, true),
        BenchDp::Both => (true, true),
        BenchDp::Auto => (true, !dev.is_software()),
    };
    let mut prm = acetab::study::bench::BenchParams {
        study_runs,
        repeats,
        threads,
        dp_host,
        dp_device,
        ..Default::default()
    };
    if quick {
        prm.mesh_sizes = vec![500];
        prm.dp_batches = vec![1, 4];
        prm.study_batches = vec![1, 2];
    }
    if let Some(m) = mesh_sizes {
        prm.mesh_sizes = m.0;
    }
    if let Some(d) = dp_batches {
        prm.dp_batches = d.0;
    }
    if let Some(b) = study_batches {
        prm.study_batches = b.0;
    }
    let report = acetab::study::bench::run_bench(&gpu, &dev.describe(), &prm, &|s| {
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
            let merged = match (s.requests_per_dispatch, s.device_seconds) {
                (Some(m), Some(d)) => {
                    format!(", {m:.2} requests per dispatch, {d:.2} s waiting for the device")
                }
                _ => String::new(),
            };
            println!(
                "study ({} runs, phantom, srvf, level 3) on {}, batch {}: {:.2} runs/s ({:.1} s{merged})",
                s.runs, s.backend, s.batch, s.runs_per_second, s.seconds
            );
        }
    }
    Ok(())
}
