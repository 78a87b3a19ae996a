//! Standard output that a closed pipe or a full disk cannot crash.
//!
//! `println!` panics when stdout fails. Here a closed pipe (`edtmap demo |
//! head -1`) makes the rest of the output go nowhere while the job goes on
//! and finishes (its files are still written), and the program exits as it
//! would have; any other failure (`> /dev/full`) is kept and reported by
//! [`finish`], which makes the program fail.

use std::fmt;
use std::io::{self, ErrorKind, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// Set once stdout's reader has gone.
static CLOSED: AtomicBool = AtomicBool::new(false);
/// The first write error other than a closed pipe.
static FAILED: Mutex<Option<io::Error>> = Mutex::new(None);

/// Prints one line on stdout (the body of [`outln!`]).
pub(crate) fn line(args: fmt::Arguments<'_>) {
    if CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = io::stdout().lock();
    let written = out.write_fmt(args).and_then(|()| out.write_all(b"\n"));
    if let Err(e) = written {
        record(e);
    }
}

/// Notes a stdout write error: a closed pipe silences what follows; any
/// other error is kept for [`finish`].
pub(crate) fn record(e: io::Error) {
    CLOSED.store(true, Ordering::Relaxed);
    if e.kind() != ErrorKind::BrokenPipe {
        if let Ok(mut slot) = FAILED.lock() {
            slot.get_or_insert(e);
        }
    }
}

/// Flushes stdout; the error that made output fail, if any, other than a
/// closed pipe.
pub(crate) fn finish() -> Option<io::Error> {
    if !CLOSED.load(Ordering::Relaxed) {
        if let Err(e) = io::stdout().lock().flush() {
            record(e);
        }
    }
    FAILED.lock().ok().and_then(|mut slot| slot.take())
}

/// `println!` that survives a closed pipe and reports a full disk; see
/// the module docs.
macro_rules! outln {
    ($($arg:tt)*) => {
        $crate::output::line(format_args!($($arg)*))
    };
}
