//! What goes wrong with study files: runs.csv and summary.json read, written and merged.

use std::path::PathBuf;

/// Problems with study files.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StudyError {
    /// A study file cannot be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A study file cannot be written.
    #[error("{path}: cannot write: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A runs.csv line that is not a run.
    #[error("{path}: line {line}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The line (1 is the header).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// Two shards of different studies.
    #[error("{path}: study field {field:?} is {value}, but {first} has {expected}: not shards of one study")]
    Mismatch {
        /// The shard.
        path: PathBuf,
        /// The study setting that differs.
        field: String,
        /// Its value there.
        value: String,
        /// The first shard.
        first: PathBuf,
        /// Its value in the first shard.
        expected: String,
    },
    /// The same run in two shards.
    #[error("run {method} level {level} run {run} appears in more than one shard ({path})")]
    Duplicate {
        /// The run's method.
        method: String,
        /// Its level.
        level: u32,
        /// Its number.
        run: usize,
        /// The second shard.
        path: PathBuf,
    },
    /// The shards given are not the whole set their summary.json files name.
    #[error("shards {missing} of {count} are missing (the folders given hold {present}); merge every shard of the study")]
    ShardGap {
        /// The missing shard indices, as "I/N" joined by commas.
        missing: String,
        /// The shard count N.
        count: usize,
        /// The shards present.
        present: String,
    },
    /// The shards hold fewer runs than their study's settings make (a shard whose runs were
    /// lost or cut short).
    #[error("the shards hold {held} of the study's {expected} runs (levels x runs x methods in summary.json); missing: {first}; run the shards again")]
    Incomplete {
        /// Runs the shards hold.
        held: usize,
        /// Runs the study makes.
        expected: usize,
        /// The first missing runs, named.
        first: String,
    },
}
