//! Ctrl-C (SIGINT) and SIGTERM for the commands that write outputs.
//!
//! A long replay that is interrupted keeps its work: the first signal asks
//! the run to stop after the frame it is integrating, and the run then
//! writes its report, pictures and map of what was integrated and exits
//! with 128 + the signal (130 for SIGINT, 143 for SIGTERM). A second signal
//! stops at once: the temporaries of outputs being written are removed (the
//! targets keep their previous contents, as with any failed atomic write)
//! and the process exits with the same code. Commands with nothing to keep
//! part-way (one transform) stop at once on the first signal.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicI32, AtomicUsize, Ordering::SeqCst};
use std::sync::{Mutex, Once, PoisonError};
use std::time::Duration;

/// The first signal received (0: none).
static FIRST: AtomicI32 = AtomicI32::new(0);
/// Signals received.
static COUNT: AtomicUsize = AtomicUsize::new(0);
/// Signals that stop at once: 1 to abandon on the first, 2 to finish first.
static AT_ONCE: AtomicUsize = AtomicUsize::new(2);
/// Folders whose temporaries are removed when the process stops at once.
static OUTPUT_DIRS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

extern "C" fn on_signal(signo: libc::c_int) {
    let _ = FIRST.compare_exchange(0, signo, SeqCst, SeqCst);
    COUNT.fetch_add(1, SeqCst);
}

/// What the first signal does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum OnFirst {
    /// Ask the command to finish its current step and write what it has
    /// ([`requested`]); the second signal stops at once.
    Finish,
    /// Stop at once.
    Abandon,
}

/// Catches SIGINT and SIGTERM from now on; outputs are written into
/// `dirs` (their temporaries are removed if the process stops at once).
pub(crate) fn catch(on_first: OnFirst, dirs: &[&Path]) {
    AT_ONCE.store(if on_first == OnFirst::Abandon { 1 } else { 2 }, SeqCst);
    OUTPUT_DIRS.lock().unwrap_or_else(PoisonError::into_inner).extend(dirs.iter().map(|d| d.to_path_buf()));
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
        // SAFETY: the handler only updates atomics, which is async-signal-safe.
        unsafe {
            libc::signal(libc::SIGINT, handler);
            libc::signal(libc::SIGTERM, handler);
        }
        // The work of stopping at once (removing files, exiting) is not
        // async-signal-safe: a watcher thread does it.
        let _ = std::thread::Builder::new().name("edtmap-signals".into()).spawn(watch);
    });
}

fn watch() {
    loop {
        std::thread::sleep(Duration::from_millis(20));
        if COUNT.load(SeqCst) >= AT_ONCE.load(SeqCst) {
            stop_now();
        }
    }
}

/// Removes the outputs' temporaries and exits with 128 + the signal.
fn stop_now() -> ! {
    let signal = FIRST.load(SeqCst);
    for dir in OUTPUT_DIRS.lock().unwrap_or_else(PoisonError::into_inner).iter() {
        edtmap_io::files::remove_own_temporaries(dir);
    }
    let _ = std::io::Write::write_all(
        &mut std::io::stderr(),
        format!("edtmap: {}: stopped at once, no partial file left\n", name(signal)).as_bytes(),
    );
    // SAFETY: _exit ends the process without running destructors or
    // flushing buffers, which other threads may be using.
    unsafe { libc::_exit(128 + signal) }
}

/// The signal that asked the command to stop, if one did.
pub(crate) fn requested() -> Option<i32> {
    match FIRST.load(SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// The signal's name.
pub(crate) fn name(signal: i32) -> &'static str {
    match signal {
        libc::SIGINT => "SIGINT (Ctrl-C)",
        libc::SIGTERM => "SIGTERM",
        _ => "a signal",
    }
}

/// A command that stopped at a signal after writing what it had; the
/// program exits with 128 + the signal.
#[derive(Debug)]
pub(crate) struct Interrupted {
    /// The signal.
    pub(crate) signal: i32,
    /// What was done and written.
    pub(crate) what: String,
}

impl Interrupted {
    /// The exit status: 128 + the signal.
    pub(crate) fn exit_code(&self) -> u8 {
        u8::try_from(128 + self.signal).unwrap_or(1)
    }
}

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "interrupted by {}: {}", name(self.signal), self.what)
    }
}

impl std::error::Error for Interrupted {}
