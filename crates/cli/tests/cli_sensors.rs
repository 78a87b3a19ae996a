//! `edtmap run` with several sensors: `configs/ugv_corridor_camera.toml`'s
//! LiDAR and low depth camera into one map, the report per sensor, and
//! `--sensors` choosing some of them.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

fn edtmap(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap")).args(args).output().expect("edtmap runs");
    (o.status.success(), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

fn config() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/ugv_corridor_camera.toml")
}

fn run(out: &Path, extra: &[&str]) -> Value {
    let config = config();
    let mut args = vec!["run", "--config", config.to_str().expect("utf-8"), "--frames", "8", "--eval", "--out"];
    args.push(out.to_str().expect("utf-8"));
    args.extend_from_slice(extra);
    let (ok, stdout, stderr) = edtmap(&args);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("final map vs ground truth"), "{stdout}");
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report")).expect("json")
}

fn true_occupied(report: &Value) -> u64 {
    report["map_eval"]["true_occupied_voxels"].as_u64().expect("map_eval")
}

#[test]
fn two_sensors_map_together_and_the_report_names_each() {
    let dir = tempfile::tempdir().expect("tempdir");
    let both = run(&dir.path().join("both"), &[]);
    let sensors = both["sensors"].as_array().expect("sensors");
    assert_eq!(sensors.len(), 2);
    assert_eq!(sensors[0]["name"], "lidar_top");
    assert_eq!(sensors[0]["kind"], "spinning LiDAR");
    assert_eq!(sensors[1]["name"], "front_camera");
    assert_eq!(sensors[1]["kind"], "depth camera");
    for s in sensors {
        assert_eq!(s["frames_integrated"], 8, "{s}");
        assert_eq!(s["frames_skipped"], 0, "{s}");
    }
    let frames = both["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 16);
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(f["sensor"], ["lidar_top", "front_camera"][i % 2], "frame {i}");
        assert_eq!(f["index"], i / 2, "frame {i}: a time step gives one frame of each sensor");
        assert_eq!(f["global_max_m"], 0.0, "frame {i}: the EDT is exact");
    }
    // Each sensor's map alone misses occupied voxels the other one sees.
    let lidar = run(&dir.path().join("lidar"), &["--sensors", "lidar_top"]);
    let camera = run(&dir.path().join("camera"), &["--sensors", "front_camera"]);
    assert_eq!(lidar["sensors"].as_array().map(Vec::len), Some(1));
    assert_eq!(camera["sensor"], "depth camera", "the chosen sensor is the first");
    assert!(true_occupied(&both) > true_occupied(&lidar), "{} vs {}", true_occupied(&both), true_occupied(&lidar));
    assert!(true_occupied(&both) > true_occupied(&camera), "{} vs {}", true_occupied(&both), true_occupied(&camera));
}

#[test]
fn sensors_names_the_sensors_a_config_has() {
    let dir = tempfile::tempdir().expect("tempdir");
    let config = config();
    let args = ["run", "--config", config.to_str().expect("utf-8"), "--sensors", "sonar", "--out"];
    let (ok, _, stderr) = edtmap(&[&args[..], &[dir.path().to_str().expect("utf-8")]].concat());
    assert!(!ok && stderr.contains("--sensors sonar") && stderr.contains("lidar_top, front_camera"), "{stderr}");
}

#[test]
fn recordings_and_the_node_take_one_sensor_and_say_so() {
    let dir = tempfile::tempdir().expect("tempdir");
    let config = config();
    let config = config.to_str().expect("utf-8");
    let out = dir.path().to_str().expect("utf-8");
    let (ok, _, stderr) = edtmap(&["run", "--config", config, "--dataset", out, "--out", out]);
    assert!(!ok && stderr.contains("lists 2 [[sensors]]") && stderr.contains("replayed with one sensor"), "{stderr}");
    let (ok, _, stderr) = edtmap(&["node", "--config", config]);
    assert!(!ok && stderr.contains("the live node maps one sensor"), "{stderr}");
}
