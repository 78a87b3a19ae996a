//! `edtmap run --dataset FILE.bag|FILE.mcap`: recordings written here of a
//! LiDAR driving past a wall, replayed end to end; the map's occupied
//! voxels must lie on the wall, and a damaged recording keeps the frames
//! before the damage under both `on_error` policies.

#[path = "../../ros/tests/common/mod.rs"]
mod common;

use common::{write_recording, Container, Msg};
use edtmap_ros::msg::{Header, Message, PointCloud2, StampedTransform};
use nalgebra::{Isometry3, Point3, Vector3};
use std::path::Path;
use std::process::{Command, Output};

const CONTAINERS: [Container; 2] = [Container::Bag, Container::Mcap];

/// The robot at `t`: along y at 0.5 m/s, turning slowly.
fn body_at(t: f64) -> Isometry3<f64> {
    Isometry3::new(Vector3::new(0.0, 0.5 * t, 0.0), Vector3::new(0.0, 0.0, 0.05 * t))
}

/// The LiDAR's extrinsics, as `sensor_in_body` writes them below.
fn body_sensor() -> Isometry3<f64> {
    Isometry3::from_parts(nalgebra::Translation3::new(0.1, 0.0, 0.5), nalgebra::UnitQuaternion::identity())
}

/// A dense wall at world x = 2, 4 m wide, 1.5 m high, as the LiDAR sees it.
fn cloud_at(t: f64) -> Message {
    let t_sensor_world = (body_at(t) * body_sensor()).inverse();
    let pts: Vec<[f32; 3]> = (0..80)
        .flat_map(|i| (0..30).map(move |k| Point3::new(2.0, -2.0 + 0.05 * i as f64 + 0.5 * t, 0.05 * k as f64)))
        .map(|p| (t_sensor_world * p).coords.map(|v| v as f32).into())
        .collect();
    Message::PointCloud2(PointCloud2::from_points(
        Header { stamp_ns: (t * 1e9) as i64, frame_id: "lidar".into() },
        &pts,
    ))
}

fn recording() -> Vec<Msg> {
    let mut msgs = Vec::new();
    for k in 0..=40 {
        let t = 0.05 * k as f64;
        let odom = StampedTransform {
            header: Header { stamp_ns: (t * 1e9) as i64, frame_id: "odom".into() },
            child_frame: "base_link".into(),
            transform: body_at(t),
        };
        msgs.push(Msg::new("/odom", Message::Odometry(odom), t));
        if k % 4 == 2 {
            msgs.push(Msg::new("/points", cloud_at(t), t + 0.001));
        }
    }
    msgs
}

const CONFIG: &str = r#"
[sensor]
kind = "points"
construction = "raycast"
min_range_m = 0.2
max_range_m = 10.0

[occupancy]
voxel_size_m = 0.1
local_size_m = [6.0, 6.0, 3.0]

[global]
max_distance_m = 1.0

[dataset]
sensor_topic = "/points"
pose_topic = "/odom"
sensor_in_body = [0.1, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]
"#;

fn run(dir: &Path, rec: &Path, config: &str) -> Output {
    run_with(dir, rec, config, &[])
}

fn run_with(dir: &Path, rec: &Path, config: &str, extra: &[&str]) -> Output {
    let cfg = dir.join("ros.toml");
    std::fs::write(&cfg, config).expect("config");
    Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(extra)
        .args(["run", "--config"])
        .arg(&cfg)
        .arg("--dataset")
        .arg(rec)
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--save")
        .arg(dir.join("map.edtmap"))
        .output()
        .expect("edtmap runs")
}

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("out/report.json")).expect("report")).expect("json")
}

/// Frames integrated, per the report.
fn frames(r: &serde_json::Value) -> Option<u64> {
    r["frames"].as_array().map(|f| f.len() as u64)
}

/// World x of every occupied voxel centre of the saved map.
fn occupied_x(dir: &Path) -> Vec<f64> {
    let map = edtmap::load_map(&dir.join("map.edtmap")).expect("map");
    let vs = map.voxel_size_m();
    let mut xs = Vec::new();
    for (key, block) in map.occupancy().iter() {
        for (offset, v) in block.log_odds.iter().enumerate() {
            if map.log_odds().state(v) == edtmap::VoxelState::Occupied {
                xs.push(key.voxel(offset).centre(vs)[0]);
            }
        }
    }
    xs
}

#[test]
fn bag_and_mcap_lidar_recordings_map_the_wall() {
    for container in CONTAINERS {
        let dir = tempfile::tempdir().expect("tempdir");
        let rec = dir.path().join(format!("drive.{}", container.ext()));
        write_recording(&rec, container, &recording(), true);
        let out = run(dir.path(), &rec, CONFIG);
        assert!(out.status.success(), "{container:?}: {}", String::from_utf8_lossy(&out.stderr));
        let r = report(dir.path());
        assert_eq!(frames(&r), Some(10), "{container:?}");
        assert_eq!(r["skipped"].as_array().map(Vec::len), Some(0));
        assert!(r["stopped"].is_null());
        for picture in ["occupancy_slice.png", "edt_slice.png", "timing.png"] {
            assert!(dir.path().join("out").join(picture).exists(), "{picture}");
        }
        let xs = occupied_x(dir.path());
        assert!(xs.len() > 500, "{container:?}: {} occupied voxels", xs.len());
        // The wall at x = 2 m lies on a voxel face: the voxels either side.
        assert!(
            xs.iter().all(|x| (x - 2.0).abs() <= 0.1),
            "{container:?}: occupied off the wall: {:?}",
            xs.iter().filter(|x| (*x - 2.0).abs() > 0.1).take(5).collect::<Vec<_>>()
        );
    }
}

#[test]
fn damaged_recordings_keep_what_was_integrated() {
    for container in CONTAINERS {
        let dir = tempfile::tempdir().expect("tempdir");
        let full = dir.path().join(format!("full.{}", container.ext()));
        write_recording(&full, container, &recording(), false);
        let bytes = std::fs::read(&full).expect("read");
        // A killed `rosbag record` leaves NAME.bag.active: the magic decides.
        let rec = dir.path().join(format!("cut.{}.active", container.ext()));
        std::fs::write(&rec, &bytes[..bytes.len() * 3 / 5]).expect("cut");
        // Skip (the default): a warning, the frames before the cut, success.
        let out = run(dir.path(), &rec, CONFIG);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{container:?}: {stderr}");
        assert!(stderr.contains("stopped early") && stderr.contains("cut."), "{stderr}");
        let r = report(dir.path());
        let kept = frames(&r).expect("frames");
        assert!((1..10).contains(&kept), "{container:?}: {kept} frames");
        assert!(r["stopped"]["reason"].as_str().is_some_and(|s| s.contains("/points")), "{}", r["stopped"]);
        assert!(!occupied_x(dir.path()).is_empty());
        // Stop: the same frames are written, and the run fails.
        let out = run(dir.path(), &rec, &format!("{CONFIG}on_error = \"stop\"\n"));
        assert!(!out.status.success());
        assert_eq!(frames(&report(dir.path())), Some(kept));
    }
}

#[test]
fn frames_without_poses_are_skipped_or_stop_the_run() {
    // Odometry ends at 1 s: the clouds after it have no pose.
    let msgs: Vec<Msg> = recording().into_iter().filter(|m| m.topic != "/odom" || m.log_time_s <= 1.0).collect();
    let dir = tempfile::tempdir().expect("tempdir");
    let rec = dir.path().join("short.mcap");
    write_recording(&rec, Container::Mcap, &msgs, true);
    let out = run_with(dir.path(), &rec, CONFIG, &["-vv"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    // -v says what was opened, -vv adds a line per frame; warnings name the skipped frames.
    assert!(stderr.contains("10 messages of sensor_msgs/PointCloud2 on /points"), "{stderr}");
    assert_eq!(stderr.lines().filter(|l| l.contains("DEBUG") && l.contains("ms")).count(), 5, "{stderr}");
    assert_eq!(stderr.lines().filter(|l| l.contains("WARN") && l.contains("skipped")).count(), 5, "{stderr}");
    let r = report(dir.path());
    assert_eq!(frames(&r), Some(5));
    let skipped = r["skipped"].as_array().expect("skipped");
    assert_eq!(skipped.len(), 5);
    assert!(
        skipped[0]["reason"].as_str().is_some_and(|s| s.contains("after the last pose") && s.contains("message 5")),
        "{}",
        skipped[0]
    );
    let out = run(dir.path(), &rec, &format!("{CONFIG}on_error = \"stop\"\n"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("after the last pose") && stderr.contains("the 5 frames before it"),
        "{stderr}"
    );
    assert_eq!(frames(&report(dir.path())), Some(5));
    // A topic the recording does not have.
    let out = run(dir.path(), &rec, &CONFIG.replace("\"/points\"", "\"/velodyne_points\""));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && stderr.contains("/velodyne_points")
            && stderr.contains("/points (sensor_msgs/PointCloud2)"),
        "{stderr}"
    );
}

fn edtmap(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_edtmap")).args(args).current_dir(dir).output().expect("edtmap runs")
}

#[test]
fn recorded_scenes_replay_into_the_scenes_own_map() {
    // A depth camera (Image + CameraInfo) and a planar LiDAR (LaserScan),
    // through both containers: the replayed map equals the simulated run's,
    // byte for byte, so decoding, stamps and poses lose nothing.
    let dir = tempfile::tempdir().expect("tempdir");
    for (scene, ext) in [("room", "bag"), ("planar", "mcap"), ("room", "mcap"), ("planar", "bag")] {
        let rec = format!("{scene}.{ext}");
        let out = edtmap(&["record", "--scene", scene, "--frames", "6", "--force", &rec], dir.path());
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let out = edtmap(
            &["run", "--config", &format!("{scene}.toml"), "--dataset", &rec, "--out", "rec", "--save", "rec.edtmap"],
            dir.path(),
        );
        assert!(out.status.success(), "{rec}: {}", String::from_utf8_lossy(&out.stderr));
        let out =
            edtmap(&["run", "--scene", scene, "--frames", "6", "--out", "sim", "--save", "sim.edtmap"], dir.path());
        assert!(out.status.success());
        let (a, b) = (
            std::fs::read(dir.path().join("rec.edtmap")).expect("map"),
            std::fs::read(dir.path().join("sim.edtmap")).expect("map"),
        );
        assert!(a == b, "{rec}: the replayed map differs from the scene's");
    }
}
