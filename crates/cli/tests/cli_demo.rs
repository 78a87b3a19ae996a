//! `edtmap demo` and `edtmap run` end to end on short runs.

use std::process::Command;

fn edtmap(args: &[&str], out: &std::path::Path) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap")).args(args).arg("--out").arg(out).output().expect("edtmap runs");
    (o.status.success(), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

fn is_png(path: &std::path::Path) -> bool {
    std::fs::read(path).map(|b| b.starts_with(b"\x89PNG\r\n\x1a\n")).unwrap_or(false)
}

#[test]
fn demo_writes_report_and_pictures() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let (ok, stdout, stderr) = edtmap(&["demo", "--frames", "4"], &out);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("EDT update median") && stdout.contains("precision"), "{stdout}");
    assert!(is_png(&out.join("edt_slice.png")) && is_png(&out.join("occupancy_slice.png")));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report")).expect("json");
    assert_eq!(report["scene"], "uav_pillars");
    assert_eq!(report["frames"].as_array().map(Vec::len), Some(4));
    let frame = &report["frames"][3];
    assert!(
        report["stages"]["integrate_ms"].is_string() && report["stages"].get("batch_edt_ms").is_none(),
        "{}",
        report["stages"]
    );
    for key in [
        "ogm_ms",
        "integrate_ms",
        "total_ms",
        "voxels_updated",
        "precision",
        "recall",
        "change_score_m",
        "map_bytes",
        "local_rms_m",
        "global_rms_m",
        "global_max_m",
    ] {
        assert!(frame[key].is_number(), "frame lacks {key}: {frame}");
    }
    assert!(report["summary"]["ogm_ms"]["p95"].is_number());
    assert!(out.join("map.edtmap").exists(), "the demo saves its map");
}

#[test]
fn run_every_scene_briefly() {
    for scene in ["uav_pillars", "ugv_corridor", "room", "planar"] {
        let dir = tempfile::tempdir().expect("tempdir");
        let (ok, stdout, stderr) =
            edtmap(&["run", "--scene", scene, "--frames", "2", "--construction", "raycast"], dir.path());
        assert!(ok, "{scene}: {stdout}\n{stderr}");
        assert!(dir.path().join("report.json").exists(), "{scene}");
        assert!(!stdout.contains("precision"), "no --eval, no scores: {stdout}");
    }
}

#[test]
fn report_states_map_bytes_per_voxel_and_peak_memory() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ok, stdout, stderr) = edtmap(&["run", "--scene", "uav_pillars", "--frames", "2"], dir.path());
    assert!(ok, "{stdout}\n{stderr}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("report.json")).expect("report")).expect("json");
    for frame in report["frames"].as_array().expect("frames") {
        let per_voxel = frame["map_bytes_per_mapped_voxel"].as_f64().expect("map_bytes_per_mapped_voxel");
        assert!((1.0..10_000.0).contains(&per_voxel), "{frame}");
    }
    assert!(report["summary"]["map_bytes_per_mapped_voxel"]["median"].is_number());
    if cfg!(target_os = "linux") {
        let peak = report["peak_rss_bytes"].as_u64().expect("peak_rss_bytes on Linux");
        let per_window_voxel = report["peak_bytes_per_window_voxel"].as_f64().expect("peak_bytes_per_window_voxel");
        let dims: Vec<u64> =
            report["local_dims"].as_array().expect("local_dims").iter().filter_map(|d| d.as_u64()).collect();
        let window: u64 = dims.iter().product();
        assert!(peak > 0 && per_window_voxel > 0.0, "{report}");
        assert!((per_window_voxel - peak as f64 / window as f64).abs() < 1e-6 * per_window_voxel, "{report}");
    } else {
        assert!(report["peak_rss_bytes"].is_u64() || report["peak_rss_bytes"].is_null());
    }
}

#[test]
fn run_refuses_bad_arguments() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (ok, _, stderr) = edtmap(&["run", "--scene", "moon"], dir.path());
    assert!(!ok && stderr.contains("moon") && stderr.contains("uav_pillars"), "{stderr}");
    let (ok, _, stderr) = edtmap(&["run"], dir.path());
    assert!(!ok && stderr.contains("--scene"), "{stderr}");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[sensor]\nkind = \"lidar\"\n").expect("write");
    let (ok, _, stderr) = edtmap(&["run", "--config", bad.to_str().expect("utf-8")], dir.path());
    assert!(!ok && stderr.contains("bad.toml") && !stderr.contains("panicked"), "{stderr}");
    let (ok, _, stderr) = edtmap(&["run", "--scene", "planar", "--frames", "0"], dir.path());
    assert!(!ok && stderr.contains("--frames"), "{stderr}");
}
