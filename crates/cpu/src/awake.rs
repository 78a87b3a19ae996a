//! Keeping rayon's other threads awake through the serial stretches of a
//! stage made of many short parallel loops.
//!
//! A rayon thread that finds no work spins briefly, then sleeps; the next
//! parallel loop wakes it, which on the machines measured here takes some
//! 70 µs: two 200 µs halves of a `join` took 270 µs after a serial stretch
//! of 50 µs or more, 200 µs after one of 5 µs. The exact integration runs
//! ten or so parallel loops a frame with serial stretches between them
//! (sorting, putting blocks back), so it paid that wake-up nearly every
//! time. [`awake`] keeps the other threads busy looking for work instead.

use rayon::Yield;
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

thread_local! {
    /// This thread runs an [`awake`] stage, or keeps awake for one: a
    /// helper that lands on it (picked up while it waits) leaves at once,
    /// since the work below it on this thread's stack could not go on
    /// under a helper that waits for the stage's end.
    static BUSY: Cell<bool> = const { Cell::new(false) };
}

/// A helper leaves after looking for work this long without finding any:
/// the stage is in a serial stretch longer than a wake-up is worth, or the
/// helper landed on top of work that waits for something it holds up.
const IDLE_LIMIT: Duration = Duration::from_millis(1);

/// Runs `f` on a thread of rayon's pool while the pool's other threads look
/// for work (`rayon::yield_now`) instead of sleeping, until `f` returns;
/// returns what `f` returns. Costs the other cores' time while `f` runs.
pub(crate) fn awake<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    let done = AtomicBool::new(false);
    let helpers = rayon::current_num_threads().saturating_sub(1);
    rayon::scope(|s| {
        for _ in 0..helpers {
            s.spawn(|_| help(&done));
        }
        // Set `done` however `f` ends (a panic included).
        struct Done<'a>(&'a AtomicBool, bool);
        impl Drop for Done<'_> {
            fn drop(&mut self) {
                BUSY.set(self.1);
                self.0.store(true, Ordering::Release);
            }
        }
        let _done = Done(&done, BUSY.replace(true));
        f()
    })
}

/// Looks for work until `done`, or until it found none for [`IDLE_LIMIT`].
fn help(done: &AtomicBool) {
    if BUSY.replace(true) {
        return;
    }
    let mut idle_since = Instant::now();
    while !done.load(Ordering::Acquire) {
        if rayon::yield_now() == Some(Yield::Executed) {
            idle_since = Instant::now();
        } else if idle_since.elapsed() > IDLE_LIMIT {
            break;
        } else {
            std::hint::spin_loop();
        }
    }
    BUSY.set(false);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    /// The stage's parallel loops give the same results with helpers
    /// looking for work, nested loops included, and `awake` inside
    /// `awake` returns.
    #[test]
    fn parallel_loops_inside_awake_give_their_results() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().expect("a pool");
        let got = pool.install(|| {
            awake(|| {
                (0..50u64)
                    .map(|r| {
                        let inner: u64 = (0..1000u64).into_par_iter().map(|i| (0..i % 7).into_par_iter().map(|j| j * r).sum::<u64>()).sum();
                        inner + awake(|| (0..100u64).into_par_iter().sum::<u64>())
                    })
                    .sum::<u64>()
            })
        });
        let want: u64 = (0..50u64).map(|r| (0..1000u64).map(|i| (0..i % 7).map(|j| j * r).sum::<u64>()).sum::<u64>() + 4950).sum();
        assert_eq!(got, want);
    }
}
