//! The banded DP as a problem another engine can solve: what one DP of an alignment asks (the two
//! SRVFs, the step set, the band's rows and the position term), the trait an engine implements
//! to return its back-pointers (the GPU's `srvf_band` kernel through the study's batcher), and
//! the traceback that turns them into a path. The host's own banded DP
//! (`band_tables::band_path`) is the reference every such engine is tested against.

use super::curve::Anchor;
use nalgebra::Vector2;

/// The back-pointer of a cell no step reaches.
pub const NO_STEP: u32 = u32::MAX;

/// One banded DP: q2 warped onto q1 over the cells (i, j) with `lo[i] <= j <= hi[i]` (row 0 holds
/// only the start cell), by the coprime `steps`, with the position term of `anchor`.
#[derive(Clone, Copy, Debug)]
pub struct BandProblem<'a> {
    /// The reference SRVF (rows).
    pub q1: &'a [Vector2<f64>],
    /// The warped SRVF (columns), as many samples as q1.
    pub q2: &'a [Vector2<f64>],
    /// The DP's steps (a, b).
    pub steps: &'a [(usize, usize)],
    /// Per row, the first column of the band.
    pub lo: &'a [usize],
    /// Per row, the last column of the band.
    pub hi: &'a [usize],
    /// The position term (weight > 0), or none.
    pub anchor: Option<Anchor<'a>>,
}

impl BandProblem<'_> {
    /// Cells in the band (the length of the back-pointer table).
    pub fn cells(&self) -> usize {
        self.lo
            .iter()
            .zip(self.hi)
            .map(|(l, h)| (h + 1).saturating_sub(*l))
            .sum()
    }
}

/// An engine that fills banded DP tables. `None` when it cannot (the device lost, a batch too
/// large): the DP then runs on the host and the engine counts it.
pub trait BandSolver: Sync {
    /// The back-pointers of `p`, one per band cell, row-major (row i from `lo[i]` to `hi[i]`),
    /// each the index of the step that reached the cell or `NO_STEP`.
    fn back_pointers(&self, p: &BandProblem) -> Option<Vec<u32>>;

    /// The back-pointers of several independent problems (an alignment's seed candidates), in
    /// order; an engine that takes batches solves them together. None: all on the host. By
    /// default one at a time.
    fn back_pointers_many(&self, ps: &[BandProblem]) -> Option<Vec<Vec<u32>>> {
        ps.iter().map(|p| self.back_pointers(p)).collect()
    }
}

/// Where an alignment's DPs run.
#[derive(Clone, Copy, Default)]
pub enum DpOn<'a> {
    /// The host's f64 banded DP (the reference).
    #[default]
    Host,
    /// Another engine (the GPU through the study's batcher).
    Device(&'a dyn BandSolver),
}

/// The path from (0, 0) to (n-1, n-1) that the back-pointers of a band give (`lo`, `hi` per row,
/// `back` row-major over the band), or None when the band cuts every path (or the rows and the
/// table do not fit together).
pub fn trace_band(
    back: &[u32],
    lo: &[usize],
    hi: &[usize],
    steps: &[(usize, usize)],
) -> Option<Vec<(usize, usize)>> {
    let n = lo.len();
    if n == 0 || hi.len() != n {
        return None;
    }
    let mut offset = Vec::with_capacity(n);
    let mut at = 0;
    for i in 0..n {
        if hi[i] < lo[i] {
            return None;
        }
        offset.push(at);
        at += hi[i] + 1 - lo[i];
    }
    if back.len() != at {
        return None;
    }
    let mut path = vec![(n - 1, n - 1)];
    let (mut i, mut j) = (n - 1, n - 1);
    while i > 0 && j > 0 {
        if j < lo[i] || j > hi[i] {
            break;
        }
        let s = back[offset[i] + j - lo[i]];
        let Some(&(a, b)) = steps.get(s as usize) else {
            break;
        };
        if a > i || b > j {
            break;
        }
        i -= a;
        j -= b;
        path.push((i, j));
    }
    if path.last() != Some(&(0, 0)) {
        return None;
    }
    path.reverse();
    Some(path)
}

/// One coprime step (a, b) prepared for the inner loop: sqrt of its slope and, for each of the
/// `a` samples it covers, the integer offset into q2 and the interpolation fraction.
/// Shared by the host's f64 DP (`band_tables`) and the f32 tables of the GPU kernel and its twin.
pub(crate) struct PreparedStep {
    pub a: usize,
    pub b: usize,
    pub sqrt_slope: f64,
    pub taps: Vec<(usize, f64)>,
}

pub(crate) fn prepare(steps: &[(usize, usize)]) -> Vec<PreparedStep> {
    steps
        .iter()
        .map(|&(a, b)| PreparedStep {
            a,
            b,
            sqrt_slope: (b as f64 / a as f64).sqrt(),
            taps: (0..a)
                .map(|r| {
                    let y = (r * b) as f64 / a as f64;
                    let off = (r * b) / a;
                    (off, y - off as f64)
                })
                .collect(),
        })
        .collect()
}

/// A band's rows as stored: each row's first and last column (clamped; row 0 holds only the
/// start cell; an empty row is kept one cell wide so every row can be reached) and where each
/// row starts in the row-major storage (n + 1 offsets, the last the cell count).
pub(crate) fn band_rows(band: &[(usize, usize)], n: usize) -> (Vec<usize>, Vec<usize>, Vec<usize>) {
    let mut lo = vec![0usize; n];
    let mut hi = vec![0usize; n];
    let mut offset = vec![0usize; n + 1];
    for i in 1..n {
        lo[i] = band[i].0.max(1);
        hi[i] = band[i].1.min(n - 1);
        if hi[i] < lo[i] {
            hi[i] = lo[i].min(n - 1);
            lo[i] = hi[i];
        }
    }
    for i in 0..n {
        offset[i + 1] = offset[i] + (hi[i] + 1 - lo[i]);
    }
    (lo, hi, offset)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn back_pointers_trace_to_their_path_and_misfits_give_none() {
        // A 3 x 3 grid, full rows 1..2 (row 0 only the start); steps (1, 1) and (1, 2).
        let steps = [(1, 1), (1, 2)];
        let (lo, hi) = ([0, 1, 1], [0, 2, 2]);
        // Cells: (0,0); (1,1) (1,2); (2,1) (2,2). (2,2) from (1,1) by (1,1); (1,1) from (0,0).
        let back = [NO_STEP, 0, 1, NO_STEP, 0];
        assert_eq!(
            trace_band(&back, &lo, &hi, &steps),
            Some(vec![(0, 0), (1, 1), (2, 2)])
        );
        // (2,2) pointing at a step out of the set: no path.
        assert_eq!(
            trace_band(&[NO_STEP, 0, 1, NO_STEP, 7], &lo, &hi, &steps),
            None
        );
        // A table of the wrong length, and a row whose last column is before its first.
        assert_eq!(trace_band(&back[..4], &lo, &hi, &steps), None);
        assert_eq!(trace_band(&back, &[0, 2, 1], &[0, 1, 2], &steps), None);
        let p = BandProblem {
            q1: &[],
            q2: &[],
            steps: &steps,
            lo: &[0, 2],
            hi: &[0, 1],
            anchor: None,
        };
        assert_eq!(p.cells(), 1);
    }
}
