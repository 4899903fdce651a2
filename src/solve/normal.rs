//! Sparse least-squares linearisations and their normal equations, solved with faer's sparse
//! Cholesky (LL^T). Parameters come in blocks (12 per deformation node, 7 for a similarity);
//! every residual row touches a few blocks, so J^T J is block-sparse.

use faer::linalg::solvers::SolveCore;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Side};
use std::collections::HashMap;

/// Residuals r and a Jacobian J stored row by row, each row as (block, bs values) pairs.
#[derive(Clone, Debug)]
pub struct Linearization {
    pub block_size: usize,
    pub n_blocks: usize,
    pub r: Vec<f64>,
    row_start: Vec<usize>,
    block_ids: Vec<u32>,
    vals: Vec<f64>,
}

impl Linearization {
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
        let bs = self.block_size;
        let mut index: HashMap<(u32, u32), usize> = HashMap::new();
        let mut blocks: Vec<f64> = Vec::new();
        let mut g = vec![0.0; self.n_params()];
        for row in 0..self.r.len() {
            let (s, e) = (self.row_start[row], self.row_start[row + 1]);
            let r = self.r[row];
            for p in s..e {
                let bp = self.block_ids[p];
                let vp = &self.vals[p * bs..(p + 1) * bs];
                for k in 0..bs {
                    g[bp as usize * bs + k] += vp[k] * r;
                }
                for q in s..e {
                    let bq = self.block_ids[q];
                    if bq > bp {
                        continue;
                    }
                    let vq = &self.vals[q * bs..(q + 1) * bs];
                    let at = *index.entry((bp, bq)).or_insert_with(|| {
                        blocks.resize(blocks.len() + bs * bs, 0.0);
                        blocks.len() / (bs * bs) - 1
                    });
                    let dst = &mut blocks[at * bs * bs..(at + 1) * bs * bs];
                    for a in 0..bs {
                        let va = vp[a];
                        if va == 0.0 {
                            continue;
                        }
                        for b in 0..bs {
                            dst[a * bs + b] += va * vq[b];
                        }
                    }
                }
            }
        }
        let mut keys: Vec<((u32, u32), usize)> = index.into_iter().collect();
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

/// H = J^T J by blocks (row block >= column block) and g = J^T r.
#[derive(Clone, Debug)]
pub struct NormalEquations {
    pub block_size: usize,
    pub n: usize,
    keys: Vec<((u32, u32), usize)>,
    blocks: Vec<f64>,
    pub g: Vec<f64>,
}

/// Numeric failure of a linear solve.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinearSolveError {
    #[error("normal matrix not positive definite at pivot {pivot}")]
    NotPositiveDefinite { pivot: usize },
    #[error("sparse factorisation failed: {0}")]
    Faer(String),
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

    /// Lower-triangle triplets of H + diag(damping).
    fn triplets(&self, damping: &[f64]) -> Vec<Triplet<usize, usize, f64>> {
        let bs = self.block_size;
        let mut t = Vec::with_capacity(self.keys.len() * bs * bs);
        for &((p, q), at) in &self.keys {
            let blk = &self.blocks[at * bs * bs..(at + 1) * bs * bs];
            for a in 0..bs {
                for b in 0..bs {
                    let (row, col) = (p as usize * bs + a, q as usize * bs + b);
                    if row < col {
                        continue;
                    }
                    let mut v = blk[a * bs + b];
                    if row == col {
                        v += damping[row];
                    }
                    t.push(Triplet::new(row, col, v));
                }
            }
        }
        // Parameters no row touches still need a diagonal entry.
        let mut seen = vec![false; self.n];
        for &((p, q), _) in &self.keys {
            if p == q {
                for a in 0..bs {
                    seen[p as usize * bs + a] = true;
                }
            }
        }
        for (i, s) in seen.iter().enumerate() {
            if !s {
                t.push(Triplet::new(i, i, damping[i].max(1.0)));
            }
        }
        t
    }

    /// Solve (H + diag(damping)) delta = -g, reusing `symbolic` when given (same pattern).
    pub fn solve(
        &self,
        damping: &[f64],
        symbolic: &mut Option<SymbolicLlt<usize>>,
    ) -> Result<Vec<f64>, LinearSolveError> {
        let trip = self.triplets(damping);
        let h = SparseColMat::<usize, f64>::try_new_from_triplets(self.n, self.n, &trip)
            .map_err(|e| LinearSolveError::Faer(format!("{e:?}")))?;
        let sym = match symbolic {
            Some(s) => s.clone(),
            None => {
                let s = SymbolicLlt::try_new(h.symbolic(), Side::Lower)
                    .map_err(|e| LinearSolveError::Faer(format!("{e:?}")))?;
                *symbolic = Some(s.clone());
                s
            }
        };
        let llt =
            Llt::try_new_with_symbolic(sym, h.as_ref(), Side::Lower).map_err(|e| match e {
                faer::sparse::linalg::LltError::Numeric(
                    faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index },
                ) => LinearSolveError::NotPositiveDefinite { pivot: index },
                e => LinearSolveError::Faer(format!("{e:?}")),
            })?;
        let mut rhs = Mat::<f64>::from_fn(self.n, 1, |i, _| -self.g[i]);
        llt.solve_in_place_with_conj(Conj::No, rhs.as_mut());
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
        let mut sym = None;
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
    }

    #[test]
    fn residual_check_rejects_a_wrong_solution() {
        let l = random_problem(12);
        let ne = l.normal_equations();
        let damping = vec![1e-3; ne.n];
        let mut d = ne.solve(&damping, &mut None).unwrap();
        d[3] += 1e-3;
        let hd = ne.h_times(&d);
        let worst = (0..ne.n)
            .map(|i| (hd[i] + damping[i] * d[i] + ne.g[i]).abs())
            .fold(0.0, f64::max);
        assert!(worst > 1e-7);
    }

    #[test]
    fn a_negative_definite_system_reports_its_pivot() {
        let mut l = Linearization::new(1, 2);
        l.push_row(1.0, &[(0, &[1.0])]);
        l.push_row(1.0, &[(1, &[1.0])]);
        let ne = l.normal_equations();
        let e = ne.solve(&[-5.0, -5.0], &mut None).unwrap_err();
        assert!(
            matches!(e, LinearSolveError::NotPositiveDefinite { .. }),
            "{e:?}"
        );
    }
}
