//! Running the `edtmap` binary in the failure tests: with a time limit (a
//! hang fails the test instead of stalling the suite) and the checks every
//! refusal must pass.
#![allow(dead_code)] // each test file uses part of it

use std::ffi::OsStr;
use std::io::Read;
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// What a run of the binary did.
#[derive(Debug)]
pub(crate) struct Run {
    pub(crate) status: ExitStatus,
    pub(crate) stdout: String,
    pub(crate) stderr: String,
}

impl Run {
    /// The exit code; `None` when a signal ended the process.
    pub(crate) fn code(&self) -> Option<i32> {
        self.status.code()
    }
}

/// The binary, ready for arguments.
pub(crate) fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_edtmap"))
}

/// Runs `edtmap ARGS` in `dir` with no stdin, failing the test if it takes
/// longer than `limit`.
pub(crate) fn run_in<S: AsRef<OsStr>>(dir: &Path, args: &[S], limit: Duration) -> Run {
    let mut cmd = bin();
    cmd.args(args).current_dir(dir);
    wait_for(cmd, limit)
}

/// Runs `cmd` with stdout and stderr captured, killing it after `limit`.
pub(crate) fn wait_for(mut cmd: Command, limit: Duration) -> Run {
    let child =
        cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("the binary starts");
    finish(child, limit)
}

/// Reads all of `stream` (if piped) on a thread of its own.
fn read_all<R: Read + Send + 'static>(stream: Option<R>) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut s = String::new();
        if let Some(mut r) = stream {
            let _ = r.read_to_string(&mut s);
        }
        s
    })
}

/// Waits for `child`, killing it after `limit`; reads whatever of stdout
/// and stderr is still piped.
pub(crate) fn finish(mut child: Child, limit: Duration) -> Run {
    let readers = (read_all(child.stdout.take()), read_all(child.stderr.take()));
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("edtmap hung: still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Run { status, stdout: readers.0.join().expect("stdout"), stderr: readers.1.join().expect("stderr") }
}

/// A refusal as the failure rules want it: exit code 1 (never a panic's
/// 101 or an abort), one `edtmap: error:` line holding every one of
/// `needles`, and no panic message.
pub(crate) fn assert_refused(run: &Run, needles: &[&str]) {
    assert_eq!(run.code(), Some(1), "exit code, stderr:\n{}", run.stderr);
    assert!(!run.stderr.contains("panicked"), "a panic:\n{}", run.stderr);
    let errors: Vec<&str> = run.stderr.lines().filter(|l| l.starts_with("edtmap: error:")).collect();
    assert_eq!(errors.len(), 1, "one error line:\n{}", run.stderr);
    for n in needles {
        assert!(errors[0].contains(n), "the error should name {n:?}:\n{}", errors[0]);
    }
}

/// The bytes of a `uint8` npy file (version 1.0, C order) of `shape`
/// (NumPy's text, e.g. `"(4, 4)"`) holding `data`.
pub(crate) fn npy_u8(shape: &str, data: &[u8]) -> Vec<u8> {
    let mut text = format!("{{'descr': '|u1', 'fortran_order': False, 'shape': {shape}, }}");
    while (10 + text.len() + 1) % 64 != 0 {
        text.push(' ');
    }
    text.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(text.len() as u16).to_le_bytes());
    bytes.extend_from_slice(text.as_bytes());
    bytes.extend_from_slice(data);
    bytes
}

/// The shipped config `name` (configs/NAME.toml) as text.
pub(crate) fn shipped_config(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs").join(format!("{name}.toml"));
    std::fs::read_to_string(&path).expect("shipped config")
}

/// Seconds a short command may take in these tests (generous: the test
/// profile and a loaded 2-core machine).
pub(crate) const SHORT: Duration = Duration::from_secs(120);
