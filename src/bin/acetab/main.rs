//! The `acetab` command line: parses arguments and calls the library, one module a subcommand.

mod align;
mod bench;
mod calibrate;
mod common;
mod demo;
mod merge;
mod plan_views;
mod pose_study;
mod prior;
mod reconstruct;
mod simulate;

use clap::{Parser, Subcommand};
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
    Demo(demo::DemoArgs),
    /// The simulation study: levels x runs x methods on a ground-truth surface.
    Simulate(Box<simulate::SimulateArgs>),
    /// Join the runs of several `acetab simulate --shard` folders.
    Merge(merge::MergeArgs),
    /// SRVF elastic alignment of two curves (CSV files of x,y; header optional).
    Align(align::AlignArgs),
    /// Each GPU kernel against its CPU twin at several sizes, and the study's throughput on both
    /// backends (needs a GPU adapter; lavapipe counts).
    Bench(bench::BenchArgs),
    /// Pose refinement in simulation: cases whose oblique views' poses are off by --deg and
    /// --mm, reconstructed with and without the per-view pose refinement.
    PoseStudy(pose_study::PoseStudyArgs),
    /// Reconstruct a case file.
    Reconstruct(reconstruct::ReconstructArgs),
    /// Learn the cup uncertainty's model-error SD from studies whose truths are known.
    Calibrate(calibrate::CalibrateArgs),
    /// View planning: the cup's accuracy per set of views, from population sweeps of the same
    /// acetabula made with different --views (leave-one-subject-out corrections).
    PlanViews(plan_views::PlanViewsArgs),
    /// The population shape prior: `acetab prior build MESH... --out prior.json`.
    Prior(prior::PriorArgs),
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Simulate(a) => simulate::run(*a),
        Command::Merge(a) => merge::run(a),
        Command::Align(a) => align::run(a),
        Command::Bench(a) => bench::run(a),
        Command::PoseStudy(a) => pose_study::run(a),
        Command::Reconstruct(a) => reconstruct::run(a),
        Command::Calibrate(a) => calibrate::run(a),
        Command::Prior(a) => prior::run(a),
        Command::PlanViews(a) => plan_views::run(a),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Printable whatever a message quotes (a file's bytes: `io::printable`).
            eprintln!("acetab: error: {}", acetab::io::printable(&e.to_string()));
            ExitCode::FAILURE
        }
    }
}
