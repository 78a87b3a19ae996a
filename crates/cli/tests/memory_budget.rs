//! Allocations sized by input are checked against the memory budget before
//! they happen: a window, a grid or a frame count too large is refused with
//! the size it would need and the setting to change, never an abort.

mod common;

use common::{assert_refused, run_in, shipped_config, SHORT};
use std::time::{Duration, Instant};

#[test]
fn a_tiny_voxel_size_is_refused_at_once() {
    let dir = tempfile::tempdir().expect("tempdir");
    let start = Instant::now();
    // 3·10⁸ voxels: some 14 GB in exact mode, more than the budget given.
    let run = run_in(
        dir.path(),
        &["run", "--scene", "uav_pillars", "--frames", "2", "--voxel-size", "0.01", "--max-memory", "8G"],
        SHORT,
    );
    assert_refused(&run, &["1000×1000×300", "--voxel-size", "--max-memory"]);
    assert!(start.elapsed() < Duration::from_secs(60), "refused before allocating");
    let run = run_in(dir.path(), &["run", "--scene", "uav_pillars", "--frames", "2", "--voxel-size", "0.001"], SHORT);
    assert_refused(&run, &["GiB", "voxel_size_m"]);
}

#[test]
fn a_huge_local_volume_in_the_config_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    for scene in ["uav_pillars", "room", "planar"] {
        let text: String = shipped_config(scene)
            .lines()
            .map(|l| {
                if l.starts_with("local_size_m") {
                    "local_size_m = [200.0, 200.0, 50.0]".to_string()
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let config = dir.path().join(format!("{scene}.toml"));
        std::fs::write(&config, text).expect("write");
        let run = run_in(
            dir.path(),
            &["run", "--config", config.to_str().expect("utf-8"), "--frames", "2", "--max-memory", "4G"],
            SHORT,
        );
        assert_refused(&run, &["200×200×50 m", "local_size_m", "4.0 GiB"]);
    }
}

#[test]
fn the_config_sets_the_budget_and_the_option_overrides_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let config = dir.path().join("c.toml");
    std::fs::write(&config, shipped_config("uav_pillars") + "\n[memory]\nmax = \"1M\"\n").expect("write");
    let c = config.to_str().expect("utf-8");
    let run = run_in(dir.path(), &["run", "--config", c, "--frames", "1"], SHORT);
    assert_refused(&run, &["1.0 MiB", "[memory] max"]);
    let run = run_in(dir.path(), &["run", "--config", c, "--frames", "1", "--max-memory", "2G", "--out", "o"], SHORT);
    assert_eq!(run.code(), Some(0), "{}", run.stderr);
    std::fs::write(&config, shipped_config("uav_pillars") + "\n[memory]\nmax = \"lots\"\n").expect("write");
    let run = run_in(dir.path(), &["run", "--config", c, "--frames", "1"], SHORT);
    assert_refused(&run, &["[memory]", "lots"]);
}

/// A sparse 1000³ u8 grid: 1 GB on disk that takes no space, 14 GB to
/// transform.
fn sparse_grid(path: &std::path::Path) {
    let header = common::npy_u8("(1000, 1000, 1000)", &[]);
    std::fs::write(path, &header).expect("write header");
    let f = std::fs::OpenOptions::new().write(true).open(path).expect("open");
    f.set_len(header.len() as u64 + 1_000_000_000).expect("sparse data");
}

#[test]
fn edt_of_a_grid_past_the_budget_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let grid = dir.path().join("big.npy");
    sparse_grid(&grid);
    let run = run_in(dir.path(), &["edt", "big.npy", "out.npy", "--max-memory", "2G"], SHORT);
    assert_refused(&run, &["big.npy", "1000, 1000, 1000", "--max-memory"]);
    assert!(!dir.path().join("out.npy").exists());
}

#[cfg(target_os = "linux")]
#[test]
fn edt_respects_the_address_space_limit() {
    if std::process::Command::new("prlimit").arg("--version").output().is_err() {
        eprintln!("skipped: no prlimit");
        return;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    sparse_grid(&dir.path().join("big.npy"));
    let mut cmd = std::process::Command::new("prlimit");
    cmd.args(["--as=8000000000", "--", env!("CARGO_BIN_EXE_edtmap"), "edt", "big.npy", "out.npy"])
        .current_dir(dir.path());
    let run = common::wait_for(cmd, SHORT);
    assert_refused(&run, &["big.npy", "RLIMIT_AS"]);
}

#[test]
fn a_huge_frame_count_reserves_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("r.mcap");
    let run =
        run_in(dir.path(), &["record", "--scene", "planar", "--frames", "2", rec.to_str().expect("utf-8")], SHORT);
    assert_eq!(run.code(), Some(0), "{}", run.stderr);
    for n in ["18446744073709551615", "100000000"] {
        let run = run_in(
            dir.path(),
            &["run", "--config", "r.toml", "--dataset", "r.mcap", "--frames", n, "--out", "o"],
            SHORT,
        );
        assert_refused(&run, &[n, "has 2 frames"]);
    }
    let run =
        run_in(dir.path(), &["record", "--scene", "planar", "--frames", "100000000000", "--force", "r.mcap"], SHORT);
    assert_refused(&run, &["--frames", "free"]);
    let run = run_in(dir.path(), &["run", "--config", "r.toml", "--dataset", "r.mcap", "--out", "o"], SHORT);
    assert_eq!(run.code(), Some(0), "the refused recording left the earlier one whole: {}", run.stderr);
}
