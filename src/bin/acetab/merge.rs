//! `acetab merge`: join the runs of several `acetab simulate --shard` folders.

use crate::common::{io_msg, print_summary_as};
use acetab::io::fill_dir_atomically;
use acetab::study::{check_complete, merge_dirs, merge_meta, write_tables};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct MergeArgs {
    /// The shard folders (`acetab simulate --shard I/N --out DIR`), every shard of one study.
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Where the merged study is written (a new folder; not one of the shards).
    #[arg(long)]
    pub out: PathBuf,
    /// Write into an --out that is not empty (same-named files are replaced, others stay).
    #[arg(long)]
    pub force: bool,
    /// Print the merged summary (summary.json's `summary`) as one JSON line instead of the table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: MergeArgs) -> Result<(), String> {
    let MergeArgs {
        dirs,
        out,
        force,
        json,
    } = args;
    // Merging into one of the shards would overwrite the shard's own tables.
    let same = |d: &PathBuf| match (d.canonicalize(), out.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if let Some(d) = dirs.iter().find(|d| same(d)) {
        return Err(format!(
            "--out {}: is the shard folder {} being merged; choose another folder",
            out.display(),
            d.display()
        ));
    }
    crate::common::check_out(&out, force)?;
    let rows = merge_dirs(&dirs).map_err(|e| e.to_string())?;
    let meta = merge_meta(&dirs).map_err(|e| e.to_string())?;
    check_complete(&rows, &meta).map_err(|e| e.to_string())?;
    fill_dir_atomically(
        &out,
        |d| {
            for w in write_tables(&rows, d, &meta).map_err(|e| e.to_string())? {
                eprintln!("acetab: warning: {w}");
            }
            Ok(())
        },
        io_msg,
    )
    .map_err(|e| crate::common::unstage(&e, &out))?;
    eprintln!("{} runs merged into {}", rows.len(), out.display());
    print_summary_as(&rows, json)
}
