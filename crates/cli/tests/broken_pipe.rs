//! A closed stdout (`| head -1`) is a quiet exit that still finishes the
//! job's files; a full stdout (`> /dev/full`) is an error message and a
//! failing exit code. Never a panic.

mod common;

use common::{bin, finish, run_in, SHORT};
use std::io::{BufRead, BufReader};
use std::process::Stdio;

/// Runs `args` in `dir`, reads one line of stdout and closes the pipe.
fn head_1(dir: &std::path::Path, args: &[&str]) -> common::Run {
    let mut child = bin()
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start");
    let stdout = child.stdout.take().expect("stdout");
    let mut first = String::new();
    BufReader::new(stdout).read_line(&mut first).expect("one line");
    // The reader was dropped: the pipe is closed.
    let mut run = finish(child, SHORT);
    run.stdout = first;
    run
}

#[cfg(unix)]
#[test]
fn a_closed_pipe_is_a_quiet_exit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    for args in [
        &["demo", "--frames", "3", "--out", "demo"][..],
        &["run", "--scene", "room", "--frames", "3", "--out", "d", "--save", "m.edtmap"],
        &["info", "m.edtmap"],
    ] {
        let run = head_1(d, args);
        assert_eq!(run.code(), Some(0), "{args:?}: {}", run.stderr);
        assert!(!run.stderr.contains("panicked") && !run.stderr.contains("error"), "{args:?}: {}", run.stderr);
        assert!(!run.stdout.is_empty(), "{args:?} printed its first line");
    }
    assert!(d.join("demo/report.json").exists() && d.join("d/edt_slice.png").exists(), "the job finished its files");
}

#[cfg(unix)]
#[test]
fn a_full_stdout_is_an_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
        eprintln!("skipped: no /dev/full");
        return;
    };
    let child = bin()
        .args(["demo", "--frames", "2", "--out", "o"])
        .current_dir(dir.path())
        .stdin(Stdio::null())
        .stdout(full)
        .stderr(Stdio::piped())
        .spawn()
        .expect("start");
    let run = finish(child, SHORT);
    assert_eq!(run.code(), Some(1), "{}", run.stderr);
    assert!(
        run.stderr.contains("cannot write to standard output") && !run.stderr.contains("panicked"),
        "{}",
        run.stderr
    );
    // The job's files were still written whole.
    let info = run_in(dir.path(), &["info", "o/map.edtmap"], SHORT);
    assert_eq!(info.code(), Some(0), "{}", info.stderr);
}
