//! Inputs that are not regular files (FIFOs, devices, folders) are refused
//! at once with a message saying what they are, instead of blocking or
//! being read until memory runs out.

mod common;

use common::{assert_refused, run_in, SHORT};
use std::path::Path;

fn mkfifo(path: &Path) -> bool {
    std::process::Command::new("mkfifo").arg(path).status().is_ok_and(|s| s.success())
}

#[cfg(unix)]
#[test]
fn devices_are_refused_wherever_a_file_is_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let saved = run_in(d, &["run", "--scene", "planar", "--frames", "1", "--out", "o", "--save", "m.edtmap"], SHORT);
    assert_eq!(saved.code(), Some(0), "{}", saved.stderr);
    for dev in ["/dev/zero", "/dev/urandom"] {
        assert_refused(
            &run_in(d, &["run", "--scene", "planar", "--config", dev, "--frames", "1", "--out", "o"], SHORT),
            &[dev, "character device"],
        );
        assert_refused(
            &run_in(d, &["run", "--scene", "planar", "--prior", dev, "--frames", "1", "--out", "o"], SHORT),
            &[dev, "character device"],
        );
        assert_refused(&run_in(d, &["info", dev], SHORT), &[dev, "character device"]);
        assert_refused(&run_in(d, &["query", "m.edtmap", "--points", dev], SHORT), &[dev, "character device"]);
        assert_refused(&run_in(d, &["edt", dev, "out.npy"], SHORT), &[dev, "character device"]);
    }
    assert_refused(&run_in(d, &["info", "o"], SHORT), &["directory"]);
}

#[cfg(unix)]
#[test]
fn fifos_are_refused_without_blocking() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    if !mkfifo(&d.join("fifo.npy")) || !mkfifo(&d.join("fifo.toml")) {
        eprintln!("skipped: no mkfifo");
        return;
    }
    assert_refused(&run_in(d, &["edt", "fifo.npy", "out.npy"], SHORT), &["fifo.npy", "FIFO"]);
    assert_refused(
        &run_in(d, &["run", "--scene", "planar", "--config", "fifo.toml", "--frames", "1", "--out", "o"], SHORT),
        &["fifo.toml", "FIFO"],
    );
    // A FIFO named like a frame of a cloud folder.
    let clouds = d.join("clouds");
    std::fs::create_dir(&clouds).expect("mkdir");
    assert!(mkfifo(&clouds.join("000000.pcd")));
    std::fs::write(clouds.join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n").expect("poses");
    let run = run_in(
        d,
        &[
            "run",
            "--config",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../configs/velodyne.toml"),
            "--dataset",
            "clouds",
            "--out",
            "o",
        ],
        SHORT,
    );
    assert_refused(&run, &["000000.pcd", "FIFO"]);
}
