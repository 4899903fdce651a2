//! The band tables' tests: the row-wise and the vectorised builds against the cell-by-cell DP,
//! to the bit, and a table one back-pointer or one ulp off told apart.

use super::*;
use crate::correspond::srvf::dp::tests::random_q;
use crate::correspond::srvf::dp::{band_around, coprime_steps, dp_warp, finish_warp, Warp};

/// `dp_in_band` filling `tables` with the banded costs and back-pointers (row-major, row i
/// holding the band's columns of row i).
#[cfg(test)]
fn dp_in_band_tables(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    band: &[(usize, usize)],
    anchor: Option<Anchor>,
    tables: &mut (Vec<f64>, Vec<u32>),
) -> Warp {
    let path = band_path(q1, q2, steps, band, anchor, tables, &mut Scratch::default());
    finish_warp(q1, q2, path.expect("the test bands hold a path"), anchor)
}

/// `value(step, p, u)` at every tap (p, u) of every step, for each start column l < n - b (the
/// tap's sample is l + its offset), laid out tap by tap: the DP's per-step tables.
#[cfg(test)]
fn tap_table<T>(
    prepared: &[PreparedStep],
    n: usize,
    value: impl Fn(&PreparedStep, usize, f64) -> T,
) -> Vec<Vec<T>> {
    prepared
        .iter()
        .map(|st| {
            let cols = n.saturating_sub(st.b);
            let mut v = Vec::with_capacity(st.taps.len() * cols);
            for &(off, u) in &st.taps {
                for l in 0..cols {
                    v.push(value(st, l + off, u));
                }
            }
            v
        })
        .collect()
}

/// The DP as it was before the row-wise loops (commit 663b1dc): cell by cell, skipping a
/// step whose predecessor already costs more than the best so far. The oracle of
/// `dp_in_band`'s costs and back-pointers, bit for bit.
fn cellwise(
    q1: &[Vector2<f64>],
    q2: &[Vector2<f64>],
    steps: &[(usize, usize)],
    band: &[(usize, usize)],
    anchor: Option<Anchor>,
) -> Tables {
    let n = q1.len();
    let prepared = prepare(steps);
    let (lo, hi, offset) = band_rows(band, n);
    let mut cost = vec![f64::INFINITY; offset[n]];
    let mut back = vec![u32::MAX; offset[n]];
    cost[0] = 0.0;
    let warped = tap_table(&prepared, n, |st, p, u| {
        let (qx, qy) = if u == 0.0 {
            (q2[p].x, q2[p].y)
        } else {
            (
                q2[p].x + (q2[p + 1].x - q2[p].x) * u,
                q2[p].y + (q2[p + 1].y - q2[p].y) * u,
            )
        };
        (qx * st.sqrt_slope, qy * st.sqrt_slope)
    });
    let weight = anchor.map_or(0.0, |a| a.weight);
    let (pa, placed): (&[Vector2<f64>], Vec<Vec<Vector2<f64>>>) = match anchor {
        Some(an) if weight > 0.0 => (
            an.a,
            tap_table(&prepared, n, |_, p, u| {
                an.b[p] + (an.b[(p + 1).min(n - 1)] - an.b[p]) * u
            }),
        ),
        _ => (&[], Vec::new()),
    };
    for i in 1..n {
        for j in lo[i]..=hi[i] {
            let mut best = f64::INFINITY;
            let mut arg = u32::MAX;
            for (si, st) in prepared.iter().enumerate() {
                if st.a > i || st.b > j {
                    continue;
                }
                let (k, l) = (i - st.a, j - st.b);
                if l < lo[k] || l > hi[k] {
                    continue;
                }
                let prev = cost[offset[k] + l - lo[k]];
                if prev >= best {
                    continue;
                }
                let mut c = 0.0;
                let cols = n - st.b;
                for r in 0..st.a {
                    let (qx, qy) = warped[si][r * cols + l];
                    let dx = q1[k + r].x - qx;
                    let dy = q1[k + r].y - qy;
                    c += dx * dx + dy * dy;
                }
                if weight > 0.0 {
                    let mut e = 0.0;
                    for r in 0..st.a {
                        e += (pa[k + r] - placed[si][r * cols + l]).norm_squared();
                    }
                    c += weight * e;
                }
                let c = prev + c;
                if c < best {
                    best = c;
                    arg = si as u32;
                }
            }
            cost[offset[i] + j - lo[i]] = best;
            back[offset[i] + j - lo[i]] = arg;
        }
    }
    (cost, back)
}

/// Whether two DP tables are the same to the bit (costs) and exactly (back-pointers).
fn same_tables(a: &Tables, b: &Tables) -> bool {
    a.0.len() == b.0.len()
        && a.0
            .iter()
            .zip(&b.0)
            .all(|(x, y)| x.to_bits() == y.to_bits())
        && a.1 == b.1
}

/// (random SRVFs, positions, a band around a wandering path, anchored or not) x sizes.
/// Costs and back-pointers of one DP.
type Tables = (Vec<f64>, Vec<u32>);

/// (the row-wise tables, the oracle's) for each case.
fn table_cases() -> Vec<(Tables, Tables)> {
    let mut out = Vec::new();
    let mut seed = 99u64;
    for &n in &[9usize, 30, 65, 120] {
        for anchored in [false, true] {
            for banded in [false, true] {
                let (q1, q2) = (random_q(n, &mut seed), random_q(n, &mut seed));
                let (a, b) = (random_q(n, &mut seed), random_q(n, &mut seed));
                let anchor = anchored.then_some(Anchor {
                    a: &a,
                    b: &b,
                    weight: 3.0,
                });
                let band = if banded {
                    let hint = dp_warp(&q2, &q1, &coprime_steps(3)).path;
                    band_around(&hint, 1, n, 4)
                } else {
                    vec![(1usize, n - 1); n]
                };
                // n = 30 with steps up to 7 samples long: the general relaxation
                // (`relax_any`) as well as the fused one.
                let steps = coprime_steps(if n == 30 { 7 } else { 5 });
                let mut tables = (Vec::new(), Vec::new());
                let w = dp_in_band_tables(&q1, &q2, &steps, &band, anchor, &mut tables);
                let oracle = cellwise(&q1, &q2, &steps, &band, anchor);
                assert!(w.path.first() == Some(&(0, 0)));
                out.push((tables, oracle));
            }
        }
    }
    out
}

#[test]
fn row_wise_dp_gives_the_cell_by_cell_tables_to_the_bit() {
    for (k, (ours, oracle)) in table_cases().into_iter().enumerate() {
        assert!(same_tables(&ours, &oracle), "case {k}");
    }
}

/// `band_path` runs its AVX2 build where the CPU has it; the plain build (SSE2 on x86-64)
/// must give the same tables, so a result does not depend on the machine's vectors.
#[test]
fn the_plain_build_gives_the_vectorised_builds_tables_to_the_bit() {
    let mut seed = 7u64;
    for &n in &[30usize, 120, 200] {
        for anchored in [false, true] {
            let (q1, q2) = (random_q(n, &mut seed), random_q(n, &mut seed));
            let (a, b) = (random_q(n, &mut seed), random_q(n, &mut seed));
            let anchor = anchored.then_some(Anchor {
                a: &a,
                b: &b,
                weight: 3.0,
            });
            let hint = dp_warp(&q2, &q1, &coprime_steps(3)).path;
            let band = band_around(&hint, 1, n, 6);
            let steps = coprime_steps(if n == 30 { 7 } else { 5 });
            let (mut plain, mut dispatched) = ((Vec::new(), Vec::new()), (Vec::new(), Vec::new()));
            let p = band_path_in::<false>(
                &q1,
                &q2,
                &steps,
                &band,
                anchor,
                &mut plain,
                &mut Scratch::default(),
            );
            let d = band_path(
                &q1,
                &q2,
                &steps,
                &band,
                anchor,
                &mut dispatched,
                &mut Scratch::default(),
            );
            assert_eq!(p, d, "n {n}, anchored {anchored}");
            assert!(
                same_tables(&plain, &dispatched),
                "n {n}, anchored {anchored}"
            );
            assert!(same_tables(
                &plain,
                &cellwise(&q1, &q2, &steps, &band, anchor)
            ));
        }
    }
}

#[test]
fn a_table_one_back_pointer_or_one_ulp_off_is_not_the_same() {
    let ((cost, back), oracle) = table_cases().swap_remove(5);
    let mut moved = back.clone();
    let at = moved.iter().position(|&s| s != u32::MAX && s != 0).unwrap();
    moved[at] = 0;
    assert!(!same_tables(&(cost.clone(), moved), &oracle));
    let mut nudged = cost.clone();
    let at = nudged
        .iter()
        .position(|c| c.is_finite() && *c > 0.0)
        .unwrap();
    nudged[at] = f64::from_bits(nudged[at].to_bits() + 1);
    assert!(!same_tables(&(nudged, back), &oracle));
}
