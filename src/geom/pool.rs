//! Work spread over a pool of threads (rayon), results in input order: the batched SRVF
//! alignments and the studies' runs. Each item is computed alone, so the results do not depend
//! on the number of threads.

use rayon::prelude::*;

/// `f(k, &items[k])` for every item on `threads` worker threads (at least one), in input order.
/// Where the operating system refuses a pool, the items run on the calling thread.
pub fn pool_map<T: Sync, R: Send>(
    threads: usize,
    items: &[T],
    f: impl Fn(usize, &T) -> R + Sync + Send,
) -> Vec<R> {
    match rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
    {
        Ok(pool) => pool.install(|| items.par_iter().enumerate().map(|(k, t)| f(k, t)).collect()),
        Err(_) => items.iter().enumerate().map(|(k, t)| f(k, t)).collect(),
    }
}

/// `f(k, &items[k])` for every item, spread over the pool the caller runs on (a study's
/// `pool_map` workers, or rayon's global pool of one thread a core), in input order. For work
/// inside one run (views, resamples): nested in a study it adds no threads, only tasks.
pub fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(usize, &T) -> R + Sync + Send) -> Vec<R> {
    items.par_iter().enumerate().map(|(k, t)| f(k, t)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_input_order_on_any_pool() {
        let items: Vec<u64> = (0..200).collect();
        let want: Vec<u64> = items.iter().map(|x| x * x + 1).collect();
        for threads in [0, 1, 2, 7] {
            assert_eq!(pool_map(threads, &items, |_, x| x * x + 1), want);
        }
        let k: Vec<usize> = pool_map(3, &items, |k, _| k);
        assert_eq!(k, (0..200).collect::<Vec<_>>());
        // Companion: a result out of place is told apart.
        let mut wrong = want.clone();
        wrong.swap(3, 4);
        assert_ne!(pool_map(2, &items, |_, x| x * x + 1), wrong);
        // The same inside a pool, nested as a run's views are in a study.
        let nested = pool_map(2, &[0u64, 1], |_, o| par_map(&items, |_, x| x * x + 1 + o));
        assert_eq!(nested[0], want);
        assert_ne!(nested[1], want);
    }
}
