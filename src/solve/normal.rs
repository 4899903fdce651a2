//! Sparse least-squares linearisations and their normal equations, solved with faer's sparse
//! Cholesky (LL^T). Parameters come in blocks (12 per deformation node, 7 for a similarity);
//! every residual row touches a few blocks, so J^T J is block-sparse.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, Mat, Par, Side};
use std::collections::HashMap;
use std::sync::Arc;

/// The deformation graph's parameters per node (`graph::NODE_PARAMS`).
const NODE_BLOCK: usize = super::graph::NODE_PARAMS;

/// Residuals r and a Jacobian J stored row by row, each row as (block, bs values) pairs.
#[derive(Clone, Debug)]
pub struct Linearization {
    /// Parameters per block.
    pub block_size: usize,
    /// Number of blocks.
    pub n_blocks: usize,
    /// Residuals.
    pub r: Vec<f64>,
    row_start: Vec<usize>,
    block_ids: Vec<u32>,
    vals: Vec<f64>,
}

impl Linearization {
    /// An empty linearisation with `n_blocks` blocks of `block_size` parameters.
    pub fn new(block_size: usize, n_blocks: usize) -> Self {
        Linearization {
            block_size,
            n_blocks,
            r: Vec::new(),
            row_start: vec![0],
            block_ids: Vec::new(),
            vals: Vec::new(),
        }
    }

    /// Append a residual and its Jacobian row. Each slice in `blocks` has `block_size` values.
    pub fn push_row(&mut self, r: f64, blocks: &[(u32, &[f64])]) {
        self.r.push(r);
        for (b, v) in blocks {
            debug_assert_eq!(v.len(), self.block_size);
            self.block_ids.push(*b);
            self.vals.extend_from_slice(v);
        }
        self.row_start.push(self.block_ids.len());
    }

    /// Append a residual without a Jacobian (cost evaluation only).
    pub fn push_residual(&mut self, r: f64) {
        self.r.push(r);
        self.row_start.push(self.block_ids.len());
    }

    /// Sum of squared residuals.
    pub fn cost(&self) -> f64 {
        self.r.iter().map(|x| x * x).sum()
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        self.block_size * self.n_blocks
    }

    /// J as a dense matrix (tests and small problems).
    pub fn dense_jacobian(&self) -> nalgebra::DMatrix<f64> {
        let bs = self.block_size;
        let mut j = nalgebra::DMatrix::zeros(self.r.len(), self.n_params());
        for row in 0..self.r.len() {
            for e in self.row_start[row]..self.row_start[row + 1] {
                let b = self.block_ids[e] as usize;
                for k in 0..bs {
                    j[(row, b * bs + k)] += self.vals[e * bs + k];
                }
            }
        }
        j
    }

    /// Assemble J^T J (lower block triangle) and J^T r.
    pub fn normal_equations(&self) -> NormalEquations {
        // The deformation's 12-parameter blocks get a build with the block size known, so the
        // block products unroll (and, with AVX2, go four entries at a time); every entry gets
        // the same products summed in the same order in every build, so the sums are equal.
        if self.block_size == NODE_BLOCK {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2, checked just above.
                return unsafe { self.assemble_nodes_avx2() };
            }
            return self.assemble::<NODE_BLOCK>();
        }
        self.assemble::<0>()
    }

    /// `assemble::<NODE_BLOCK>` compiled with AVX2 (call only where the CPU has it).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn assemble_nodes_avx2(&self) -> NormalEquations {
        self.assemble::<NODE_BLOCK>()
    }

    /// `normal_equations` with the block size `BS` fixed at compile time (0: read at run time).
    #[inline(always)]
    fn assemble<const BS: usize>(&self) -> NormalEquations {
        let bs = if BS > 0 { BS } else { self.block_size };
        let mut index = BlockIndex::new(self.n_blocks);
        let mut blocks: Vec<f64> = Vec::new();
        let mut g = vec![0.0; self.n_params()];
        for row in 0..self.r.len() {
            let (s, e) = (self.row_start[row], self.row_start[row + 1]);
            let r = self.r[row];
            for p in s..e {
                let bp = self.block_ids[p];
                let vp = &self.vals[p * bs..(p + 1) * bs];
                let gp = &mut g[bp as usize * bs..(bp as usize + 1) * bs];
                for k in 0..bs {
                    gp[k] += vp[k] * r;
                }
                for q in s..e {
                    let bq = self.block_ids[q];
                    if bq > bp {
                        continue;
                    }
                    let vq = &self.vals[q * bs..(q + 1) * bs];
                    let at = index.slot(bp, bq, || {
                        blocks.resize(blocks.len() + bs * bs, 0.0);
                        blocks.len() / (bs * bs) - 1
                    });
                    let dst = &mut blocks[at * bs * bs..(at + 1) * bs * bs];
                    for (a, &va) in vp.iter().enumerate() {
                        if va == 0.0 {
                            continue;
                        }
                        let d = &mut dst[a * bs..(a + 1) * bs];
                        if BS > 0 {
                            // bs is BS here: the same loop with the length known.
                            add_scaled::<BS>(d, va, vq);
                        } else {
                            for b in 0..bs {
                                d[b] += va * vq[b];
                            }
                        }
                    }
                }
            }
        }
        let mut keys = index.into_keys();
        keys.sort_unstable();
        NormalEquations {
            block_size: bs,
            n: self.n_params(),
            keys,
            blocks,
            g,
        }
    }
}

/// d += va * vq, entry by entry (a function of its own so that the compiler knows `d` and `vq`
/// apart and can take several entries at a time).
/// `d` and `vq` must hold `BS` entries each (they are cut to `BS` first).
#[inline(always)]
fn add_scaled<const BS: usize>(d: &mut [f64], va: f64, vq: &[f64]) {
    let (d, vq) = (&mut d[..BS], &vq[..BS]);
    for b in 0..BS {
        d[b] += va * vq[b];
    }
}

/// Where each (row block, column block) pair's values live in `normal_equations`' block list: a
/// dense table for the usual few hundred blocks (a lookup per Jacobian entry pair is the
/// assembly's inner loop), a hash map beyond.
enum BlockIndex {
    Dense {
        n: usize,
        table: Vec<u32>,
        keys: Vec<((u32, u32), usize)>,
    },
    Hashed(HashMap<(u32, u32), usize>),
}

/// Most blocks the dense table serves (512^2 slots, 1 MiB).
const DENSE_BLOCKS: usize = 512;

impl BlockIndex {
    fn new(n_blocks: usize) -> Self {
        if n_blocks <= DENSE_BLOCKS {
            BlockIndex::Dense {
                n: n_blocks,
                table: vec![u32::MAX; n_blocks * n_blocks],
                keys: Vec::new(),
            }
        } else {
            BlockIndex::Hashed(HashMap::new())
        }
    }

    /// The slot of (p, q), made by `new_slot` the first time the pair is seen.
    #[inline]
    fn slot(&mut self, p: u32, q: u32, new_slot: impl FnOnce() -> usize) -> usize {
        match self {
            BlockIndex::Dense { n, table, keys } => {
                let t = &mut table[p as usize * *n + q as usize];
                if *t == u32::MAX {
                    let at = new_slot();
                    *t = at as u32;
                    keys.push(((p, q), at));
                }
                *t as usize
            }
            BlockIndex::Hashed(map) => *map.entry((p, q)).or_insert_with(new_slot),
        }
    }

    fn into_keys(self) -> Vec<((u32, u32), usize)> {
        match self {
            BlockIndex::Dense { keys, .. } => keys,
            BlockIndex::Hashed(map) => map.into_iter().collect(),
        }
    }
}

/// H = J^T J by blocks (row block >= column block) and g = J^T r.
#[derive(Clone, Debug)]
pub struct NormalEquations {
    /// Parameters per block.
    pub block_size: usize,
    /// Number of parameters.
    pub n: usize,
    keys: Vec<((u32, u32), usize)>,
    blocks: Vec<f64>,
    /// The gradient J^T r.
    pub g: Vec<f64>,
}

/// Numeric failure of a linear solve.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LinearSolveError {
    /// The normal matrix is not positive definite (raise the damping).
    #[error("normal matrix not positive definite at pivot {pivot}")]
    NotPositiveDefinite {
        /// The pivot where the factorisation stopped.
        pivot: usize,
    },
    /// faer's factorisation failed (its message).
    #[error("sparse factorisation failed: {0}")]
    Faer(String),
    /// A block pattern given to `SymbolicCache::for_pattern` holds a pair above the diagonal
    /// or past the parameters.
    #[error(
        "block pair {pair:?} lies outside the lower triangle of {n} parameters in blocks of \
         {block_size}"
    )]
    PatternOutside {
        /// The (row block, column block) pair.
        pair: (u32, u32),
        /// Parameters.
        n: usize,
        /// Parameters per block.
        block_size: usize,
    },
}

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
fn lower_csc(
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
fn undiagonal(n: usize, bs: usize, layout: &[(u32, u32)]) -> Vec<usize> {
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
    /// The block pattern (same pattern -> the symbolic factorisation can be reused).
    pub fn pattern(&self) -> Vec<(u32, u32)> {
        self.keys.iter().map(|(k, _)| *k).collect()
    }

    /// Diagonal of H.
    pub fn diagonal(&self) -> Vec<f64> {
        let bs = self.block_size;
        let mut d = vec![0.0; self.n];
        for &((p, q), at) in &self.keys {
            if p == q {
                for a in 0..bs {
                    d[p as usize * bs + a] = self.blocks[at * bs * bs + a * bs + a];
                }
            }
        }
        d
    }

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

    /// H times a vector (tests).
    pub fn h_times(&self, x: &[f64]) -> Vec<f64> {
        let bs = self.block_size;
        let mut y = vec![0.0; self.n];
        for &((p, q), at) in &self.keys {
            let blk = &self.blocks[at * bs * bs..(at + 1) * bs * bs];
            for a in 0..bs {
                for b in 0..bs {
                    let (row, col) = (p as usize * bs + a, q as usize * bs + b);
                    y[row] += blk[a * bs + b] * x[col];
                    if p != q {
                        y[col] += blk[a * bs + b] * x[row];
                    }
                }
            }
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `lower_csc` against faer's own construction from the (row, column) list, on random
    /// layouts with and without diagonal blocks; the companion: a structure with one row moved
    /// is told apart.
    #[test]
    fn the_direct_csc_equals_faers_from_the_entry_list() {
        use faer::sparse::Pair;
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let (bs, blocks) = (rng.random_range(1..5usize), rng.random_range(1..9u32));
            let n = bs * blocks as usize + rng.random_range(0..3usize);
            let mut layout: Vec<(u32, u32)> = (0..blocks)
                .flat_map(|p| (0..=p).map(move |q| (p, q)))
                .filter(|_| rng.random_range(0..3) > 0)
                .collect();
            layout.sort_unstable();
            let und = undiagonal(n, bs, &layout);
            let (csc, slot) = lower_csc(n, bs, &layout, &und).unwrap();
            let mut idx = Vec::new();
            for &(p, q) in &layout {
                for a in 0..bs {
                    for b in 0..bs {
                        let (row, col) = (p as usize * bs + a, q as usize * bs + b);
                        if row >= col {
                            idx.push(Pair { row, col });
                        }
                    }
                }
            }
            idx.extend(und.iter().map(|&i| Pair { row: i, col: i }));
            let (faer, _) = SymbolicSparseColMat::try_new_from_indices(n, n, &idx).unwrap();
            assert_eq!(csc.col_ptr(), faer.col_ptr());
            assert_eq!(csc.row_idx(), faer.row_idx());
            for (e, &at) in idx.iter().zip(&slot) {
                assert_eq!(csc.row_idx()[at], e.row);
                assert!(csc.col_ptr()[e.col] <= at && at < csc.col_ptr()[e.col + 1]);
            }
            if csc.row_idx().len() > 1 {
                let mut moved = csc.row_idx().to_vec();
                moved[0] = (moved[0] + 1) % n;
                assert_ne!(moved.as_slice(), faer.row_idx());
            }
        }
    }

    /// Rows like the deformation's: 12-parameter blocks, up to four a row, some entries zero.
    fn node_problem(seed: u64) -> Linearization {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut l = Linearization::new(NODE_BLOCK, 9);
        for _ in 0..200 {
            let k = rng.random_range(1..=4usize);
            let first = rng.random_range(0..9u32);
            let vals: Vec<Vec<f64>> = (0..k)
                .map(|_| {
                    (0..NODE_BLOCK)
                        .map(|_| {
                            if rng.random_range(0..4) == 0 {
                                0.0
                            } else {
                                rng.random_range(-1.0..1.0)
                            }
                        })
                        .collect()
                })
                .collect();
            let row: Vec<(u32, &[f64])> = vals
                .iter()
                .enumerate()
                .map(|(i, v)| ((first + 2 * i as u32) % 9, &v[..]))
                .collect();
            l.push_row(rng.random_range(-1.0..1.0), &row);
        }
        l
    }

    fn same_bits(a: &NormalEquations, b: &NormalEquations) -> bool {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        a.keys == b.keys && bits(&a.blocks) == bits(&b.blocks) && bits(&a.g) == bits(&b.g)
    }

    #[test]
    fn the_unrolled_and_vectorised_assembly_equals_the_plain_one_to_the_bit() {
        for seed in 0..5 {
            let l = node_problem(seed);
            let plain = l.assemble::<0>();
            assert!(
                same_bits(&plain, &l.assemble::<NODE_BLOCK>()),
                "seed {seed}"
            );
            assert!(same_bits(&plain, &l.normal_equations()), "seed {seed}");
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2, checked just above.
                let v = unsafe { l.assemble_nodes_avx2() };
                assert!(same_bits(&plain, &v), "seed {seed}");
            }
        }
        // The companion: one Jacobian entry changed in its twelfth digit is told apart.
        let l = node_problem(0);
        let mut m = l.clone();
        let i = m.vals.iter().position(|&x| x != 0.0).unwrap();
        m.vals[i] *= 1.0 + 1e-12;
        assert!(!same_bits(&l.normal_equations(), &m.normal_equations()));
    }

    fn random_problem(seed: u64) -> Linearization {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut l = Linearization::new(3, 5);
        for _ in 0..40 {
            let b1 = rng.random_range(0..5u32);
            let b2 = (b1 + rng.random_range(1..5u32)) % 5;
            let v1: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
            let v2: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
            l.push_row(rng.random_range(-1.0..1.0), &[(b1, &v1), (b2, &v2)]);
        }
        l
    }

    #[test]
    fn normal_equations_match_dense_algebra_and_the_solve_satisfies_them() {
        let l = random_problem(11);
        let j = l.dense_jacobian();
        let r = nalgebra::DVector::from_vec(l.r.clone());
        let ne = l.normal_equations();
        let g = j.transpose() * &r;
        for i in 0..ne.n {
            assert!((ne.g[i] - g[i]).abs() < 1e-12);
        }
        let damping = vec![1e-3; ne.n];
        let mut sym = SymbolicCache::default();
        let d = ne.solve(&damping, &mut sym).unwrap();
        // (J^T J + D) d = -J^T r
        let hd = ne.h_times(&d);
        for i in 0..ne.n {
            assert!(
                (hd[i] + damping[i] * d[i] + ne.g[i]).abs() < 1e-9,
                "row {i}"
            );
        }
        // Reusing the symbolic factorisation gives the same answer.
        let d2 = ne.solve(&damping, &mut sym).unwrap();
        assert_eq!(d, d2);
        assert_eq!((sym.hits, sym.misses), (1, 1));
    }

    /// The dense block table and the hash map index the same blocks in the same slots; a
    /// changed Jacobian value shows in the blocks (the companion: the comparison can fail).
    #[test]
    fn dense_and_hashed_block_indices_assemble_the_same_system() {
        let small = random_problem(5);
        let mut large = Linearization::new(3, DENSE_BLOCKS + 100);
        large.r = small.r.clone();
        large.row_start = small.row_start.clone();
        large.block_ids = small.block_ids.clone();
        large.vals = small.vals.clone();
        let (a, b) = (small.normal_equations(), large.normal_equations());
        assert!(matches!(BlockIndex::new(5), BlockIndex::Dense { .. }));
        assert!(matches!(
            BlockIndex::new(DENSE_BLOCKS + 100),
            BlockIndex::Hashed(_)
        ));
        assert_eq!(a.keys, b.keys);
        assert_eq!(a.blocks, b.blocks);
        assert_eq!(a.g[..], b.g[..a.n]);
        large.vals[0] += 0.5;
        assert_ne!(large.normal_equations().blocks, a.blocks);
    }

    /// Largest |(H + D) d + g| entry.
    fn worst_residual(ne: &NormalEquations, damping: &[f64], d: &[f64]) -> f64 {
        let hd = ne.h_times(d);
        (0..ne.n)
            .map(|i| (hd[i] + damping[i] * d[i] + ne.g[i]).abs())
            .fold(0.0, f64::max)
    }

    /// `random_problem(21)` with every pair of its five blocks coupled.
    fn fully_coupled() -> Linearization {
        let mut full = random_problem(21);
        for p in 0..5u32 {
            for q in 0..p {
                full.push_row(0.5, &[(p, &[1.0, 0.5, 0.25]), (q, &[0.3, -0.2, 0.1])]);
            }
        }
        full
    }

    #[test]
    fn a_kept_factorisation_serves_a_pattern_within_it_and_a_new_pattern_gets_its_own() {
        // Full pattern first: every pair of the five blocks coupled.
        let full = fully_coupled();
        // A pattern within it (random_problem couples some pairs only), and one outside it
        // (more blocks).
        let within = random_problem(22);
        let mut outside = Linearization::new(3, 6);
        for b in 0..6u32 {
            outside.push_row(
                1.0,
                &[(b, &[1.0, 2.0, 3.0]), ((b + 1) % 6, &[0.5, 0.0, 1.0])],
            );
            outside.push_row(-1.0, &[(b, &[0.0, 1.0, 0.0])]);
            outside.push_row(2.0, &[(b, &[0.0, 0.0, 1.0])]);
        }
        let mut cache = SymbolicCache::default();
        for (l, hits, misses) in [(&full, 0, 1), (&within, 1, 1), (&outside, 1, 2)] {
            let ne = l.normal_equations();
            let damping = vec![1e-3; ne.n];
            let d = ne.solve(&damping, &mut cache).unwrap();
            assert!(worst_residual(&ne, &damping, &d) < 1e-9);
            assert_eq!((cache.hits, cache.misses), (hits, misses));
            // The same system solved without the kept factorisation agrees to rounding.
            let fresh = ne.solve(&damping, &mut SymbolicCache::default()).unwrap();
            assert!(d.iter().zip(&fresh).all(|(a, b)| (a - b).abs() < 1e-9));
        }
    }

    /// A cache made for a pattern serves every system within it from the first solve, its
    /// shares hold the same analysis with buffers of their own, and a system outside the
    /// pattern gets its own; the answers agree with fresh solves to rounding.
    #[test]
    fn a_cache_made_for_a_pattern_serves_the_systems_within_it_and_its_shares_too() {
        let full = fully_coupled();
        let pattern = full.normal_equations().pattern();
        let made = SymbolicCache::for_pattern(15, 3, pattern.clone()).unwrap();
        for seed in [22, 23, 24] {
            let ne = random_problem(seed).normal_equations();
            let damping = vec![1e-3; ne.n];
            let mut shared = made.share().unwrap();
            let d = ne.solve(&damping, &mut shared).unwrap();
            assert_eq!((shared.hits, shared.misses), (1, 0), "seed {seed}");
            let fresh = ne.solve(&damping, &mut SymbolicCache::default()).unwrap();
            assert!(d.iter().zip(&fresh).all(|(a, b)| (a - b).abs() < 1e-9));
            assert!(worst_residual(&ne, &damping, &d) < 1e-9);
        }
        // Companion: a pattern without block pair (4, 0) does not serve a system that has it.
        let smaller: Vec<(u32, u32)> = pattern.into_iter().filter(|&k| k != (4, 0)).collect();
        let mut cache = SymbolicCache::for_pattern(15, 3, smaller).unwrap();
        let ne = full.normal_equations();
        ne.solve(&vec![1e-3; ne.n], &mut cache).unwrap();
        assert_eq!((cache.hits, cache.misses), (0, 1));
        // A pair above the diagonal or past the parameters is refused, not a panic.
        for bad in [vec![(0, 1)], vec![(5, 5)]] {
            let pair = bad[0];
            let e = SymbolicCache::for_pattern(15, 3, bad)
                .err()
                .expect("refused");
            assert!(
                matches!(e, LinearSolveError::PatternOutside { pair: p, n: 15, block_size: 3 } if p == pair),
                "{e}"
            );
            assert!(e.to_string().contains("lower triangle"), "{e}");
        }
    }

    #[test]
    fn residual_check_rejects_a_wrong_solution() {
        let l = random_problem(12);
        let ne = l.normal_equations();
        let damping = vec![1e-3; ne.n];
        let mut d = ne.solve(&damping, &mut SymbolicCache::default()).unwrap();
        d[3] += 1e-3;
        assert!(worst_residual(&ne, &damping, &d) > 1e-7);
    }

    #[test]
    fn a_negative_definite_system_reports_its_pivot() {
        let mut l = Linearization::new(1, 2);
        l.push_row(1.0, &[(0, &[1.0])]);
        l.push_row(1.0, &[(1, &[1.0])]);
        let ne = l.normal_equations();
        let e = ne
            .solve(&[-5.0, -5.0], &mut SymbolicCache::default())
            .unwrap_err();
        assert!(
            matches!(e, LinearSolveError::NotPositiveDefinite { .. }),
            "{e:?}"
        );
    }
}
