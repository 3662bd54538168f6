//! Work spread over all cores: one job per index, taken by whichever thread is free.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// `f(0), …, f(n − 1)` computed on all available cores (jobs of uneven length balance
/// themselves: each thread takes the next index when it is free); `done(k)` is called after
/// each job with the number finished so far. Results come back in index order.
pub fn map<T: Send>(
    n: usize,
    f: impl Fn(usize) -> T + Sync,
    done: impl Fn(usize) + Sync,
) -> Vec<T> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |c| c.get())
        .min(n)
        .max(1);
    let next = AtomicUsize::new(0);
    let finished = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<T>>> = Mutex::new((0..n).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n {
                    break;
                }
                let value = f(i);
                if let Ok(mut r) = results.lock() {
                    r[i] = Some(value);
                }
                done(finished.fetch_add(1, Ordering::Relaxed) + 1);
            });
        }
    });
    results
        .into_inner()
        .unwrap_or_default()
        .into_iter()
        .flatten()
        .collect()
}

/// Number of threads [`map`] uses for `n` jobs.
pub fn threads(n: usize) -> usize {
    std::thread::available_parallelism()
        .map_or(1, |c| c.get())
        .min(n)
        .max(1)
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
