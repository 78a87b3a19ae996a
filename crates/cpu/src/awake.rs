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
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};
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

/// Runs `f(state, item)` for every item, on every thread of rayon's pool
/// when `parallel`, and returns the results in the items' order. Each
/// thread makes its `state` once, with `init`.
///
/// The items are cut into one run per thread, in order; each thread works
/// through its own run from the front, then takes items one at a time from
/// the back of the run with the most left. Rayon's parallel loops split
/// their items in halves only as threads steal them, so a thread could be
/// left with a long run while the other waited: pass z of 3dmatch-seq01 at
/// 2 m ended with one of two threads idle for up to 0.5 ms of its 2-4 ms.
/// Here the threads end at most an item apart. Each still works through
/// neighbouring items, as in rayon's halves, and the calling thread always
/// through the first run: the passes of the exact integration order their
/// items alike, so a thread mostly reads what it wrote in the pass before,
/// from its own cache (handing items out in turn across threads was 10 %
/// slower). The calling thread spins for the others' last items rather than
/// sleep in rayon's wait (a wake-up takes longer than an item).
pub(crate) fn share_out<I: Send, T: Send, S>(
    items: impl IntoIterator<IntoIter: ExactSizeIterator<Item = I>>,
    parallel: bool,
    init: impl Fn() -> S + Sync,
    f: impl Fn(&mut S, I) -> T + Sync,
) -> Vec<T> {
    let items = items.into_iter();
    let n = items.len();
    // (Runs' bounds are packed in 32 bits each.)
    let threads = if parallel && u32::try_from(n).is_ok() { rayon::current_num_threads().min(n) } else { 1 };
    if threads <= 1 {
        let mut state = init();
        return items.map(|i| f(&mut state, i)).collect();
    }
    let slots: Vec<Mutex<Option<I>>> = items.map(|i| Mutex::new(Some(i))).collect();
    // Each run's first and end, packed in one word: `first << 32 | end`.
    let runs: Vec<AtomicU64> = (0..threads)
        .map(|t| AtomicU64::new(((n * t / threads) as u64) << 32 | (n * (t + 1) / threads) as u64))
        .collect();
    let results = Mutex::new(Vec::with_capacity(n));
    let running = AtomicUsize::new(0);
    // Takes the first item of run `r`, or its last.
    let take = |r: usize, last: bool| -> Option<usize> {
        let mut v = runs[r].load(Ordering::Acquire);
        loop {
            let (first, end) = (v >> 32, v & 0xFFFF_FFFF);
            if first >= end {
                return None;
            }
            let (next, i) = if last { (first << 32 | (end - 1), end - 1) } else { ((first + 1) << 32 | end, first) };
            match runs[r].compare_exchange_weak(v, next, Ordering::AcqRel, Ordering::Acquire) {
                Ok(_) => return Some(i as usize),
                Err(now) => v = now,
            }
        }
    };
    let left = |r: usize| {
        let v = runs[r].load(Ordering::Acquire);
        (v & 0xFFFF_FFFF).saturating_sub(v >> 32)
    };
    // The last item of the run with the most left, none when all are done.
    let steal = || loop {
        let (r, most) = (0..threads).map(|r| (r, left(r))).max_by_key(|&(_, n)| n)?;
        if most == 0 {
            return None;
        }
        if let Some(i) = take(r, true) {
            return Some(i);
        }
    };
    let run = |own: usize| {
        let mut state = init();
        let mut mine = Vec::new();
        loop {
            let next = take(own, false).or_else(steal);
            let Some(i) = next else { break };
            let item = slots[i].lock().unwrap_or_else(PoisonError::into_inner).take();
            if let Some(item) = item {
                mine.push((i, f(&mut state, item)));
            }
        }
        results.lock().unwrap_or_else(PoisonError::into_inner).append(&mut mine);
    };
    rayon::scope(|s| {
        for t in 1..threads {
            let (run, running) = (&run, &running);
            s.spawn(move |_| {
                running.fetch_add(1, Ordering::AcqRel);
                run(t);
                running.fetch_sub(1, Ordering::AcqRel);
            });
        }
        run(0);
        // A helper that started is on its last item at most: spin for it,
        // then, if it takes long (another process may hold its core), give
        // this core up between looks.
        let mut wait = Backoff::default();
        while running.load(Ordering::Acquire) > 0 {
            wait.snooze();
        }
    });
    let mut results = results.into_inner().unwrap_or_else(PoisonError::into_inner);
    results.sort_unstable_by_key(|r| r.0);
    results.into_iter().map(|r| r.1).collect()
}

/// Spins of a waiting thread before it yields its core between looks (a
/// few microseconds).
const SPINS_BEFORE_YIELD: u32 = 1 << 10;

/// A waiting thread's pause between two looks: a spin for the first
/// [`SPINS_BEFORE_YIELD`] looks, then a yield of its core, so that on a
/// loaded machine a waiter does not keep the thread it waits for (or
/// another process) off a core.
#[derive(Default)]
struct Backoff {
    looks: u32,
}

impl Backoff {
    fn snooze(&mut self) {
        if self.looks < SPINS_BEFORE_YIELD {
            self.looks += 1;
            std::hint::spin_loop();
        } else {
            std::thread::yield_now();
        }
    }
}

/// Looks for work until `done`, or until it found none for [`IDLE_LIMIT`],
/// pausing between fruitless looks as a [`Backoff`] does.
fn help(done: &AtomicBool) {
    if BUSY.replace(true) {
        return;
    }
    let mut idle_since = Instant::now();
    let mut wait = Backoff::default();
    while !done.load(Ordering::Acquire) {
        if rayon::yield_now() == Some(Yield::Executed) {
            idle_since = Instant::now();
            wait = Backoff::default();
        } else if idle_since.elapsed() > IDLE_LIMIT {
            break;
        } else {
            wait.snooze();
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
                        let inner: u64 = (0..1000u64)
                            .into_par_iter()
                            .map(|i| (0..i % 7).into_par_iter().map(|j| j * r).sum::<u64>())
                            .sum();
                        inner + awake(|| (0..100u64).into_par_iter().sum::<u64>())
                    })
                    .sum::<u64>()
            })
        });
        let want: u64 =
            (0..50u64).map(|r| (0..1000u64).map(|i| (0..i % 7).map(|j| j * r).sum::<u64>()).sum::<u64>() + 4950).sum();
        assert_eq!(got, want);
    }

    /// Every item is handed out once and its result comes back in the
    /// items' order, on pools of one to five threads, inside and outside
    /// `awake`, with each thread's state kept across its items, and with
    /// items that take long (one thread's run stolen from its end).
    #[test]
    fn share_out_runs_every_item_once_and_keeps_their_order() {
        for threads in [1, 2, 3, 5] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a pool");
            for n in [0usize, 1, 2, 3, 7, 64, 1000] {
                for parallel in [false, true] {
                    let calls = AtomicUsize::new(0);
                    let states = AtomicUsize::new(0);
                    let job = || {
                        share_out(
                            (0..n).collect::<Vec<_>>(),
                            parallel,
                            || {
                                states.fetch_add(1, Ordering::Relaxed);
                                0usize
                            },
                            |seen: &mut usize, i| {
                                *seen += 1;
                                calls.fetch_add(1, Ordering::Relaxed);
                                // The first items are slow: the thread on
                                // the first run leaves the rest to others.
                                std::hint::black_box(
                                    (0..if i < 3 { 20_000u64 } else { 10 }).map(|k| k ^ i as u64).sum::<u64>(),
                                );
                                i * 3
                            },
                        )
                    };
                    let got = pool.install(|| if n % 2 == 0 { awake(job) } else { job() });
                    assert_eq!(got, (0..n).map(|i| i * 3).collect::<Vec<_>>(), "{threads} threads, {n} items");
                    assert_eq!(calls.load(Ordering::Relaxed), n);
                    assert!(states.load(Ordering::Relaxed) <= if parallel { threads } else { 1 });
                }
            }
        }
    }
}
