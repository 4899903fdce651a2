//! Sparse least-squares linearisations and their normal equations, solved with faer's sparse
//! Cholesky (LL^T). Parameters come in blocks (12 per deformation node, 7 for a similarity);
//! every residual row touches a few blocks, so J^T J is block-sparse. The assembly is here, the
//! factorisation and solve in `factor`.

use std::collections::HashMap;

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

mod factor;
#[cfg(test)]
mod tests;

pub use factor::SymbolicCache;

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
