//! Work spread over all cores by rayon's work-stealing pool.

use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

/// `f(0), …, f(n − 1)` computed on rayon's pool (one thread per core; jobs of uneven length
/// balance themselves by work stealing); `done(k)` is called after each job with the number
/// finished so far. Results come back in index order.
pub fn map<T: Send>(
    n: usize,
    f: impl Fn(usize) -> T + Sync,
    done: impl Fn(usize) + Sync,
) -> Vec<T> {
    let finished = AtomicUsize::new(0);
    (0..n)
        .into_par_iter()
        .map(|i| {
            let value = f(i);
            done(finished.fetch_add(1, Ordering::Relaxed) + 1);
            value
        })
        .collect()
}

/// Number of threads [`map`] uses for `n` jobs.
pub fn threads(n: usize) -> usize {
    rayon::current_num_threads().min(n).max(1)
}

#[cfg(test)]
mod tests {
    #[test]
    fn results_come_back_in_order() {
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let out = super::map(
            100,
            |i| i * i,
            |_| {
                calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            },
        );
        assert_eq!(out, (0..100).map(|i| i * i).collect::<Vec<_>>());
        assert_eq!(calls.into_inner(), 100);
    }
}
