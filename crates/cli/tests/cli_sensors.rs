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
fn folders_take_one_sensor_and_the_node_sensors_of_ros_messages() {
    let dir = tempfile::tempdir().expect("tempdir");
    let config = config();
    let config = config.to_str().expect("utf-8");
    let out = dir.path().to_str().expect("utf-8");
    let (ok, _, stderr) = edtmap(&["run", "--config", config, "--dataset", out, "--out", out]);
    assert!(!ok && stderr.contains("lists 2 [[sensors]]") && stderr.contains("holds one sensor's frames"), "{stderr}");
    // The node takes every sensor, each from its ROS message: a spinning
    // LiDAR's range images are not one, and the entry is named.
    let (ok, _, stderr) = edtmap(&["node", "--config", config]);
    assert!(!ok && stderr.contains("[[sensors]] \"lidar_top\" kind = \"lidar\" takes range images"), "{stderr}");
}

/// Occupied voxels in `--ply`'s `occupied.ply`.
fn occupied_in_ply(out: &Path) -> u64 {
    let bytes = std::fs::read(out.join("occupied.ply")).expect("occupied.ply");
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(512)]).to_string();
    let line = head.lines().find(|l| l.starts_with("element vertex")).expect("vertex count");
    line.rsplit(' ').next().and_then(|n| n.parse().ok()).expect("a number")
}

fn replay(config: &Path, recording: &Path, out: &Path, extra: &[&str]) -> Value {
    let save = out.join("map.edtmap");
    let mut args = vec!["run", "--config", config.to_str().expect("utf-8"), "--dataset"];
    args.extend([recording.to_str().expect("utf-8"), "--ply", "--save", save.to_str().expect("utf-8")]);
    args.extend(["--out", out.to_str().expect("utf-8")]);
    args.extend_from_slice(extra);
    let (ok, stdout, stderr) = edtmap(&args);
    assert!(ok, "{stdout}\n{stderr}");
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report")).expect("json")
}

#[test]
fn a_two_sensor_recording_replays_every_sensor() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let config = config();
    for ext in ["mcap", "bag"] {
        let rec = d.join(format!("two.{ext}"));
        let (ok, stdout, stderr) = edtmap(&[
            "record",
            "--config",
            config.to_str().expect("utf-8"),
            "--frames",
            "6",
            "--force",
            rec.to_str().expect("utf-8"),
        ]);
        assert!(ok && stdout.contains("/lidar_top/points, /front_camera/depth/image"), "{stdout}\n{stderr}");
    }
    let replay_config = d.join("two.toml");
    let text = std::fs::read_to_string(&replay_config).expect("replay config");
    assert!(text.contains("topic = \"/front_camera/depth/image\"") && text.contains("sensor_in_body"), "{text}");

    let both = replay(&replay_config, &d.join("two.mcap"), &d.join("both"), &[]);
    let sensors = both["sensors"].as_array().expect("sensors");
    assert_eq!(sensors.len(), 2);
    for (s, (name, kind)) in sensors.iter().zip([("lidar_top", "point cloud"), ("front_camera", "depth camera")]) {
        assert_eq!((s["name"].as_str(), s["kind"].as_str()), (Some(name), Some(kind)), "{s}");
        assert_eq!((s["frames_integrated"].as_u64(), s["frames_skipped"].as_u64()), (Some(6), Some(0)), "{s}");
    }
    // In the recorded order, each indexed among its sensor's frames.
    let frames = both["frames"].as_array().expect("frames");
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(f["sensor"], ["lidar_top", "front_camera"][i % 2], "frame {i}");
        assert_eq!(f["index"], i / 2, "frame {i}");
    }
    // A ROS 1 bag (its own encoding and reader) of the same frames makes
    // the same map, byte for byte.
    replay(&replay_config, &d.join("two.bag"), &d.join("bag"), &[]);
    let map = |out: &str| std::fs::read(d.join(out).join("map.edtmap")).expect("saved map");
    assert!(map("both") == map("bag"), "the MCAP's and the bag's maps differ");
    // Each sensor alone sees less of the corridor than both together.
    let lidar = replay(&replay_config, &d.join("two.mcap"), &d.join("lidar"), &["--sensors", "lidar_top"]);
    replay(&replay_config, &d.join("two.mcap"), &d.join("camera"), &["--sensors", "front_camera"]);
    assert_eq!(lidar["sensors"].as_array().map(Vec::len), Some(1));
    let occupied = |out: &str| occupied_in_ply(&d.join(out));
    assert!(occupied("both") > occupied("lidar") && occupied("both") > occupied("camera"));

    // One sensor's topic missing from the recording: the other is
    // replayed, and the report says the missing one gave nothing.
    let wrong = text.replace("/front_camera/depth/image", "/front/depth/image");
    let wrong_config = d.join("wrong.toml");
    std::fs::write(&wrong_config, wrong).expect("write");
    let one = replay(&wrong_config, &d.join("two.mcap"), &d.join("one"), &[]);
    let sensors = one["sensors"].as_array().expect("sensors");
    assert_eq!(sensors[0]["frames_integrated"], 6);
    assert_eq!(sensors[1]["frames_integrated"], 0);
    assert!(map("one") == map("lidar"), "without the camera's topic, the LiDAR's map alone");
}

#[test]
fn several_sensors_replayed_from_a_recording_need_their_topics() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let config = config();
    let rec = d.join("two.mcap");
    let (ok, _, stderr) =
        edtmap(&["record", "--config", config.to_str().expect("utf-8"), "--frames", "2", rec.to_str().expect("utf-8")]);
    assert!(ok, "{stderr}");
    let text = std::fs::read_to_string(d.join("two.toml")).expect("replay config");
    let cases = [
        (text.replace("topic = \"/lidar_top/points\"\n", ""), "[[sensors]] \"lidar_top\" has no topic"),
        (
            text.replace("pose_topic = \"/odom\"", "pose_topic = \"/odom\"\nsensor_topic = \"/points\""),
            "[dataset] sensor_topic is for a lone [sensor]",
        ),
        (
            text.replace("\"/front_camera/depth/image\"", "\"/lidar_top/points\"").replace(
                "topic = \"/lidar_top/points\"\n\n[[sensors]]",
                "topic = \"/front_camera/depth/image\"\n\n[[sensors]]",
            ),
            "carries sensor_msgs/Image, but kind = \"points\" takes sensor_msgs/PointCloud2",
        ),
        (
            text.replacen(
                "kind = \"points\"",
                "kind = \"lidar\"\nrings = 16\nelevation_min_deg = -15.0\nelevation_max_deg = 15.0\nazimuth_bins = 900",
                1,
            ),
            "[[sensors]] \"lidar_top\": kind = \"lidar\" takes range images, which no ROS message carries",
        ),
    ];
    for (i, (text, want)) in cases.iter().enumerate() {
        let path = d.join(format!("bad{i}.toml"));
        std::fs::write(&path, text).expect("write");
        let out = d.join(format!("out{i}"));
        let (ok, _, stderr) = edtmap(&[
            "run",
            "--config",
            path.to_str().expect("utf-8"),
            "--dataset",
            rec.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
        ]);
        assert!(!ok && stderr.contains(want), "case {i}: {stderr}");
    }
}
