//! Parallel work whose results are consumed in order: what makes a tile-set build reproducible.
//!
//! A build makes its tiles on every core and writes them to one file as they come. If they
//! were written in the order they finish, two builds of the same input would lay the same
//! tiles out differently, so their bytes would differ, and so would a set merged from parts
//! built apart. [`in_order`] hands out the jobs in index order, runs them on rayon's threads,
//! and gives their results to one consumer in index order. A job may start only while it is
//! fewer than `window` jobs past the oldest result not yet consumed, so what waits for its
//! turn is bounded by `window` results, whatever the jobs' times.
//!
//! ```
//! let mut seen = Vec::new();
//! tiles::ordered::in_order(100, 4, |i| i * i, |i, square| {
//!     seen.push((i, square));
//!     Ok::<(), ()>(())
//! })
//! .unwrap();
//! assert_eq!(seen, (0..100).map(|i| (i, i * i)).collect::<Vec<_>>());
//! ```

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::sync_channel;
use std::sync::{Condvar, Mutex, PoisonError};

/// Where the consumer is: the next index it takes, and whether it stopped (an error).
struct Gate {
    next: usize,
    stopped: bool,
}

/// Runs `work(i)` for `i` in `0..count` on rayon's threads and calls `consume(i, result)` on
/// the calling thread for `i = 0, 1, 2, ...` in that order. A job starts only when its index
/// is below the consumer's next index plus `window` (at least 1). The first error of
/// `consume` stops the jobs not yet started and is returned; jobs already running finish and
/// their results are dropped.
pub fn in_order<T: Send, E>(
    count: usize,
    window: usize,
    work: impl Fn(usize) -> T + Sync,
    mut consume: impl FnMut(usize, T) -> Result<(), E>,
) -> Result<(), E> {
    let window = window.max(1);
    let taken = AtomicUsize::new(0);
    let gate = (
        Mutex::new(Gate {
            next: 0,
            stopped: false,
        }),
        Condvar::new(),
    );
    // A result waits in the channel or in `early` until its turn; both are bounded by the
    // window, so the channel never blocks a job for long.
    let (send, receive) = sync_channel::<(usize, T)>(window);
    let workers = rayon::current_num_threads().clamp(1, count.max(1));
    let lock = || gate.0.lock().unwrap_or_else(PoisonError::into_inner);
    let stop = || {
        lock().stopped = true;
        gate.1.notify_all();
    };
    std::thread::scope(|scope| {
        let (work, taken, gate, lock) = (&work, &taken, &gate, &lock);
        scope.spawn(move || {
            rayon::scope(|s| {
                for _ in 0..workers {
                    let send = send.clone();
                    s.spawn(move |_| loop {
                        let i = taken.fetch_add(1, Ordering::Relaxed);
                        if i >= count {
                            return;
                        }
                        {
                            let mut g = lock();
                            while !g.stopped && i >= g.next + window {
                                g = gate.1.wait(g).unwrap_or_else(PoisonError::into_inner);
                            }
                            if g.stopped {
                                return;
                            }
                        }
                        // A failed send means the consumer stopped.
                        if send.send((i, work(i))).is_err() {
                            return;
                        }
                    });
                }
            });
            drop(send);
        });
        let mut early = BTreeMap::new();
        let mut next = 0;
        let result = (|| {
            for (i, value) in &receive {
                early.insert(i, value);
                while let Some(value) = early.remove(&next) {
                    consume(next, value)?;
                    next += 1;
                    lock().next = next;
                    gate.1.notify_all();
                }
            }
            Ok(())
        })();
        if result.is_err() {
            stop();
        }
        // Dropping the receiver makes any job still sending give up.
        drop(receive);
        result
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// Jobs that finish out of order (later ones first) still arrive in order, and no job ever
    /// runs `window` or more ahead of the consumer.
    #[test]
    fn results_arrive_in_index_order_within_the_window() {
        let consumed = AtomicUsize::new(0);
        let ahead = AtomicUsize::new(0);
        let mut seen = Vec::new();
        in_order(
            60,
            3,
            |i| {
                let lead = i - consumed.load(Ordering::SeqCst);
                ahead.fetch_max(lead, Ordering::SeqCst);
                // Early jobs of each group of three are the slowest.
                std::thread::sleep(Duration::from_millis(3 * (3 - i as u64 % 3)));
                i
            },
            |i, v| {
                assert_eq!(i, v);
                seen.push(i);
                consumed.store(i + 1, Ordering::SeqCst);
                Ok::<(), ()>(())
            },
        )
        .unwrap();
        assert_eq!(seen, (0..60).collect::<Vec<_>>());
        assert!(
            ahead.load(Ordering::SeqCst) < 3,
            "a job ran beyond the window"
        );
    }

    /// The control: the same jobs consumed in the order they finish are out of order, so
    /// the test above could fail.
    #[test]
    fn the_same_jobs_finish_out_of_order() {
        use rayon::prelude::*;
        let finished = Mutex::new(Vec::new());
        (0..12usize).into_par_iter().with_max_len(1).for_each(|i| {
            std::thread::sleep(Duration::from_millis(5 * (3 - i as u64 % 3)));
            finished.lock().unwrap().push(i);
        });
        let finished = finished.into_inner().unwrap();
        if rayon::current_num_threads() > 1 {
            assert_ne!(finished, (0..12).collect::<Vec<_>>());
        }
    }

    /// An error of the consumer stops the jobs and is returned; nothing past it is consumed.
    #[test]
    fn an_error_stops_the_jobs() {
        let started = AtomicUsize::new(0);
        let mut seen = Vec::new();
        let result = in_order(
            1000,
            4,
            |i| {
                started.fetch_add(1, Ordering::SeqCst);
                i
            },
            |i, _| {
                seen.push(i);
                if i == 10 {
                    Err("stop")
                } else {
                    Ok(())
                }
            },
        );
        assert_eq!(result, Err("stop"));
        assert_eq!(seen, (0..=10).collect::<Vec<_>>());
        assert!(started.load(Ordering::SeqCst) <= 11 + 4);
    }

    #[test]
    fn no_jobs() {
        in_order(0, 4, |i| i, |_, _: usize| Err::<(), ()>(())).unwrap();
    }
}
