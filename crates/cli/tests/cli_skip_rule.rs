//! One skip rule for every kind of folder recording:
//! a frame's own problem (its image or cloud corrupt, its pose missing) is
//! skipped under `on_error = "skip"` and stops the run under `"stop"`,
//! keeping and writing the frames before it, whether it is the first frame
//! or a later one and whatever the kind: 3DMatch, TUM, PCD, PLY, KITTI,
//! ROS bags and MCAP files. Files named like frames that are not frames
//! are left out with a warning under both.

#[path = "../../ros/tests/common/mod.rs"]
mod common;

use common::{write_recording, Container, Msg};
use edtmap_ros::msg::{Header, Message, PointCloud2, StampedTransform};
use nalgebra::Isometry3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    ThreeDMatch,
    Tum,
    Pcd,
    Ply,
    Bin,
    Bag,
    Mcap,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fault {
    /// Frame `k`'s image or cloud is not a valid file.
    Corrupt(usize),
    /// Nothing gives frame `k` a pose: its pose file is missing (TUM: the
    /// ground truth has a hole at its time).
    NoPose(usize),
    /// A file named like a frame that is not one.
    Stray,
}

const FRAMES: usize = 3;
/// TUM image times, seconds.
const TUM_TIMES: [f64; FRAMES] = [10.0, 10.5, 11.0];
/// ROS cloud stamps, seconds.
const ROS_TIMES: [f64; FRAMES] = [0.1, 0.5, 0.9];
/// Replays the ROS recordings: a LiDAR's clouds placed by odometry.
const ROS_CONFIG: &str =
    "[sensor]\nkind = \"points\"\nconstruction = \"raycast\"\nmin_range_m = 0.2\nmax_range_m = 10.0\n\n\
    [occupancy]\nvoxel_size_m = 0.1\nlocal_size_m = [8.0, 8.0, 4.0]\n\n[global]\nmax_distance_m = 1.0\n\n\
    [dataset]\nsensor_topic = \"/points\"\npose_topic = \"/odom\"\n";
const IDENTITY: &str = "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";

fn write_depth_png(path: &Path, width: u32, height: u32, value: u16) {
    let file = std::fs::File::create(path).expect("create png");
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().expect("png header");
    let bytes: Vec<u8> = (0..width * height).flat_map(|_| value.to_be_bytes()).collect();
    writer.write_image_data(&bytes).expect("png data");
}

/// A wall at x = 3 m, 2 m wide and 1 m high, as points.
fn wall() -> Vec<[f32; 3]> {
    (0..40).flat_map(|i| (0..10).map(move |k| [3.0, -1.0 + 0.05 * i as f32, 0.1 * k as f32])).collect()
}

fn cloud_bytes(kind: Kind) -> Vec<u8> {
    let pts = wall();
    let lines: String = pts.iter().map(|p| format!("{} {} {}\n", p[0], p[1], p[2])).collect();
    match kind {
        Kind::Pcd => format!("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA ascii\n{lines}", n = pts.len()).into_bytes(),
        Kind::Ply => format!("ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n{lines}", pts.len()).into_bytes(),
        Kind::Bin => pts.iter().flat_map(|p| p.iter().chain([&1.0]).flat_map(|v| v.to_le_bytes())).collect(),
        _ => unreachable!("not a cloud kind"),
    }
}

fn ext(kind: Kind) -> &'static str {
    match kind {
        Kind::Pcd => "pcd",
        Kind::Ply => "ply",
        Kind::Bin => "bin",
        _ => "png",
    }
}

/// Frame `k`'s file and pose file names (TUM: no pose file; ROS: the
/// message).
fn names(kind: Kind, k: usize) -> (String, Option<String>) {
    match kind {
        Kind::Bag | Kind::Mcap => (format!("topic /points, message {k}"), None),
        Kind::ThreeDMatch => (format!("frame-{k:06}.depth.png"), Some(format!("frame-{k:06}.pose.txt"))),
        Kind::Tum => (format!("{:.6}.png", TUM_TIMES[k]), None),
        _ => (format!("{k:06}.{}", ext(kind)), Some(format!("{k:06}.pose.txt"))),
    }
}

/// A ROS recording of `FRAMES` clouds of the wall, posed by odometry
/// every 50 ms; a hole of ±0.2 s in the odometry at the cloud without a
/// pose, a cut payload for the corrupt one.
fn ros_recording(path: &Path, container: Container, fault: Fault) {
    let header = |t: f64, frame: &str| Header { stamp_ns: (t * 1e9) as i64, frame_id: frame.into() };
    let mut msgs = Vec::new();
    for i in 0..=24 {
        let t = 0.05 * f64::from(i);
        if matches!(fault, Fault::NoPose(k) if (t - ROS_TIMES[k]).abs() < 0.2) {
            continue;
        }
        let odom = StampedTransform {
            header: header(t, "odom"),
            child_frame: "base_link".into(),
            transform: Isometry3::identity(),
        };
        msgs.push(Msg::new("/odom", Message::Odometry(odom), t));
    }
    for (k, t) in ROS_TIMES.into_iter().enumerate() {
        let mut cloud =
            Msg::new("/points", Message::PointCloud2(PointCloud2::from_points(header(t, "lidar"), &wall())), t + 0.001);
        cloud.truncate_payload = fault == Fault::Corrupt(k);
        msgs.push(cloud);
    }
    msgs.sort_by(|a, b| a.log_time_s.total_cmp(&b.log_time_s));
    write_recording(path, container, &msgs, true);
}

/// Writes a recording of `FRAMES` frames of `kind` with `fault`; returns
/// it and the text of the config that replays it (a shipped one for
/// folders).
fn recording(dir: &Path, kind: Kind, fault: Fault) -> (PathBuf, String) {
    std::fs::create_dir_all(dir).expect("dir");
    let shipped = |name: &str| std::fs::read_to_string(root().join("configs").join(name)).expect("config");
    if let Some(container) = match kind {
        Kind::Bag => Some(Container::Bag),
        Kind::Mcap => Some(Container::Mcap),
        _ => None,
    } {
        let path = dir.join(format!("rec.{}", container.ext()));
        ros_recording(&path, container, fault);
        return (path, ROS_CONFIG.to_string());
    }
    let config = match kind {
        Kind::ThreeDMatch => {
            // A 40 × 30 camera: the folder's intrinsics, not the config's 640 × 480.
            std::fs::write(dir.join("camera-intrinsics.txt"), "40 0 20\n0 40 15\n0 0 1\n").expect("intrinsics");
            for k in 0..FRAMES {
                let (image, pose) = names(kind, k);
                write_depth_png(&dir.join(image), 40, 30, 1500);
                std::fs::write(dir.join(pose.expect("pose")), IDENTITY).expect("pose");
            }
            shipped("3dmatch.toml")
        }
        Kind::Tum => {
            std::fs::create_dir(dir.join("depth")).expect("depth/");
            for t in TUM_TIMES {
                write_depth_png(&dir.join(format!("depth/{t:.6}.png")), 640, 480, 7500);
            }
            // Ground truth every 10 ms, with a hole of ±0.2 s at the frame without a pose.
            let mut gt = String::from("# timestamp tx ty tz qx qy qz qw\n");
            for i in 0..=120 {
                let t = 9.9 + 0.01 * f64::from(i);
                if let Fault::NoPose(k) = fault {
                    if (t - TUM_TIMES[k]).abs() < 0.2 {
                        continue;
                    }
                }
                writeln!(gt, "{t:.6} 0 0 0 0 0 0 1").expect("format");
            }
            std::fs::write(dir.join("groundtruth.txt"), gt).expect("groundtruth");
            shipped("tum.toml")
        }
        _ => {
            for k in 0..FRAMES {
                let (cloud, pose) = names(kind, k);
                std::fs::write(dir.join(cloud), cloud_bytes(kind)).expect("cloud");
                std::fs::write(dir.join(pose.expect("pose")), IDENTITY).expect("pose");
            }
            shipped("velodyne.toml")
        }
    };
    match fault {
        Fault::Corrupt(k) => {
            let (file, _) = names(kind, k);
            let path = if kind == Kind::Tum { dir.join("depth").join(file) } else { dir.join(file) };
            // Not a whole number of KITTI points, not a PCD, PLY or PNG.
            std::fs::write(path, b"garbage: not a frame at all\n").expect("corrupt");
        }
        Fault::NoPose(k) => {
            if let (_, Some(pose)) = names(kind, k) {
                std::fs::remove_file(dir.join(pose)).expect("rm pose");
            }
        }
        Fault::Stray => match kind {
            Kind::ThreeDMatch => {
                write_depth_png(&dir.join("frame-abc.depth.png"), 40, 30, 1000);
                std::fs::write(dir.join("frame-abc.pose.txt"), IDENTITY).expect("pose");
            }
            Kind::Tum => write_depth_png(&dir.join("depth/notes.png"), 640, 480, 7500),
            _ => unreachable!("cloud folders take every cloud"),
        },
    }
    (dir.to_path_buf(), config)
}

/// `text` with `[dataset] on_error = policy`, written beside `dir`.
fn config_with(dir: &Path, text: &str, policy: &str) -> PathBuf {
    let line = format!("on_error = \"{policy}\"\n");
    let text = if text.contains("[dataset]\n") {
        text.replace("[dataset]\n", &format!("[dataset]\n{line}"))
    } else {
        format!("{text}\n[dataset]\n{line}")
    };
    let path = dir.join(format!("{policy}.toml"));
    std::fs::write(&path, text).expect("config");
    path
}

fn report(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("report.json")).expect("report.json is written")).expect("json")
}

fn indices(v: &serde_json::Value) -> Vec<u64> {
    v.as_array().map(|a| a.iter().filter_map(|f| f["index"].as_u64()).collect()).unwrap_or_default()
}

/// Runs `kind` with `fault` under both policies and checks the outcome
/// against the rule.
fn check(kind: Kind, fault: Fault) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let (data, config) = recording(&tmp.path().join("rec"), kind, fault);
    let what = format!("{kind:?} {fault:?}");
    // The file the messages must name.
    let named = match fault {
        Fault::Corrupt(k) => names(kind, k).0,
        Fault::NoPose(k) => names(kind, k).1.unwrap_or_else(|| names(kind, k).0),
        Fault::Stray if kind == Kind::Tum => "notes.png".into(),
        Fault::Stray => "frame-abc.depth.png".into(),
    };
    for policy in ["skip", "stop"] {
        let out = tmp.path().join(format!("out-{policy}"));
        let o = Command::new(env!("CARGO_BIN_EXE_edtmap"))
            .args(["run", "--config"])
            .arg(config_with(tmp.path(), &config, policy))
            .arg("--dataset")
            .arg(&data)
            .arg("--out")
            .arg(&out)
            .output()
            .expect("edtmap runs");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{what} {policy}: {err}");
        assert!(err.contains(&named), "{what} {policy}: {named} not named in {err}");
        let r = report(&out);
        let all: Vec<u64> = (0..FRAMES as u64).collect();
        match (fault, policy) {
            (Fault::Stray, _) => {
                assert!(o.status.success(), "{what} {policy}: {err}");
                assert!(err.contains("left out"), "{what} {policy}: {err}");
                assert_eq!(indices(&r["frames"]), all, "{what} {policy}");
                assert!(
                    r["skipped"].as_array().is_some_and(Vec::is_empty) && r["stopped"].is_null(),
                    "{what} {policy}: {r}"
                );
            }
            (Fault::Corrupt(k) | Fault::NoPose(k), "skip") => {
                assert!(o.status.success(), "{what} {policy}: {err}");
                let rest: Vec<u64> = all.iter().copied().filter(|&i| i != k as u64).collect();
                assert_eq!(indices(&r["frames"]), rest, "{what} {policy}");
                assert_eq!(indices(&r["skipped"]), vec![k as u64], "{what} {policy}: {}", r["skipped"]);
                assert!(
                    r["skipped"][0]["reason"].as_str().is_some_and(|s| s.contains(&named)),
                    "{what} {policy}: {}",
                    r["skipped"]
                );
                assert!(out.join("occupancy_slice.png").is_file(), "{what} {policy}");
            }
            (Fault::Corrupt(k) | Fault::NoPose(k), _) => {
                assert!(!o.status.success(), "{what} {policy}: a stop is an error exit");
                let before: Vec<u64> = (0..k as u64).collect();
                assert_eq!(indices(&r["frames"]), before, "{what} {policy}");
                assert_eq!(r["stopped"]["index"].as_u64(), Some(k as u64), "{what} {policy}: {r}");
                assert!(
                    r["stopped"]["reason"].as_str().is_some_and(|s| s.contains(&named)),
                    "{what} {policy}: {}",
                    r["stopped"]
                );
                if k > 0 {
                    // The frames before the stop are kept and written.
                    assert!(err.contains("the 1 frame before it is integrated"), "{what} {policy}: {err}");
                    for picture in ["occupancy_slice.png", "edt_slice.png", "timing.png"] {
                        assert!(out.join(picture).metadata().is_ok_and(|m| m.len() > 0), "{what} {policy}: {picture}");
                    }
                }
            }
        }
    }
}

#[test]
fn a_bad_first_or_later_frame_is_skipped_or_stops_the_run_for_every_kind() {
    for kind in [Kind::ThreeDMatch, Kind::Tum, Kind::Pcd, Kind::Ply, Kind::Bin, Kind::Bag, Kind::Mcap] {
        for fault in [Fault::Corrupt(0), Fault::Corrupt(1), Fault::NoPose(0), Fault::NoPose(1)] {
            check(kind, fault);
        }
    }
}

#[test]
fn files_named_like_frames_are_left_out_with_a_warning_under_both_policies() {
    check(Kind::ThreeDMatch, Fault::Stray);
    check(Kind::Tum, Fault::Stray);
}
