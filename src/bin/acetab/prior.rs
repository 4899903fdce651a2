//! `acetab prior build`: learn the population shape prior from acetabula whose surfaces are
//! known (see `acetab::prior`); `--prior` on demo, simulate and reconstruct uses it.

use crate::common::mesh_files;
use acetab::prior::{PriorFile, PriorMesh, DEFAULT_MODES, MAX_MODES};
use acetab::study::population::mesh_name;
use std::path::PathBuf;
use std::sync::Arc;

#[derive(clap::Args)]
pub struct PriorArgs {
    #[command(subcommand)]
    pub command: PriorCommand,
}

#[derive(clap::Subcommand)]
pub enum PriorCommand {
    /// Learn a prior from acetabulum meshes (STL/PLY/OBJ in body axes, mm; a closed shell is
    /// reduced to its outer side) or folders of them. A subject is a file's name up to the first
    /// '_' (both hips of one person leave a leave-one-subject-out study together).
    Build(BuildArgs),
}

#[derive(clap::Args)]
pub struct BuildArgs {
    /// The training meshes, or folders of them.
    #[arg(required = true)]
    pub meshes: Vec<PathBuf>,
    /// Principal modes the prior carries (0 to 8).
    #[arg(long, default_value_t = DEFAULT_MODES, value_parser = crate::common::count_in(0, MAX_MODES))]
    pub modes: usize,
    /// What the meshes are, for people reading the file (their source and licence).
    #[arg(long)]
    pub note: Option<String>,
    /// Where the prior is written (JSON).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: PriorArgs) -> Result<(), String> {
    match args.command {
        PriorCommand::Build(b) => build(b),
    }
}

fn build(args: BuildArgs) -> Result<(), String> {
    crate::common::check_out_file(&args.out)?;
    let files = mesh_files(&args.meshes, "")?;
    let mut meshes = Vec::new();
    for f in &files {
        // The mesh's own name before the reason (this command has no --gt).
        let truth = acetab::sim::load_truth(&f.to_string_lossy()).map_err(|e| {
            if e.reason.contains(&e.gt) {
                e.reason
            } else {
                format!("{}: {}", e.gt, e.reason)
            }
        })?;
        let name = mesh_name(f);
        if meshes.iter().any(|m: &PriorMesh| m.name == name) {
            return Err(format!("{}: two meshes are named {name:?}", f.display()));
        }
        let subject = crate::calibrate::subject_of(f);
        meshes.push(
            PriorMesh::of(&name, &subject, &truth).map_err(|e| format!("{}: {e}", f.display()))?,
        );
    }
    let note = args
        .note
        .unwrap_or_else(|| format!("{} meshes given to `acetab prior build`", meshes.len()));
    let file = PriorFile::new(meshes, args.modes, note);
    let prior = file.prior().map_err(|e| match e {
        // The meshes given are what falls short, not the output.
        acetab::prior::PriorFileError::Learn {
            source: source @ acetab::prior::PriorError::TooFewMeshes { .. },
            ..
        } => format!("the meshes given: {source} (give more, or fewer --modes)"),
        e => format!("--out {}: {e}", args.out.display()),
    })?;
    crate::common::write_out_file(&args.out, file.to_json().as_bytes())?;
    println!(
        "prior of {} meshes ({} subjects), {} mode(s) (SD {}) -> {}",
        file.meshes.len(),
        file.subjects().len(),
        prior.mode_count(),
        prior
            .mode_sd
            .iter()
            .map(|s| format!("{s:.3}"))
            .collect::<Vec<_>>()
            .join(", "),
        args.out.display()
    );
    Ok(())
}

/// `--prior`: "none", "default" or a prior file (see `acetab::prior::choose_prior`); with
/// `leave_out`, the prior learned without that subject's meshes.
pub fn choose(
    arg: &str,
    leave_out: Option<&str>,
) -> Result<(Option<Arc<acetab::prior::ShapePrior>>, String), String> {
    let (p, what) = acetab::prior::choose_prior(arg, leave_out).map_err(|e| match e {
        acetab::prior::PriorFileError::NothingToLeaveOut(_) => {
            "--prior-leave-out needs a prior (--prior default or a file)".to_string()
        }
        e => format!("--prior {e}"),
    })?;
    Ok((p.map(Arc::new), what))
}
