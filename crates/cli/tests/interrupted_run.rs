//! SIGINT and SIGTERM during `edtmap run`: the frame being integrated is
//! finished, then the report, pictures and `--save` map of every integrated
//! frame are written and the program exits with 128 + the signal; a second
//! signal stops at once without leaving a partial file.

mod common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Stdio};
use std::time::Duration;

/// Starts a long replay that logs every frame (`-vv`) and returns it once
/// it has integrated `frames` frames.
fn start_after(out: &Path, frames: usize) -> (Child, std::thread::JoinHandle<String>) {
    let save = out.join("map.edtmap");
    let mut child = common::bin()
        .args(["-vv", "run", "--scene", "room", "--frames", "100000", "--out"])
        .arg(out)
        .arg("--save")
        .arg(&save)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary starts");
    let mut lines = BufReader::new(child.stderr.take().expect("stderr")).lines();
    let mut seen = 0;
    let mut log = String::new();
    while seen < frames {
        let line = lines.next().expect("the run logs its frames").expect("utf-8");
        seen += usize::from(line.contains("ms") && line.contains("frame "));
        log.push_str(&line);
        log.push('\n');
    }
    // The rest of stderr, read until the process ends.
    let rest = std::thread::spawn(move || {
        for line in lines.map_while(Result::ok) {
            log.push_str(&line);
            log.push('\n');
        }
        log
    });
    (child, rest)
}

fn signal(child: &Child, sig: i32) {
    // SAFETY: kill(2) with the id of a child this test started and waits for.
    unsafe { libc::kill(child.id() as libc::pid_t, sig) };
}

fn wait(child: &mut Child) -> std::process::ExitStatus {
    for _ in 0..6000 {
        if let Some(status) = child.try_wait().expect("wait") {
            return status;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    panic!("the run did not stop within 60 s of the signal");
}

#[test]
fn sigint_and_sigterm_keep_the_frames_integrated() {
    for (sig, code, name) in [(libc::SIGINT, 130, "SIGINT"), (libc::SIGTERM, 143, "SIGTERM")] {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("out");
        let (mut child, log) = start_after(&out, 3);
        signal(&child, sig);
        let status = wait(&mut child);
        let log = log.join().expect("log");
        assert_eq!(status.code(), Some(code), "{name}: {log}");
        assert!(log.contains("interrupted by") && log.contains("integrated frames"), "{name}: {log}");
        let report: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("report.json")).expect("report")).expect("json");
        let frames = report["frames"].as_array().map(Vec::len).expect("frames");
        assert!((3..100000).contains(&frames), "{name}: {frames} frames");
        assert_eq!(report["interrupted"]["signal"], name);
        assert_eq!(report["interrupted"]["frames"].as_u64(), Some(frames as u64));
        for picture in ["occupancy_slice.png", "edt_slice.png", "timing.png"] {
            assert!(out.join(picture).metadata().is_ok_and(|m| m.len() > 0), "{name}: {picture}");
        }
        // The saved map is the map of the frames in the report: replaying
        // that many frames uninterrupted saves the same bytes.
        let again = dir.path().join("again");
        let run = common::run_in(
            dir.path(),
            &[
                "run",
                "--scene",
                "room",
                "--frames",
                &frames.to_string(),
                "--out",
                again.to_str().expect("utf-8"),
                "--save",
                again.join("map.edtmap").to_str().expect("utf-8"),
            ],
            Duration::from_secs(300),
        );
        assert!(run.status.success(), "{}", run.stderr);
        assert!(
            std::fs::read(out.join("map.edtmap")).expect("map")
                == std::fs::read(again.join("map.edtmap")).expect("map"),
            "{name}: the saved map differs"
        );
    }
}

#[test]
fn a_second_signal_stops_at_once_leaving_no_partial_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let (mut child, log) = start_after(&out, 2);
    signal(&child, libc::SIGINT);
    signal(&child, libc::SIGINT);
    let status = wait(&mut child);
    let log = log.join().expect("log");
    assert_eq!(status.code(), Some(130), "{log}");
    // Whatever was written is whole: no temporary is left, and a report,
    // if it got written, parses.
    let left: Vec<String> =
        std::fs::read_dir(&out).expect("out").flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    assert!(left.iter().all(|n| !n.ends_with(".tmp")), "{left:?}");
    if let Ok(bytes) = std::fs::read(out.join("report.json")) {
        serde_json::from_slice::<serde_json::Value>(&bytes).expect("a whole report");
    }
}

#[test]
fn an_interrupted_recording_is_closed_and_replays() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mcap = dir.path().join("planar.mcap");
    // 250,000 frames: some 18 s of recording in a release build (the
    // signal comes after 1.5 s), and about 1 GiB that `record` checks is
    // free before it starts.
    let mut child = common::bin()
        .args(["record", "--scene", "planar", "--frames", "250000"])
        .arg(&mcap)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary starts");
    std::thread::sleep(Duration::from_millis(1500));
    signal(&child, libc::SIGINT);
    let status = wait(&mut child);
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().expect("stderr"), &mut err).expect("stderr");
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("closed and replayable"), "{err}");
    let out = dir.path().join("out");
    let config = dir.path().join("planar.toml");
    let run = common::run_in(
        dir.path(),
        &[
            "run",
            "--config",
            config.to_str().expect("utf-8"),
            "--dataset",
            mcap.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
        ],
        Duration::from_secs(600),
    );
    assert!(run.status.success(), "{}", run.stderr);
}
