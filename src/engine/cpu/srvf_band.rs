//! CPU twin of `shaders/srvf_band.wgsl`: the banded SRVF DP of an alignment (the host's
//! `correspond::srvf` banded DP, position term included) in f32, for a batch of problems of any
//! sizes and bands. Rows in order, cells of a row in any order (the kernel shares them among its
//! threads), the steps in order with a strict "<", and per cell the same sums in the same order
//! as the kernel, so that the back-pointers agree with the GPU's exactly.

use crate::correspond::srvf::{BandProblem, NO_STEP};
use crate::engine::cpu::srvf_dp::{step_tables, StepEntry, TapEntry};

/// Cost of a cell no path reaches (the kernel's UNREACHED).
pub const UNREACHED: f32 = 1e30;

/// One problem as the kernel reads it. Keep in sync with `Problem` in shaders/srvf_band.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BandHeader {
    /// Samples per curve.
    pub n: u32,
    /// Its first row in `BandBatch::rows`.
    pub rows: u32,
    /// Its first cell in the tables.
    pub cells: u32,
    /// Its first sample in `curves` and `positions`.
    pub curve: u32,
    /// The position term's weight (0: none).
    pub weight: f32,
    /// Padding to 32 bytes.
    pub _pad: [u32; 3],
}

/// One row of a band. Keep in sync with `Row` in shaders/srvf_band.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BandRow {
    /// First column.
    pub lo: u32,
    /// Last column.
    pub hi: u32,
    /// The row's first cell, from the problem's first.
    pub offset: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

/// A batch of banded DP problems sharing one step set.
#[derive(Clone, Debug, PartialEq)]
pub struct BandBatch {
    /// Per problem, where its data lie.
    pub headers: Vec<BandHeader>,
    /// Every problem's rows.
    pub rows: Vec<BandRow>,
    /// Per sample: q1 (x, y) and q2 (x, y).
    pub curves: Vec<[f32; 4]>,
    /// Per sample: A's position (x, y) and B's (x, y); zeros without a position term.
    pub positions: Vec<[f32; 4]>,
    /// The DP steps.
    pub steps: Vec<StepEntry>,
    /// The steps' interpolation taps.
    pub taps: Vec<TapEntry>,
    /// The step set the entries came from.
    pub step_set: Vec<(usize, usize)>,
    /// Cells over all problems (the tables' length).
    pub cells: usize,
}

/// Why a batch cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BandBatchError {
    /// No problem.
    #[error("the batch is empty")]
    Empty,
    /// Problems with different step sets.
    #[error("problem {problem}: its step set differs from the batch's")]
    Steps {
        /// The problem.
        problem: usize,
    },
    /// Curves, rows or positions of unequal lengths, or a band outside the grid.
    #[error("problem {problem}: {what}")]
    Shape {
        /// The problem.
        problem: usize,
        /// What is wrong.
        what: &'static str,
    },
    /// A NaN or infinite sample.
    #[error("problem {problem}: non-finite sample {index}")]
    NonFinite {
        /// The problem.
        problem: usize,
        /// The sample.
        index: usize,
    },
    /// More cells than a u32 index reaches.
    #[error("{cells} cells do not fit a u32 index")]
    TooLarge {
        /// The cells asked for.
        cells: usize,
    },
}

impl BandBatch {
    /// The batch of `problems` (at least one, all with the same step set).
    pub fn new(problems: &[BandProblem]) -> Result<Self, BandBatchError> {
        let first = problems.first().ok_or(BandBatchError::Empty)?;
        let (steps, taps) = step_tables(first.steps);
        let mut b = BandBatch {
            headers: Vec::with_capacity(problems.len()),
            rows: Vec::new(),
            curves: Vec::new(),
            positions: Vec::new(),
            steps,
            taps,
            step_set: first.steps.to_vec(),
            cells: 0,
        };
        for (problem, p) in problems.iter().enumerate() {
            b.push(problem, p)?;
        }
        Ok(b)
    }

    fn push(&mut self, problem: usize, p: &BandProblem) -> Result<(), BandBatchError> {
        let shape = |what| BandBatchError::Shape { problem, what };
        let n = p.q1.len();
        if p.steps != self.step_set.as_slice() {
            return Err(BandBatchError::Steps { problem });
        }
        if n < 2 || p.q2.len() != n || p.lo.len() != n || p.hi.len() != n {
            return Err(shape(
                "q1, q2 and the band's rows need the same length, at least 2",
            ));
        }
        if p.lo[0] != 0 || p.hi[0] != 0 {
            return Err(shape("row 0 must hold only the start cell"));
        }
        if (1..n).any(|i| p.lo[i] < 1 || p.lo[i] > p.hi[i] || p.hi[i] >= n) {
            return Err(shape("a row's columns lie outside 1..n or are empty"));
        }
        let anchor = p.anchor.filter(|a| a.weight > 0.0);
        if let Some(an) = anchor {
            if an.a.len() != n || an.b.len() != n || !an.weight.is_finite() {
                return Err(shape(
                    "the position term needs n samples a curve and a finite weight",
                ));
            }
        }
        let finite = |v: &nalgebra::Vector2<f64>| v.x.is_finite() && v.y.is_finite();
        for index in 0..n {
            let pos_ok = anchor.is_none_or(|an| finite(&an.a[index]) && finite(&an.b[index]));
            if !(finite(&p.q1[index]) && finite(&p.q2[index]) && pos_ok) {
                return Err(BandBatchError::NonFinite { problem, index });
            }
        }
        let cells = p.cells();
        let total = self.cells + cells;
        if total > u32::MAX as usize {
            return Err(BandBatchError::TooLarge { cells: total });
        }
        self.headers.push(BandHeader {
            n: n as u32,
            rows: self.rows.len() as u32,
            cells: self.cells as u32,
            curve: self.curves.len() as u32,
            weight: anchor.map_or(0.0, |a| a.weight as f32),
            _pad: [0; 3],
        });
        let mut at = 0u32;
        for i in 0..n {
            self.rows.push(BandRow {
                lo: p.lo[i] as u32,
                hi: p.hi[i] as u32,
                offset: at,
                _pad: 0,
            });
            at += (p.hi[i] + 1 - p.lo[i]) as u32;
        }
        for i in 0..n {
            let (q1, q2) = (p.q1[i], p.q2[i]);
            self.curves
                .push([q1.x as f32, q1.y as f32, q2.x as f32, q2.y as f32]);
            self.positions.push(match anchor {
                Some(an) => [
                    an.a[i].x as f32,
                    an.a[i].y as f32,
                    an.b[i].x as f32,
                    an.b[i].y as f32,
                ],
                None => [0.0; 4],
            });
        }
        self.cells = total;
        Ok(())
    }

    /// Append another batch of the same step set (its problems after this one's); refused when
    /// the step sets differ or an index would leave u32.
    pub fn append(&mut self, other: &BandBatch) -> Result<(), BandBatchError> {
        if other.step_set != self.step_set {
            return Err(BandBatchError::Steps {
                problem: self.headers.len(),
            });
        }
        let fits = |n: usize| u32::try_from(n).ok();
        let (Some(rows), Some(cells), Some(curve), Some(_), Some(_), Some(_)) = (
            fits(self.rows.len()),
            fits(self.cells),
            fits(self.curves.len()),
            fits(self.rows.len() + other.rows.len()),
            fits(self.cells + other.cells),
            fits(self.curves.len() + other.curves.len()),
        ) else {
            return Err(BandBatchError::TooLarge {
                cells: self.cells + other.cells,
            });
        };
        self.headers
            .extend(other.headers.iter().map(|h| BandHeader {
                rows: h.rows + rows,
                cells: h.cells + cells,
                curve: h.curve + curve,
                ..*h
            }));
        self.rows.extend_from_slice(&other.rows);
        self.curves.extend_from_slice(&other.curves);
        self.positions.extend_from_slice(&other.positions);
        self.cells += other.cells;
        Ok(())
    }

    /// Problem k's cells in the tables.
    pub fn range(&self, k: usize) -> std::ops::Range<usize> {
        let start = self.headers[k].cells as usize;
        let end = self
            .headers
            .get(k + 1)
            .map_or(self.cells, |h| h.cells as usize);
        start..end
    }

    /// Each problem's cells in the tables, in order.
    pub fn ranges(&self) -> Vec<std::ops::Range<usize>> {
        (0..self.headers.len()).map(|k| self.range(k)).collect()
    }

    /// Problem k's slice of a table.
    pub fn slice<'t, T>(&self, table: &'t [T], k: usize) -> &'t [T] {
        &table[self.range(k)]
    }
}

/// The kernel's loops on the CPU: the (cost, back-pointer) tables of every problem, each
/// problem's band cells row-major from its header's first cell.
pub fn band_tables(b: &BandBatch) -> (Vec<f32>, Vec<u32>) {
    let mut cost = vec![UNREACHED; b.cells];
    let mut back = vec![NO_STEP; b.cells];
    for h in &b.headers {
        let n = h.n as usize;
        let rows = &b.rows[h.rows as usize..][..n];
        let (cb, qb) = (h.cells as usize, h.curve as usize);
        let curves = &b.curves[qb..][..n];
        let positions = &b.positions[qb..][..n];
        cost[cb] = 0.0;
        for (i, row) in rows.iter().enumerate().skip(1) {
            for j in row.lo as usize..=row.hi as usize {
                let (best, arg) = relax_cell(b, h, rows, curves, positions, &cost[cb..], i, j);
                let at = cb + row.offset as usize + j - row.lo as usize;
                cost[at] = best;
                back[at] = arg;
            }
        }
    }
    (cost, back)
}

/// The kernel's per-cell loop: the best (cost, step) of cell (i, j) over the steps, in order.
#[allow(clippy::too_many_arguments)]
fn relax_cell(
    b: &BandBatch,
    h: &BandHeader,
    rows: &[BandRow],
    curves: &[[f32; 4]],
    positions: &[[f32; 4]],
    cost: &[f32],
    i: usize,
    j: usize,
) -> (f32, u32) {
    let n = h.n as usize;
    let mut best = UNREACHED;
    let mut arg = NO_STEP;
    for (s, st) in b.steps.iter().enumerate() {
        let (sa, sb) = (st.a as usize, st.b as usize);
        if sa > i || sb > j {
            continue;
        }
        let (k, l) = (i - sa, j - sb);
        let rk = rows[k];
        if l < rk.lo as usize || l > rk.hi as usize {
            continue;
        }
        let prev = cost[rk.offset as usize + l - rk.lo as usize];
        let mut c = 0.0f32;
        for r in 0..sa {
            let tap = b.taps[st.tap_start as usize + r];
            let p = l + tap.offset as usize;
            let (x, y) = if tap.frac == 0.0 {
                (curves[p][2] * st.sqrt_slope, curves[p][3] * st.sqrt_slope)
            } else {
                (
                    (curves[p][2] + (curves[p + 1][2] - curves[p][2]) * tap.frac) * st.sqrt_slope,
                    (curves[p][3] + (curves[p + 1][3] - curves[p][3]) * tap.frac) * st.sqrt_slope,
                )
            };
            let dx = curves[k + r][0] - x;
            let dy = curves[k + r][1] - y;
            c += dx * dx + dy * dy;
        }
        if h.weight > 0.0 {
            let mut e = 0.0f32;
            for r in 0..sa {
                let tap = b.taps[st.tap_start as usize + r];
                let p = l + tap.offset as usize;
                let p1 = (p + 1).min(n - 1);
                let x = positions[p][2] + (positions[p1][2] - positions[p][2]) * tap.frac;
                let y = positions[p][3] + (positions[p1][3] - positions[p][3]) * tap.frac;
                let dx = positions[k + r][0] - x;
                let dy = positions[k + r][1] - y;
                e += dx * dx + dy * dy;
            }
            c += h.weight * e;
        }
        let v = prev + c;
        if v < best {
            best = v;
            arg = s as u32;
        }
    }
    (best, arg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::correspond::srvf::{coprime_steps, trace_band, Anchor};
    use nalgebra::Vector2;

    fn wavy(n: usize, k: f64, phase: f64) -> Vec<Vector2<f64>> {
        (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / n as f64;
                Vector2::new((k * t + phase).cos(), (t + 0.3 * (k * t).sin()).sin())
            })
            .collect()
    }

    #[test]
    fn the_twin_finds_the_path_of_a_known_warp() {
        // q2 is q1 itself: the diagonal costs nothing, so the twin's path is the diagonal.
        let n = 40;
        let q = wavy(n, 3.0, 0.2);
        let steps = coprime_steps(3);
        let lo: Vec<usize> = (0..n)
            .map(|i| {
                if i == 0 {
                    0
                } else {
                    1.max(i.saturating_sub(4))
                }
            })
            .collect();
        let hi: Vec<usize> = (0..n)
            .map(|i| if i == 0 { 0 } else { (i + 4).min(n - 1) })
            .collect();
        let p = BandProblem {
            q1: &q,
            q2: &q,
            steps: &steps,
            lo: &lo,
            hi: &hi,
            anchor: Some(Anchor {
                a: &q,
                b: &q,
                weight: 2.0,
            }),
        };
        let b = BandBatch::new(&[p]).unwrap();
        let (cost, back) = band_tables(&b);
        let path = trace_band(&back, &lo, &hi, &steps).unwrap();
        assert_eq!(path, (0..n).map(|i| (i, i)).collect::<Vec<_>>());
        assert_eq!(*cost.last().unwrap(), 0.0);
        // A shifted q2 is not matched by the diagonal.
        let shifted = wavy(n, 3.0, 0.9);
        let p2 = BandProblem { q2: &shifted, ..p };
        let (cost2, back2) = band_tables(&BandBatch::new(&[p2]).unwrap());
        assert!(*cost2.last().unwrap() > 0.1);
        assert_ne!(trace_band(&back2, &lo, &hi, &steps).unwrap(), path);
    }

    /// The twin as an alignment's DP engine; `straight` points every cell at the diagonal
    /// step instead (a wrong answer).
    struct Twin {
        straight: bool,
    }

    impl crate::correspond::srvf::BandSolver for Twin {
        fn back_pointers(&self, p: &BandProblem) -> Option<Vec<u32>> {
            let (_, back) = band_tables(&BandBatch::new(std::slice::from_ref(p)).ok()?);
            if self.straight {
                let diagonal = p.steps.iter().position(|&s| s == (1, 1))? as u32;
                return Some(vec![diagonal; back.len()]);
            }
            Some(back)
        }
    }

    #[test]
    fn alignments_on_the_twins_tables_equal_the_hosts() {
        use crate::correspond::srvf::{align, align_on, CurveKind, DpOn};
        use nalgebra::Point2;
        // A coarse polygon with a bulge and a dent against a smooth ellipse, closed and as an
        // open arc, with the study's SRVF settings (bounded rotation, position term).
        let outline: Vec<Point2<f64>> = (0..28)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 28.0;
                let bump = 1.0 + 0.35 * (-((t - 1.2) / 0.4).powi(2)).exp();
                let dent = if (4.0..4.5).contains(&t) { 0.8 } else { 1.0 };
                let r = bump * dent;
                Point2::new(r * 30.0 * t.cos(), r * 22.0 * t.sin())
            })
            .collect();
        let model: Vec<Point2<f64>> = (0..140)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / 140.0 + 0.1;
                Point2::new(29.0 * t.cos() + 0.5, 23.0 * t.sin())
            })
            .collect();
        let prm = crate::correspond::CorrespondParams::default().srvf;
        let same = |x: &crate::correspond::srvf::Alignment,
                    y: &crate::correspond::srvf::Alignment| {
            x.seed == y.seed && x.gamma == y.gamma && x.rotation == y.rotation
        };
        for (a, kind) in [
            (&outline[..], CurveKind::Closed),
            (&outline[3..20], CurveKind::Partial),
        ] {
            let host = align(a, &model, kind, &prm).unwrap();
            let twin = Twin { straight: false };
            let on_twin = align_on(a, &model, kind, &prm, DpOn::Device(&twin)).unwrap();
            assert!(
                same(&host, &on_twin),
                "{kind:?}: the twin's alignment differs"
            );
            let wrong = Twin { straight: true };
            let on_wrong = align_on(a, &model, kind, &prm, DpOn::Device(&wrong)).unwrap();
            assert!(!same(&host, &on_wrong), "{kind:?}: straight warps passed");
        }
    }

    #[test]
    fn appended_batches_give_each_problem_its_own_tables() {
        let steps = coprime_steps(3);
        let (q1, q2) = (wavy(30, 2.0, 0.1), wavy(30, 2.5, 0.7));
        let lo: Vec<usize> = (0..30).map(|i| usize::from(i > 0)).collect();
        let hi: Vec<usize> = (0..30).map(|i| if i == 0 { 0 } else { 29 }).collect();
        let p = BandProblem {
            q1: &q1,
            q2: &q2,
            steps: &steps,
            lo: &lo,
            hi: &hi,
            anchor: None,
        };
        let p2 = BandProblem {
            q1: &q2,
            q2: &q1,
            ..p
        };
        let (one, two) = (
            BandBatch::new(&[p]).unwrap(),
            BandBatch::new(&[p2]).unwrap(),
        );
        let mut merged = one.clone();
        merged.append(&two).unwrap();
        assert_eq!(merged, BandBatch::new(&[p, p2]).unwrap());
        let (_, back) = band_tables(&merged);
        assert_eq!(merged.slice(&back, 1), band_tables(&two).1.as_slice());
        assert_ne!(merged.slice(&back, 0), merged.slice(&back, 1));
        // Another step set is refused.
        let other = coprime_steps(2);
        let p3 = BandProblem { steps: &other, ..p };
        assert!(matches!(
            merged.append(&BandBatch::new(&[p3]).unwrap()),
            Err(BandBatchError::Steps { problem: 2 })
        ));
    }

    #[test]
    fn a_bad_problem_is_named() {
        let q = wavy(10, 2.0, 0.0);
        let steps = coprime_steps(2);
        let lo = vec![0; 10];
        let hi = vec![0; 10];
        let p = BandProblem {
            q1: &q,
            q2: &q,
            steps: &steps,
            lo: &lo,
            hi: &hi,
            anchor: None,
        };
        assert!(matches!(
            BandBatch::new(&[p]),
            Err(BandBatchError::Shape { problem: 0, .. })
        ));
        assert_eq!(BandBatch::new(&[]), Err(BandBatchError::Empty));
    }
}
