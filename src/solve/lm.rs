//! Gauss-Newton with Levenberg-Marquardt damping on block-sparse problems: a step that would
//! raise the cost is refused and the damping raised, so the accepted cost never rises.

use super::normal::{LinearSolveError, Linearization, SymbolicCache};

/// A least-squares problem min sum r(x)^2.
pub trait Problem {
    /// Parameters per block.
    fn block_size(&self) -> usize;
    /// Number of blocks.
    fn n_blocks(&self) -> usize;
    /// Residuals at x, with the Jacobian when `jacobian` is set.
    fn linearize(&self, x: &[f64], jacobian: bool) -> Linearization;
    /// x "plus" a step (additive unless the parameters live on a manifold).
    fn retract(&self, x: &[f64], delta: &[f64]) -> Vec<f64> {
        x.iter().zip(delta).map(|(a, b)| a + b).collect()
    }
}

/// Solver parameters, with their defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct LmParams {
    /// Most Gauss-Newton iterations (default 30).
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the cost by less than this fraction (default 1e-5).
    pub rel_tol: f64,
    /// Initial Marquardt damping lambda, relative to diag(J^T J) (default 1e-4).
    pub lambda0: f64,
    /// Give up raising lambda beyond this (default 1e8): the current point is a minimum.
    pub max_lambda: f64,
}

impl Default for LmParams {
    fn default() -> Self {
        LmParams {
            max_iterations: 30,
            rel_tol: 1e-5,
            lambda0: 1e-4,
            max_lambda: 1e8,
        }
    }
}

/// What the solver did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LmInfo {
    /// Accepted steps.
    pub iterations: usize,
    /// Cost before the first step, then after each accepted step (never rising).
    pub costs: Vec<f64>,
    /// Stopped because the relative decrease fell below `rel_tol` or lambda ran out.
    pub converged: bool,
    /// Steps rejected (the cost rose; the damping was raised).
    pub rejected_steps: usize,
}

impl LmInfo {
    /// The cost at the end.
    pub fn final_cost(&self) -> f64 {
        *self.costs.last().unwrap_or(&f64::NAN)
    }
}

/// Why the solver stopped without an answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SolveError {
    /// The cost is NaN or infinite at the start.
    #[error("the cost is not finite ({cost}) at the starting point")]
    NonFiniteStart {
        /// The cost.
        cost: f64,
    },
    /// The normal equations could not be solved.
    #[error("linear solve failed at iteration {iteration}: {source}")]
    Linear {
        /// The LM iteration.
        iteration: usize,
        /// Why.
        source: LinearSolveError,
    },
}

/// Minimise the problem from x0. Returns the best x found and the log.
pub fn levenberg_marquardt<P: Problem>(
    p: &P,
    x0: Vec<f64>,
    prm: &LmParams,
) -> Result<(Vec<f64>, LmInfo), SolveError> {
    levenberg_marquardt_cached(p, x0, prm, &mut SymbolicCache::default())
}

/// As `levenberg_marquardt`, keeping the sparse symbolic factorisation in `cache` so that a
/// sequence of solves whose block patterns fit in the kept one computes it once. What the cache
/// held changes the result by rounding at most (a kept pattern larger than the problem's adds
/// zero blocks).
pub fn levenberg_marquardt_cached<P: Problem>(
    p: &P,
    x0: Vec<f64>,
    prm: &LmParams,
    cache: &mut SymbolicCache,
) -> Result<(Vec<f64>, LmInfo), SolveError> {
    let mut x = x0;
    let mut lin = p.linearize(&x, true);
    let mut cost = lin.cost();
    if !cost.is_finite() {
        return Err(SolveError::NonFiniteStart { cost });
    }
    let mut info = LmInfo {
        costs: vec![cost],
        ..Default::default()
    };
    let mut lambda = prm.lambda0;
    while info.iterations < prm.max_iterations {
        info.iterations += 1;
        let ne = lin.normal_equations();
        let diag = ne.diagonal();
        let mut accepted = false;
        while lambda <= prm.max_lambda {
            let damping: Vec<f64> = diag.iter().map(|d| lambda * d.max(1e-9) + 1e-12).collect();
            let delta = match ne.solve(&damping, cache) {
                Ok(d) => d,
                Err(LinearSolveError::NotPositiveDefinite { .. }) => {
                    lambda *= 10.0;
                    continue;
                }
                Err(source) => {
                    return Err(SolveError::Linear {
                        iteration: info.iterations,
                        source,
                    })
                }
            };
            let x_new = p.retract(&x, &delta);
            let new_cost = p.linearize(&x_new, false).cost();
            if new_cost.is_finite() && new_cost < cost {
                let rel = (cost - new_cost) / cost.max(1e-300);
                x = x_new;
                cost = new_cost;
                info.costs.push(cost);
                lambda = (lambda / 3.0).max(1e-12);
                accepted = true;
                if rel < prm.rel_tol {
                    info.converged = true;
                }
                break;
            }
            info.rejected_steps += 1;
            lambda *= 4.0;
        }
        if !accepted {
            info.converged = true; // no descent direction left at any damping
            break;
        }
        // Converged, or out of iterations: no Jacobian at the last point is needed.
        if info.converged || info.iterations >= prm.max_iterations {
            break;
        }
        lin = p.linearize(&x, true);
    }
    Ok((x, info))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as residuals (1 - a, 10 (b - a^2)), one block of two parameters.
    struct Rosen;
    impl Problem for Rosen {
        fn block_size(&self) -> usize {
            2
        }
        fn n_blocks(&self) -> usize {
            1
        }
        fn linearize(&self, x: &[f64], jac: bool) -> Linearization {
            let mut l = Linearization::new(2, 1);
            if jac {
                l.push_row(1.0 - x[0], &[(0, &[-1.0, 0.0])]);
                l.push_row(10.0 * (x[1] - x[0] * x[0]), &[(0, &[-20.0 * x[0], 10.0])]);
            } else {
                l.push_residual(1.0 - x[0]);
                l.push_residual(10.0 * (x[1] - x[0] * x[0]));
            }
            l
        }
    }

    #[test]
    fn lm_solves_rosenbrock_and_the_cost_never_rises() {
        let (x, info) = levenberg_marquardt(
            &Rosen,
            vec![-1.2, 1.0],
            &LmParams {
                max_iterations: 200,
                rel_tol: 1e-14,
                ..Default::default()
            },
        )
        .unwrap();
        assert!(
            (x[0] - 1.0).abs() < 1e-6 && (x[1] - 1.0).abs() < 1e-6,
            "{x:?}"
        );
        assert!(info.costs.windows(2).all(|w| w[1] < w[0]));
    }

    #[test]
    fn a_non_finite_start_is_an_error() {
        let e = levenberg_marquardt(&Rosen, vec![f64::NAN, 1.0], &LmParams::default()).unwrap_err();
        assert!(matches!(e, SolveError::NonFiniteStart { .. }));
    }
}
