//! CPU twin of `shaders/srvf_dp.wgsl`: batched SRVF DP tables in f32, filled by anti-diagonals
//! with the kernel's loop structure and operation order, so that the back-pointers agree with
//! the GPU's exactly. The traceback (shared with the f64 engine) turns them into warps.

use crate::correspond::srvf::{prepare_steps, traceback, warp_from_path, CurvePair, Warp};

/// Cost of a cell no path reaches (the kernel's UNREACHED).
pub const UNREACHED: f32 = 1e30;
/// Back-pointer of a cell no path reaches (the kernel's NO_STEP).
pub const NO_STEP: u32 = u32::MAX;

/// One coprime step as the kernel reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepEntry {
    /// Step in A's samples.
    pub a: u32,
    /// Step in B's samples.
    pub b: u32,
    /// sqrt(b / a), the step's SRVF factor.
    pub sqrt_slope: f32,
    /// First of its taps in `taps`.
    pub tap_start: u32,
}

/// One interpolation tap: sample r of step (a, b) reads q2 at l + offset + frac.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TapEntry {
    /// Whole-sample offset along B.
    pub offset: u32,
    /// Fraction between that sample and the next.
    pub frac: f32,
}

/// The kernels' step and tap tables of a step set (both DP kernels read them).
pub fn step_tables(steps: &[(usize, usize)]) -> (Vec<StepEntry>, Vec<TapEntry>) {
    let (mut entries, mut taps) = (Vec::new(), Vec::new());
    for st in prepare_steps(steps) {
        entries.push(StepEntry {
            a: st.a as u32,
            b: st.b as u32,
            sqrt_slope: st.sqrt_slope as f32,
            tap_start: taps.len() as u32,
        });
        taps.extend(st.taps.iter().map(|&(offset, frac)| TapEntry {
            offset: offset as u32,
            frac: frac as f32,
        }));
    }
    (entries, taps)
}

/// A batch of DP problems, all with n samples per curve.
#[derive(Clone, Debug, PartialEq)]
pub struct DpBatch {
    /// Samples per curve.
    pub samples: u32,
    /// Problems in the batch.
    pub problems: u32,
    /// P * n SRVF samples of the first curve of each problem, then of the second.
    pub q1: Vec<[f32; 2]>,
    /// Per problem, the SRVF of its second curve.
    pub q2: Vec<[f32; 2]>,
    /// The DP steps.
    pub steps: Vec<StepEntry>,
    /// The steps' interpolation taps.
    pub taps: Vec<TapEntry>,
    /// The step set the entries came from (for the traceback).
    pub step_set: Vec<(usize, usize)>,
}

/// Why a batch cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DpBatchError {
    /// No problem in the batch.
    #[error("the batch is empty")]
    Empty,
    /// Curves whose sample counts differ from the batch's.
    #[error("problem {problem}: curves have {got1} and {got2} samples; every curve needs {expected} (at least 2)")]
    Samples {
        /// The problem's index.
        problem: usize,
        /// Samples of its first curve.
        got1: usize,
        /// Samples of its second curve.
        got2: usize,
        /// The batch's sample count.
        expected: usize,
    },
    /// A NaN or infinite SRVF sample.
    #[error("problem {problem}: non-finite SRVF sample {index}")]
    NonFinite {
        /// The problem's index.
        problem: usize,
        /// The sample.
        index: usize,
    },
    /// No DP steps to take.
    #[error("the step set is empty")]
    NoSteps,
}

impl DpBatch {
    /// A batch of `pairs` (both curves of equal sample counts) under the step set `steps`.
    pub fn new(pairs: &[CurvePair<'_>], steps: &[(usize, usize)]) -> Result<Self, DpBatchError> {
        let n = pairs.first().ok_or(DpBatchError::Empty)?.0.len();
        if steps.is_empty() {
            return Err(DpBatchError::NoSteps);
        }
        let mut b = DpBatch {
            samples: n as u32,
            problems: pairs.len() as u32,
            q1: Vec::with_capacity(n * pairs.len()),
            q2: Vec::with_capacity(n * pairs.len()),
            steps: Vec::new(),
            taps: Vec::new(),
            step_set: steps.to_vec(),
        };
        for (problem, (q1, q2)) in pairs.iter().enumerate() {
            if q1.len() != n || q2.len() != n || n < 2 {
                return Err(DpBatchError::Samples {
                    problem,
                    got1: q1.len(),
                    got2: q2.len(),
                    expected: n.max(2),
                });
            }
            for (index, v) in q1.iter().chain(q2.iter()).enumerate() {
                if !(v.x.is_finite() && v.y.is_finite()) {
                    return Err(DpBatchError::NonFinite {
                        problem,
                        index: index % n,
                    });
                }
            }
            b.q1.extend(q1.iter().map(|v| [v.x as f32, v.y as f32]));
            b.q2.extend(q2.iter().map(|v| [v.x as f32, v.y as f32]));
        }
        (b.steps, b.taps) = step_tables(steps);
        Ok(b)
    }

    /// Cells per problem.
    pub fn cells(&self) -> usize {
        (self.samples as usize).pow(2)
    }
}

/// The kernel's loops on the CPU: (cost, back-pointer) tables, P * n * n each.
pub fn dp_tables(b: &DpBatch) -> (Vec<f32>, Vec<u32>) {
    let n = b.samples as usize;
    let mut cost = vec![0.0f32; b.problems as usize * n * n];
    let mut back = vec![0u32; cost.len()];
    for problem in 0..b.problems as usize {
        let base = problem * n * n;
        let qb = problem * n;
        for c in 0..n {
            cost[base + c] = UNREACHED;
            back[base + c] = NO_STEP;
            cost[base + c * n] = UNREACHED;
            back[base + c * n] = NO_STEP;
        }
        cost[base] = 0.0;
        for d in 2..=2 * (n - 1) {
            let i_lo = 1.max(d - d.min(n - 1));
            let i_hi = (n - 1).min(d - 1);
            for i in i_lo..=i_hi {
                let j = d - i;
                let mut best = UNREACHED;
                let mut arg = NO_STEP;
                for (s, st) in b.steps.iter().enumerate() {
                    let (sa, sb) = (st.a as usize, st.b as usize);
                    if sa > i || sb > j {
                        continue;
                    }
                    let (k, l) = (i - sa, j - sb);
                    let prev = cost[base + k * n + l];
                    if prev >= UNREACHED {
                        continue;
                    }
                    let mut c = 0.0f32;
                    for r in 0..sa {
                        let tap = b.taps[st.tap_start as usize + r];
                        let p = l + tap.offset as usize;
                        let mut qx = b.q2[qb + p][0];
                        let mut qy = b.q2[qb + p][1];
                        if tap.frac != 0.0 {
                            qx += (b.q2[qb + p + 1][0] - qx) * tap.frac;
                            qy += (b.q2[qb + p + 1][1] - qy) * tap.frac;
                        }
                        let dx = b.q1[qb + k + r][0] - qx * st.sqrt_slope;
                        let dy = b.q1[qb + k + r][1] - qy * st.sqrt_slope;
                        c += dx * dx;
                        c += dy * dy;
                    }
                    let total = prev + c;
                    if total < best {
                        best = total;
                        arg = s as u32;
                    }
                }
                cost[base + i * n + j] = best;
                back[base + i * n + j] = arg;
            }
        }
    }
    (cost, back)
}

/// Warps (in f64, from the f32 paths) of every problem, given its back-pointer table.
pub fn warps_from_tables(pairs: &[CurvePair<'_>], b: &DpBatch, back: &[u32]) -> Vec<Warp> {
    let n = b.samples as usize;
    pairs
        .iter()
        .enumerate()
        .map(|(p, (q1, q2))| {
            let path = traceback(&back[p * n * n..(p + 1) * n * n], n, &b.step_set);
            warp_from_path(q1, q2, &path)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::correspond::srvf::{coprime_steps, dp_warp};
    use nalgebra::Vector2;

    fn wave(n: usize, f: f64, ph: f64) -> Vec<Vector2<f64>> {
        (0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64;
                Vector2::new((f * 5.0 * t + ph).cos(), (f * 3.0 * t).sin() + 0.2)
            })
            .collect()
    }

    #[test]
    fn twin_paths_cost_what_the_f64_dp_finds() {
        let steps = coprime_steps(4);
        let (a, b) = (wave(40, 1.0, 0.0), wave(40, 1.4, 0.3));
        let pairs = [(&a[..], &b[..])];
        let batch = DpBatch::new(&pairs, &steps).unwrap();
        let (_, back) = dp_tables(&batch);
        let w32 = &warps_from_tables(&pairs, &batch, &back)[0];
        let w64 = dp_warp(&a, &b, &steps);
        // The f32 table may pick a different path only among near-ties.
        assert!((w32.energy - w64.energy).abs() <= 1e-5 * w64.energy.max(1e-6) + 1e-6);
        assert_eq!(w32.path.first(), Some(&(0, 0)));
        assert_eq!(w32.path.last(), Some(&(39, 39)));
    }

    #[test]
    fn bad_batches_are_errors() {
        let steps = coprime_steps(3);
        let a = wave(20, 1.0, 0.0);
        let short = wave(10, 1.0, 0.0);
        assert!(matches!(
            DpBatch::new(&[(&a[..], &short[..])], &steps),
            Err(DpBatchError::Samples { problem: 0, .. })
        ));
        let mut nan = a.clone();
        nan[3].x = f64::NAN;
        assert!(matches!(
            DpBatch::new(&[(&a[..], &a[..]), (&a[..], &nan[..])], &steps),
            Err(DpBatchError::NonFinite {
                problem: 1,
                index: 3
            })
        ));
        assert_eq!(DpBatch::new(&[], &steps), Err(DpBatchError::Empty));
    }
}
