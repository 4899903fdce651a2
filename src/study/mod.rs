//! The simulation study: for each method, noise level and run, simulate three X-rays of a ground
//! truth, reconstruct, and measure. Every run has its own seed derived from the study seed, the
//! level and the run number (not the method, so all methods see the same simulated case), so any
//! run can be repeated alone, and results do not depend on thread count or sharding.

pub mod bench;
pub mod compare;
pub mod cup_spread;
mod error;
pub mod frame_shift;
mod merge;
mod method;
mod outputs;
pub mod population;
pub mod pose;
mod runner;
mod runs_csv;
mod summary;
mod task;
pub mod view_plan;

pub use error::StudyError;
pub use merge::{check_complete, merge_dirs, merge_meta};
pub use method::StudyMethod;
pub use outputs::{write_examples, write_tables};
pub use runner::{
    run_one, run_study, run_study_and_truth, tasks, ExampleRun, StudyConfig, TruthSpheres,
};
pub use runs_csv::{read_csv, write_csv, Row};
pub use summary::{summarize, Summary};
pub use task::{run_seed, Task};
