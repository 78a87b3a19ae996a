//! A run that did nothing useful does not exit 0: when every frame is
//! refused the run fails, says why, writes the report of what it refused,
//! and leaves an earlier map in place.

mod common;

use common::{assert_refused, run_in, shipped_config, SHORT};

#[test]
fn a_run_whose_every_frame_was_skipped_fails_and_keeps_the_old_map() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let good = run_in(d, &["run", "--scene", "planar", "--frames", "1", "--out", "o", "--save", "m.edtmap"], SHORT);
    assert_eq!(good.code(), Some(0), "{}", good.stderr);
    let map_before = std::fs::read(d.join("m.edtmap")).expect("map");
    let clouds = d.join("clouds");
    std::fs::create_dir(&clouds).expect("mkdir");
    for i in 0..3 {
        std::fs::write(clouds.join(format!("{i:06}.pcd")), "this is not a point cloud\n").expect("write");
    }
    std::fs::write(clouds.join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n".repeat(3)).expect("write");
    let config = d.join("skip.toml");
    std::fs::write(&config, shipped_config("velodyne") + "\n[dataset]\non_error = \"skip\"\n").expect("write");
    let run = run_in(
        d,
        &["run", "--config", "skip.toml", "--dataset", "clouds", "--out", "o2", "--save", "m.edtmap", "--ply"],
        SHORT,
    );
    assert_refused(&run, &["no frame was integrated", "3 frames were skipped", "000000.pcd", "report.json"]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("o2/report.json")).expect("report")).expect("json");
    assert_eq!(report["skipped"].as_array().map(Vec::len), Some(3), "{report}");
    assert!(!d.join("o2/occupied.ply").exists() && !d.join("o2/edt_slice.png").exists(), "no empty outputs");
    assert_eq!(std::fs::read(d.join("m.edtmap")).expect("map"), map_before, "the earlier map is kept");
    assert!(!run.stdout.contains("NaN"), "{}", run.stdout);
}
