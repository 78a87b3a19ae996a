//! How many threads a frame runs on: rayon's whole pool while the
//! machine's cores are free, fewer while other processes keep some busy.
//!
//! The exact update and the occupancy stage share their loops among the
//! pool's threads and wait for the last piece. When another process holds
//! a core, the scheduler time-slices one of those threads against it: the
//! thread keeps a piece of work for a time slice (milliseconds) while the
//! others wait for it, and a frame on two threads costs more than on one.
//! [`FrameThreads`] watches what the other processes use (the kernel's
//! tick counts in `/proc/stat`, less this process's own time in
//! `/proc/self/stat`) and runs each frame on a pool of as many threads as
//! cores are left free, never more than the pool it was made on. Before a
//! window of ticks has passed, the first frame goes by the threads that
//! other processes have running or waiting for a core (`/proc/loadavg`,
//! less this process's running threads): the fewest of four counts over a
//! millisecond when it was made and one at the first frame. A recording
//! of a few frames is then on its threads from the start.

use std::time::{Duration, Instant};

/// Runs frames on as many threads as the machine has cores free; see the
/// module's documentation.
///
/// Linux only: elsewhere, or where `/proc` cannot be read, every frame
/// runs on the whole pool.
pub struct FrameThreads {
    /// The pool's size when made: the most threads a frame gets.
    full: usize,
    /// Threads the next frame runs on.
    now: usize,
    /// Stack size of the smaller pools' threads.
    stack_bytes: Option<usize>,
    /// The load when last looked at; `None` for a count that follows no
    /// load (fixed, one thread, or no `/proc`).
    last: Option<Sample>,
    /// Other processes' threads running when made, until the first frame
    /// has used it.
    first: Option<usize>,
    /// Smaller pools, made when first needed and kept.
    pools: Vec<(usize, rayon::ThreadPool)>,
}

/// The shortest time between two looks at the load: `/proc/stat` counts in
/// ticks of 10 ms per core, so a shorter window says little.
const WINDOW: Duration = Duration::from_millis(50);

/// How far the free cores must be from the threads in use before the
/// count changes (cores), so that a load near a boundary does not switch
/// back and forth.
const HYSTERESIS: f64 = 0.6;

impl Default for FrameThreads {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameThreads {
    /// Frames on the current rayon pool's threads (the global pool outside
    /// one), fewer while other processes keep cores busy.
    pub fn new() -> Self {
        Self::following(true)
    }

    /// Every frame on the whole pool, whatever the load.
    pub fn fixed() -> Self {
        Self::following(false)
    }

    fn following(load: bool) -> Self {
        let full = rayon::current_num_threads();
        let last = if load && full > 1 { Sample::take(Instant::now()) } else { None };
        let first = if last.is_some() { others_running_steadily() } else { None };
        Self { full, now: full, stack_bytes: None, last, first, pools: Vec::new() }
    }

    /// The smaller pools' threads get stacks of `bytes` (rayon's default
    /// otherwise): give them what the calling pool's threads have.
    pub fn with_stack_size(mut self, bytes: usize) -> Self {
        self.stack_bytes = Some(bytes);
        self
    }

    /// Threads the last [`FrameThreads::run`] ran on (the whole pool before
    /// the first).
    pub fn threads(&self) -> usize {
        self.now
    }

    /// Runs `op` (a frame) on as many threads as cores are free: on the
    /// whole pool, or installed in a smaller pool. A smaller pool that
    /// cannot be made leaves the frame on the whole pool.
    ///
    /// On the whole pool `op` runs on a thread of it: inline when the
    /// caller is one, else handed to one (`rayon::scope`), so that the
    /// frame's parallel loops start at once instead of each being handed
    /// to the pool while the caller waits.
    pub fn run<R: Send>(&mut self, op: impl FnOnce() -> R + Send) -> R {
        self.look();
        if self.now == self.full {
            return on_pool(op);
        }
        let at = match self.pools.iter().position(|(n, _)| *n == self.now) {
            Some(at) => at,
            None => {
                let mut builder = rayon::ThreadPoolBuilder::new().num_threads(self.now);
                if let Some(bytes) = self.stack_bytes {
                    builder = builder.stack_size(bytes);
                }
                match builder.build() {
                    Ok(pool) => {
                        self.pools.push((self.now, pool));
                        self.pools.len() - 1
                    }
                    Err(e) => {
                        tracing::debug!("a pool of {} threads: {e}; the frame runs on all {}", self.now, self.full);
                        self.now = self.full;
                        return on_pool(op);
                    }
                }
            }
        };
        self.pools[at].1.install(op)
    }

    /// Sets the thread count from the load since the last look, once a
    /// window has passed.
    fn look(&mut self) {
        let Some(last) = self.last else { return };
        let at = Instant::now();
        if let Some(then) = self.first.take() {
            // Both must see the load: a count may catch a passing task.
            if let Some(now) = others_running() {
                self.follow((last.cores as f64 - then.min(now) as f64).max(0.0));
            }
        }
        if at.duration_since(last.at) < WINDOW {
            return;
        }
        let Some(next) = Sample::take(at) else {
            // `/proc` went away: stay where we are.
            self.last = None;
            return;
        };
        // Too few ticks to say: the window grows until there are enough.
        if let Some(free) = next.free_cores(&last) {
            self.follow(free);
            self.last = Some(next);
        }
    }

    /// Moves to the threads `free` cores take, unless they are within
    /// [`HYSTERESIS`] of the threads in use.
    fn follow(&mut self, free: f64) {
        if (free - self.now as f64).abs() > HYSTERESIS {
            self.now = threads_for(free, self.full);
        }
    }
}

/// The fewest threads of other processes running in four counts a
/// quarter of a millisecond apart (a millisecond in all): a process that
/// keeps a core busy is in every count, a passing task in few.
fn others_running_steadily() -> Option<usize> {
    let mut fewest = others_running()?;
    for _ in 1..4 {
        if fewest == 0 {
            break;
        }
        std::thread::sleep(Duration::from_micros(250));
        fewest = fewest.min(others_running()?);
    }
    Some(fewest)
}

/// Threads of other processes running or waiting for a core now: the
/// kernel's count of runnable threads (`/proc/loadavg`'s fourth field,
/// `runnable/all`) less this process's threads that are running.
fn others_running() -> Option<usize> {
    let runnable = runnable_of(&std::fs::read_to_string("/proc/loadavg").ok()?)?;
    let mut own = 0;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        // A thread that ended since the listing is not running.
        if let Ok(stat) = std::fs::read_to_string(task.ok()?.path().join("stat")) {
            own += usize::from(state_of(&stat) == Some('R'));
        }
    }
    Some(runnable.saturating_sub(own))
}

/// The runnable threads in `/proc/loadavg` (`0.36 1.00 1.44 1/110 11774`).
fn runnable_of(loadavg: &str) -> Option<usize> {
    loadavg.split_whitespace().nth(3)?.split_once('/')?.0.parse().ok()
}

/// A thread's state in its `stat` file: the letter after the command's
/// closing parenthesis.
fn state_of(stat: &str) -> Option<char> {
    stat.get(stat.rfind(')')? + 1..)?.trim_start().chars().next()
}

/// Runs `op` on a thread of the current pool: inline on one, else handed
/// to one.
fn on_pool<R: Send>(op: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() {
        op()
    } else {
        rayon::scope(|_| op())
    }
}

/// The threads that `free` cores take, between one and `full`.
fn threads_for(free: f64, full: usize) -> usize {
    let rounded = (free + 0.5).floor();
    if rounded < 1.0 {
        1
    } else {
        (rounded as usize).min(full)
    }
}

/// The kernel's counts at one moment, in ticks.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    at: Instant,
    /// Cores' time busy (user, nice, system, interrupts, stolen by a
    /// hypervisor), all cores.
    busy: u64,
    /// Busy plus idle and waiting for I/O, all cores.
    total: u64,
    /// This process's time (user and system), all its threads.
    own: u64,
    cores: usize,
}

impl Sample {
    fn take(at: Instant) -> Option<Self> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let own = std::fs::read_to_string("/proc/self/stat").ok()?;
        Self::parse(at, &stat, &own)
    }

    /// Reads `/proc/stat` (its `cpu` line and the count of `cpuN` lines)
    /// and `/proc/self/stat` (fields 14 and 15, `utime` and `stime`).
    fn parse(at: Instant, stat: &str, own: &str) -> Option<Self> {
        let mut lines = stat.lines();
        let counts: Vec<u64> =
            lines.next()?.strip_prefix("cpu ")?.split_whitespace().map(|v| v.parse().ok()).collect::<Option<_>>()?;
        // user nice system idle iowait irq softirq steal (guest time is
        // within user and nice).
        let field = |i: usize| counts.get(i).copied().unwrap_or(0);
        let busy = field(0) + field(1) + field(2) + field(5) + field(6) + field(7);
        let total = busy + field(3) + field(4);
        let cores = lines.take_while(|l| l.starts_with("cpu")).count();
        // The command name (field 2) may hold spaces and parentheses; the
        // fields after its last ')' start with field 3.
        let mut after = own.get(own.rfind(')')? + 1..)?.split_whitespace();
        let utime: u64 = after.nth(11)?.parse().ok()?;
        let stime: u64 = after.next()?.parse().ok()?;
        (cores > 0).then_some(Self { at, busy, total, own: utime + stime, cores })
    }

    /// Cores the other processes left free between `before` and `self`;
    /// `None` for too few ticks to say.
    fn free_cores(&self, before: &Sample) -> Option<f64> {
        let total = self.total.checked_sub(before.total)?;
        if total < 4 * self.cores as u64 {
            return None;
        }
        let busy = self.busy.saturating_sub(before.busy);
        let own = self.own.saturating_sub(before.own);
        let others = busy.saturating_sub(own) as f64 / total as f64 * self.cores as f64;
        Some((self.cores as f64 - others).max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STAT: &str = "cpu  6040450 1 560273 2697640 25470 0 4176 2022 0 0\n\
                        cpu0 2889794 0 270442 1493918 7507 0 536 1013 0 0\n\
                        cpu1 3150656 0 289830 1203722 17963 0 3639 1008 0 0\n\
                        intr 35851350 0 0\nctxt 1\n";

    fn own(utime: u64, stime: u64) -> String {
        format!("4242 (a (b) c) R 1 2 3 4 5 6 7 8 9 10 {utime} {stime} 0 0 20 0 3 0 99 0 0")
    }

    #[test]
    fn the_kernels_counts_are_read_field_by_field() {
        let at = Instant::now();
        let s = Sample::parse(at, STAT, &own(300, 20)).expect("parses");
        assert_eq!(s.busy, 6040450 + 1 + 560273 + 4176 + 2022);
        assert_eq!(s.total, s.busy + 2697640 + 25470);
        assert_eq!((s.own, s.cores), (320, 2));
        assert_eq!(Sample::parse(at, "intr 1\n", &own(1, 1)), None);
        assert_eq!(Sample::parse(at, STAT, "4242 (cut"), None);
    }

    /// Two cores for one second (200 ticks): another process busy on one
    /// of them leaves one free, whatever this process did.
    #[test]
    fn free_cores_are_what_other_processes_leave() {
        let at = Instant::now();
        let before = Sample { at, busy: 1000, total: 5000, own: 100, cores: 2 };
        let after = |busy: u64, own: u64| Sample { at, busy: 1000 + busy, total: 5200, own: 100 + own, cores: 2 };
        let free = |s: Sample| s.free_cores(&before).expect("enough ticks");
        // Quiet: this process alone, on one core or both.
        assert!((free(after(100, 100)) - 2.0).abs() < 1e-9);
        assert!((free(after(200, 200)) - 2.0).abs() < 1e-9);
        // Another process spinning on one core.
        assert!((free(after(200, 100)) - 1.0).abs() < 1e-9);
        assert!((free(after(180, 60)) - 0.8).abs() < 1e-9);
        // Both cores taken by others.
        assert!(free(after(200, 0)).abs() < 1e-9);
        // Too short a window (fewer than 4 ticks a core).
        let soon = Sample { at, busy: 1005, total: 5007, own: 100, cores: 2 };
        assert_eq!(soon.free_cores(&before), None);
    }

    #[test]
    fn the_run_queue_and_a_threads_state_are_read() {
        assert_eq!(runnable_of("0.36 1.00 1.44 3/110 11774\n"), Some(3));
        assert_eq!(runnable_of("0.36 1.00 1.44"), None);
        assert_eq!(state_of(&own(1, 1)), Some('R'));
        assert_eq!(state_of("77 (x) y) S 1 2"), Some('S'));
        assert_eq!(state_of("77 (x"), None);
        // This thread runs while it counts: others never include it.
        if let (Some(all), Some(others)) =
            (std::fs::read_to_string("/proc/loadavg").ok().and_then(|l| runnable_of(&l)), others_running())
        {
            assert!(others < all.max(1), "{others} of {all}");
        }
    }

    #[test]
    fn threads_follow_the_free_cores_within_the_pool() {
        assert_eq!(threads_for(0.0, 2), 1);
        assert_eq!(threads_for(0.8, 2), 1);
        assert_eq!(threads_for(1.4, 2), 1);
        assert_eq!(threads_for(1.6, 2), 2);
        assert_eq!(threads_for(7.6, 2), 2);
        assert_eq!(threads_for(6.2, 16), 6);
    }

    /// A frame from outside the pool runs on a thread of it.
    #[test]
    fn a_frame_from_outside_the_pool_runs_on_it() {
        let mut threads = FrameThreads::fixed();
        let on = std::thread::spawn(move || threads.run(rayon::current_thread_index)).join().expect("joins");
        assert!(on.is_some());
    }

    /// A frame run on a smaller pool runs there, on the threads chosen.
    #[test]
    fn a_frame_runs_on_the_threads_chosen() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().expect("a pool");
        pool.install(|| {
            let mut threads = FrameThreads::fixed();
            assert_eq!(threads.run(rayon::current_num_threads), 3);
            threads.now = 1;
            assert_eq!(threads.run(rayon::current_num_threads), 1);
            assert_eq!(threads.pools.len(), 1);
            threads.now = 2;
            assert_eq!(threads.run(rayon::current_num_threads), 2);
            threads.now = 1;
            assert_eq!(threads.run(rayon::current_num_threads), 1);
            assert_eq!(threads.pools.len(), 2);
        });
    }
}
