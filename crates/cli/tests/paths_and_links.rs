//! Outputs never write through a link into a file the user did not name,
//! and two outputs that are one file are refused before anything runs.

mod common;

use common::{assert_refused, run_in, SHORT};
use std::path::Path;

fn grid(path: &Path) {
    std::fs::write(path, common::npy_u8("(4, 4)", &[0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]))
        .expect("write grid");
}

#[cfg(unix)]
#[test]
fn outputs_that_are_links_are_refused_and_their_targets_kept() {
    use std::os::unix::fs::symlink;
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    std::fs::write(d.join("victim.txt"), "keep me").expect("write");
    std::fs::create_dir(d.join("out")).expect("mkdir");
    for name in ["report.json", "timing.png"] {
        let link = d.join("out").join(name);
        symlink(d.join("victim.txt"), &link).expect("link");
        let run = run_in(d, &["run", "--scene", "planar", "--frames", "2", "--out", "out"], SHORT);
        assert_refused(&run, &[name, "symbolic link"]);
        assert_eq!(std::fs::read_to_string(d.join("victim.txt")).expect("read"), "keep me");
        std::fs::remove_file(&link).expect("unlink");
    }
    grid(&d.join("g.npy"));
    symlink(d.join("victim.txt"), d.join("dist.npy")).expect("link");
    let run = run_in(d, &["edt", "g.npy", "dist.npy"], SHORT);
    assert_refused(&run, &["dist.npy", "symbolic link"]);
    assert_eq!(std::fs::read_to_string(d.join("victim.txt")).expect("read"), "keep me");
}

#[test]
fn two_outputs_that_are_one_file_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    grid(&d.join("in.npy"));
    let run = run_in(d, &["edt", "in.npy", "same.npy", "--nearest", "same.npy"], SHORT);
    assert_refused(&run, &["same.npy", "--nearest"]);
    let run = run_in(d, &["edt", "in.npy", "same.npy", "--nearest", "./same.npy"], SHORT);
    assert_refused(&run, &["same.npy", "--nearest"]);
    assert!(!d.join("same.npy").exists());
    let run =
        run_in(d, &["run", "--scene", "planar", "--frames", "1", "--out", "out", "--save", "out/report.json"], SHORT);
    assert_refused(&run, &["report.json", "--save"]);
    // The input may be replaced by the output: it is read first, and the
    // output is put in place whole.
    let run = run_in(d, &["edt", "in.npy", "in.npy"], SHORT);
    assert_eq!(run.code(), Some(0), "{}", run.stderr);
}

#[test]
fn record_keeps_a_config_it_was_not_asked_to_replace() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    std::fs::write(d.join("mydata.toml"), "# my own notes\n").expect("write");
    let run = run_in(d, &["record", "--scene", "planar", "--frames", "2", "mydata.mcap"], SHORT);
    assert_refused(&run, &["mydata.toml", "--force"]);
    assert_eq!(std::fs::read_to_string(d.join("mydata.toml")).expect("read"), "# my own notes\n");
    assert!(!d.join("mydata.mcap").exists(), "nothing recorded");
    let run = run_in(d, &["record", "--scene", "planar", "--frames", "2", "--force", "mydata.mcap"], SHORT);
    assert_eq!(run.code(), Some(0), "{}", run.stderr);
    assert!(std::fs::read_to_string(d.join("mydata.toml")).expect("read").contains("[dataset]"));
}
