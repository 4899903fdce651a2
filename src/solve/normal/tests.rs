//! The normal equations' tests: the assembly against dense algebra and to the bit across its
//! variants, the direct CSC against faer's, and the solves.

use super::factor::{lower_csc, undiagonal};
use super::*;
use faer::sparse::SymbolicSparseColMat;

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
