//! Independent jobs on threads, their results in the jobs' order: how the diagnosis fits
//! its candidates and the automatic start searches its grids. Each job is a pure function
//! of its input, so the results (and every choice made from them in order) are the same on
//! any number of threads and under any load.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Runs `f` on every job on up to `threads` threads (at least one), results in job order.
pub fn parallel<T: Send, J: Sync>(
    jobs: &[J],
    threads: usize,
    f: impl Fn(&J) -> T + Sync,
) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<T>>> = Mutex::new((0..jobs.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..threads.clamp(1, jobs.len().max(1)) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= jobs.len() {
                    break;
                }
                let r = f(&jobs[i]);
                out.lock().expect("no panic while holding the lock")[i] = Some(r);
            });
        }
    });
    out.into_inner()
        .expect("no panic while holding the lock")
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}

/// Runs `a` and `b`, side by side when `threads` is above one (`b` on a thread of its own),
/// one after the other otherwise; their results as a pair.
pub fn join<A: Send, B: Send>(
    threads: usize,
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    if threads < 2 {
        return (a(), b());
    }
    std::thread::scope(|s| {
        let other = s.spawn(b);
        let first = a();
        (first, other.join().expect("the job does not panic"))
    })
}

/// The threads this machine offers (at least one).
pub fn machine_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_in_job_order_on_any_number_of_threads() {
        let jobs: Vec<u64> = (0..37).collect();
        let one = parallel(&jobs, 1, |j| j * j);
        for threads in [2, 3, 64] {
            assert_eq!(parallel(&jobs, threads, |j| j * j), one);
        }
        assert!(parallel(&[] as &[u64], 4, |j| *j).is_empty());
    }

    #[test]
    fn join_gives_both_results_in_their_places_on_any_number_of_threads() {
        for threads in [1, 2, 8] {
            let (a, b) = join(threads, || "left", || 2 + 3);
            assert_eq!((a, b), ("left", 5));
        }
    }
}
