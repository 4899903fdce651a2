//! One run of a study, and the seed it gets: what the runner runs and each table row records.

use super::method::StudyMethod;

/// One run to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Task {
    /// The method.
    pub method: StudyMethod,
    /// The start's noise level.
    pub level: u32,
    /// The run.
    pub run: usize,
    /// Its seed.
    pub seed: u64,
}

/// The seed of run `run` at `level` of a study seeded with `master` (SplitMix64 of the three).
pub fn run_seed(master: u64, level: u32, run: usize) -> u64 {
    let mut z = master
        .wrapping_add(0x9E37_79B9_7F4A_7C15u64.wrapping_mul(1 + level as u64))
        .wrapping_add(0xD1B5_4A32_D192_ED03u64.wrapping_mul(1 + run as u64));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
