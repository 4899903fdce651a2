//! The normal equations' sparse Cholesky (faer): the symbolic analysis of a block pattern, kept
//! for later solves on the same pattern or one within it (`SymbolicCache`), and the numeric
//! factorisation and solve (`NormalEquations::solve`).

use super::{LinearSolveError, NormalEquations};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, Mat, Par, Side};
use std::sync::Arc;

/// The symbolic Cholesky factorisation of the last new block pattern solved, kept for later
/// solves whose pattern is the same or lies within it. Within one Levenberg-Marquardt run the
/// pattern never changes, so a solve with many iterations computes it once.
#[derive(Default)]
pub struct SymbolicCache {
    entry: Option<CachedPattern>,
    /// Solves that reused the kept factorisation, and solves that computed a new one.
    pub hits: usize,
    /// Solves that computed a new factorisation.
    pub misses: usize,
}

/// A block pattern's symbolic analysis: what every solve on the pattern shares.
struct Analysis {
    n: usize,
    block_size: usize,
    keys: Vec<(u32, u32)>,
    /// The parameters `keys` has no diagonal block for (`undiagonal`).
    undiagonal: Vec<usize>,
    csc: SymbolicSparseColMat<usize>,
    /// Where each lower-triangle entry, in `NormalEquations::fill_lower`'s order, sits among
    /// `csc`'s values (column by column, rows ascending; no entry appears twice).
    slot: Vec<usize>,
    chol: SymbolicCholesky<usize>,
}

struct CachedPattern {
    analysis: Arc<Analysis>,
    /// The factor's values and the factorisation's scratch, sized by the analysis, reused by
    /// every solve on this pattern.
    l_values: Vec<f64>,
    /// H's values in `csc`'s order, refilled by every solve.
    h_values: Vec<f64>,
    mem: MemBuffer,
}

impl CachedPattern {
    /// Numeric buffers for `analysis`.
    fn new(analysis: Arc<Analysis>) -> Result<CachedPattern, LinearSolveError> {
        let chol = &analysis.chol;
        let mem = MemBuffer::try_new(
            chol.factorize_numeric_llt_scratch::<f64>(PAR, Default::default())
                .or(chol.solve_in_place_scratch::<f64>(1, PAR)),
        )
        .map_err(|e| LinearSolveError::Faer(format!("{e:?}")))?;
        Ok(CachedPattern {
            l_values: vec![0.0; chol.len_val()],
            h_values: vec![0.0; analysis.slot.len()],
            analysis,
            mem,
        })
    }
}

/// The symbolic analysis of the lower-triangle entries `NormalEquations::fill_lower` lays
/// out on `layout` for `n` parameters in blocks of `block_size` (their (row, column) pairs
/// listed here in the same order).
fn analyse(
    n: usize,
    block_size: usize,
    layout: Vec<(u32, u32)>,
) -> Result<Analysis, LinearSolveError> {
    let faer_err = |e: &dyn std::fmt::Debug| LinearSolveError::Faer(format!("{e:?}"));
    let undiagonal = undiagonal(n, block_size, &layout);
    let (csc, slot) = lower_csc(n, block_size, &layout, &undiagonal)?;
    let chol = factorize_symbolic_cholesky(
        csc.as_ref(),
        Side::Lower,
        SymmetricOrdering::Amd,
        Default::default(),
    )
    .map_err(|e| faer_err(&e))?;
    Ok(Analysis {
        n,
        block_size,
        keys: layout,
        undiagonal,
        csc,
        slot,
        chol,
    })
}

/// The CSC structure (by column, rows ascending) of the lower-triangle entries that
/// `NormalEquations::fill_lower` lists for `layout` (sorted block pairs, row block >= column
/// block, within `n`) and `undiagonal`, and where each of those entries, in that order, sits in
/// it. Built directly: going through `layout` in order gives each column's rows ascending (a
/// column's blocks come in row-block order), and an `undiagonal` entry is its column's first.
pub(super) fn lower_csc(
    n: usize,
    bs: usize,
    layout: &[(u32, u32)],
    undiagonal: &[usize],
) -> Result<(SymbolicSparseColMat<usize>, Vec<usize>), LinearSolveError> {
    let lost = || LinearSolveError::Faer("a layout entry lies outside the system".into());
    let mut count = vec![0usize; n + 1];
    for &(p, q) in layout {
        // A block's last row is among its lower entries (p >= q).
        if (p as usize + 1) * bs > n {
            return Err(lost());
        }
        for_each_lower(p, q, bs, |_, col, _| count[col] += 1);
    }
    for &i in undiagonal {
        *count.get_mut(i).ok_or_else(lost)? += 1;
    }
    let mut col_ptr = vec![0usize; n + 1];
    for c in 0..n {
        col_ptr[c + 1] = col_ptr[c] + count[c];
    }
    let mut next = col_ptr[..n].to_vec();
    for &i in undiagonal {
        next[i] += 1;
    }
    let mut row_idx = vec![0usize; col_ptr[n]];
    let mut slot = Vec::with_capacity(col_ptr[n]);
    for &(p, q) in layout {
        for_each_lower(p, q, bs, |row, col, _| {
            row_idx[next[col]] = row;
            slot.push(next[col]);
            next[col] += 1;
        });
    }
    for &i in undiagonal {
        row_idx[col_ptr[i]] = i;
        slot.push(col_ptr[i]);
    }
    let csc = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
    Ok((csc, slot))
}

/// The lower-triangle entries (row >= column) of block (p, q) in blocks of `bs`, row by row:
/// `f(row, column, index in the block)`. `lower_csc` lays the structure out and `fill_lower`
/// the values in this one order.
#[inline(always)]
fn for_each_lower(p: u32, q: u32, bs: usize, mut f: impl FnMut(usize, usize, usize)) {
    for a in 0..bs {
        for b in 0..bs {
            let (row, col) = (p as usize * bs + a, q as usize * bs + b);
            if row >= col {
                f(row, col, a * bs + b);
            }
        }
    }
}

/// The parameters `layout` (sorted block pairs) has no diagonal block for, in order: they
/// still need a diagonal entry.
pub(super) fn undiagonal(n: usize, bs: usize, layout: &[(u32, u32)]) -> Vec<usize> {
    let mut seen = vec![false; n];
    for &(p, q) in layout {
        if p == q {
            for a in 0..bs {
                if let Some(s) = seen.get_mut(p as usize * bs + a) {
                    *s = true;
                }
            }
        }
    }
    (0..n).filter(|&i| !seen[i]).collect()
}

impl SymbolicCache {
    /// A cache that already holds the symbolic factorisation of `pattern` (block pairs, row
    /// block >= column block) for `n` parameters in blocks of `block_size`, so that every solve
    /// whose pattern lies within it reuses it: for many solves of one structure (the cup's
    /// resamples) analysed once.
    pub fn for_pattern(
        n: usize,
        block_size: usize,
        mut pattern: Vec<(u32, u32)>,
    ) -> Result<SymbolicCache, LinearSolveError> {
        pattern.sort_unstable();
        pattern.dedup();
        if let Some(&pair) = pattern
            .iter()
            .find(|&&(p, q)| p < q || (p as usize + 1) * block_size > n)
        {
            return Err(LinearSolveError::PatternOutside {
                pair,
                n,
                block_size,
            });
        }
        let analysis = Arc::new(analyse(n, block_size, pattern)?);
        Ok(SymbolicCache {
            entry: Some(CachedPattern::new(analysis)?),
            hits: 0,
            misses: 0,
        })
    }

    /// A cache holding the same symbolic factorisation as this one (shared, not recomputed)
    /// with numeric buffers of its own, its counts at zero: for solves on other threads.
    pub fn share(&self) -> Result<SymbolicCache, LinearSolveError> {
        Ok(SymbolicCache {
            entry: match &self.entry {
                Some(c) => Some(CachedPattern::new(Arc::clone(&c.analysis))?),
                None => None,
            },
            hits: 0,
            misses: 0,
        })
    }
}

/// Sequential on purpose: these systems have a few thousand unknowns, where faer's threads cost
/// more than they save, and a study already runs one case per core.
const PAR: Par = Par::Seq;

/// Whether sorted `a` is contained in sorted `b`.
fn is_sorted_subset(a: &[(u32, u32)], b: &[(u32, u32)]) -> bool {
    let mut it = b.iter();
    a.iter().all(|x| it.any(|y| y == x))
}

impl NormalEquations {
    /// H + diag(damping)'s lower triangle on `a`'s layout into `out`, each value at its slot
    /// among the CSC values: layout block by block, each block's entries row by row, then one
    /// diagonal entry for each parameter in `a.undiagonal` (those the layout has no diagonal
    /// block for). Layout blocks this system lacks are zeros (a diagonal one gets the damping,
    /// at least 1, as a parameter no row touches does).
    fn fill_lower(&self, an: &Analysis, damping: &[f64], out: &mut [f64]) {
        let bs = self.block_size;
        let zeros = vec![0.0; bs * bs];
        let mut mine = self.keys.iter().peekable();
        let mut slots = an.slot.iter();
        let mut put = |v: f64| {
            if let Some(&at) = slots.next() {
                out[at] = v;
            }
        };
        for &(p, q) in &an.keys {
            let blk = match mine.peek() {
                Some(&&(k, at)) if k == (p, q) => {
                    mine.next();
                    Some(&self.blocks[at * bs * bs..(at + 1) * bs * bs])
                }
                _ => None,
            };
            for_each_lower(p, q, bs, |row, col, k| {
                let mut v = blk.unwrap_or(&zeros)[k];
                if row == col {
                    v += if blk.is_some() {
                        damping[row]
                    } else {
                        damping[row].max(1.0)
                    };
                }
                put(v);
            });
        }
        for &i in &an.undiagonal {
            put(damping[i].max(1.0));
        }
    }

    /// Solve (H + diag(damping)) delta = -g. The symbolic factorisation (fill-reducing ordering,
    /// elimination tree) depends on the block pattern only. It is taken from `cache` when the
    /// pattern is part of the one kept there: the blocks this system lacks enter as zeros, which
    /// changes the answer by rounding only. Otherwise this pattern is factorised and kept.
    pub fn solve(
        &self,
        damping: &[f64],
        cache: &mut SymbolicCache,
    ) -> Result<Vec<f64>, LinearSolveError> {
        let pattern = self.pattern();
        let kept = cache.entry.as_ref().filter(|c| {
            let a = &c.analysis;
            a.n == self.n && a.block_size == self.block_size && is_sorted_subset(&pattern, &a.keys)
        });
        if kept.is_some() {
            cache.hits += 1;
        } else {
            let analysis = Arc::new(analyse(self.n, self.block_size, pattern)?);
            cache.entry = Some(CachedPattern::new(analysis)?);
            cache.misses += 1;
        }
        // Invariant: the entry was matched or filled just above.
        let c = cache.entry.as_mut().expect("cached pattern present");
        let a = &*c.analysis;
        self.fill_lower(a, damping, &mut c.h_values);
        let h = SparseColMatRef::new(a.csc.as_ref(), &c.h_values);
        let llt = a
            .chol
            .factorize_numeric_llt(
                &mut c.l_values,
                h,
                Side::Lower,
                Default::default(),
                PAR,
                MemStack::new(&mut c.mem),
                Default::default(),
            )
            .map_err(|e| match e {
                faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index } => {
                    LinearSolveError::NotPositiveDefinite { pivot: index }
                }
            })?;
        let mut rhs = Mat::<f64>::from_fn(self.n, 1, |i, _| -self.g[i]);
        llt.solve_in_place_with_conj(Conj::No, rhs.as_mut(), PAR, MemStack::new(&mut c.mem));
        Ok((0..self.n).map(|i| rhs[(i, 0)]).collect())
    }
}
