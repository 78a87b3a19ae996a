//! ROS bags and MCAP files written here, replayed into frames: every
//! sensor and pose message type, poses interpolated at the sensor's stamps
//! and composed with the extrinsics (checked against the analytic motion),
//! and the bad recordings a user brings.

mod common;

const CONTAINERS: [Container; 2] = [Container::Bag, Container::Mcap];

use common::{write_recording, Container, Msg};
use edtmap_core::sensor::Measurement;
use edtmap_ros::msg::{CameraInfo, Header, Image, LaserScanMsg, Message, PointCloud2, StampedTransform};
use edtmap_ros::{RosOptions, RosReplay, SensorTopic};
use nalgebra::{Isometry3, Point3, Vector3};

/// The robot's pose in the world at `t`: x 0.1 t, y 0.5 t, yaw 0.2 t.
/// Linear in translation and in angle about one axis, so interpolation
/// between samples reproduces it exactly.
fn body_at(t: f64) -> Isometry3<f64> {
    Isometry3::new(Vector3::new(0.1 * t, 0.5 * t, 0.0), Vector3::new(0.0, 0.0, 0.2 * t))
}

/// The LiDAR on the robot, 0.2 m ahead, 0.3 m up, turned 0.1 rad.
fn body_sensor() -> Isometry3<f64> {
    Isometry3::new(Vector3::new(0.2, 0.0, 0.3), Vector3::new(0.0, 0.0, 0.1))
}

fn header(t: f64, frame: &str) -> Header {
    Header { stamp_ns: (t * 1e9).round() as i64, frame_id: frame.into() }
}

/// Points of a wall at world x = 3, seen from the sensor at `t`.
fn wall_world() -> Vec<Point3<f64>> {
    (0..20).flat_map(|i| (0..5).map(move |k| Point3::new(3.0, -1.0 + 0.1 * i as f64, 0.25 * k as f64))).collect()
}

fn cloud_at(t: f64) -> PointCloud2 {
    let t_sensor_world = (body_at(t) * body_sensor()).inverse();
    let pts: Vec<[f32; 3]> =
        wall_world().iter().map(|p| (t_sensor_world * p).coords.map(|v| v as f32).into()).collect();
    PointCloud2::from_points(header(t, "lidar"), &pts)
}

fn stamped(t: f64, parent: &str, child: &str, pose: Isometry3<f64>) -> StampedTransform {
    StampedTransform { header: header(t, parent), child_frame: child.into(), transform: pose }
}

fn options(sensor: &str, pose: &str) -> RosOptions {
    RosOptions {
        sensors: vec![SensorTopic { t_body_sensor: body_sensor(), ..SensorTopic::new(sensor) }],
        pose_topic: pose.into(),
        static_tf_topic: "/tf_static".into(),
        world_frame: None,
        body_frame: None,
        max_pose_gap_s: 0.2,
        depth_scale_m: 0.001,
    }
}

/// Clouds at 5 Hz from t = 0.13 s, odometry at 20 Hz from 0, both over 2 s.
fn lidar_and(pose_msg: impl Fn(f64) -> Message, pose_topic: &str) -> Vec<Msg> {
    let mut msgs = Vec::new();
    for k in 0..=40 {
        let t = k as f64 * 0.05;
        msgs.push(Msg::new(pose_topic, pose_msg(t), t));
    }
    for k in 0..9 {
        let t = 0.13 + 0.2 * k as f64;
        msgs.push(Msg::new("/points", Message::PointCloud2(cloud_at(t)), t + 0.01));
    }
    msgs.sort_by(|a, b| a.log_time_s.total_cmp(&b.log_time_s));
    msgs
}

/// Every frame's points land back on the wall, and stamps are the clouds'.
fn assert_frames_on_the_wall(replay: &RosReplay, frames: usize) {
    let got: Vec<_> = replay.frames().collect::<Result<_, _>>().expect("every frame");
    assert_eq!(got.len(), frames);
    for (k, frame) in got.iter().enumerate() {
        assert!((frame.stamp_s - (0.13 + 0.2 * k as f64)).abs() < 1e-9, "stamp {}", frame.stamp_s);
        let Measurement::Points(cloud) = &frame.measurement else { panic!("points") };
        for (p, want) in cloud.points.iter().zip(wall_world()) {
            let world = frame.t_world_sensor * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            assert!((world - want).norm() < 1e-5, "frame {k}: {world} vs {want}");
        }
    }
}

#[test]
fn clouds_with_odometry_pose_stamped_and_transform_stamped() {
    let dir = tempfile::tempdir().expect("tempdir");
    type PoseMessage = fn(f64) -> Message;
    let makers: [(&str, PoseMessage); 3] = [
        ("/odom", |t| Message::Odometry(stamped(t, "odom", "base_link", body_at(t)))),
        ("/pose", |t| Message::PoseStamped(stamped(t, "map", "", body_at(t)))),
        ("/vicon", |t| Message::TransformStamped(stamped(t, "world", "robot", body_at(t)))),
    ];
    for container in CONTAINERS {
        for (topic, make) in makers {
            let path = dir.path().join(format!("rec{topic}.{}", container.ext()).replace("/", "_"));
            let path = dir.path().join(path.file_name().expect("name"));
            write_recording(&path, container, &lidar_and(make, topic), true);
            let replay = RosReplay::open(&path, &options("/points", topic)).expect("opens");
            assert_eq!((replay.len(), replay.kind()), (9, "point cloud"));
            assert_frames_on_the_wall(&replay, 9);
        }
    }
}

#[test]
fn clouds_placed_by_the_tf_tree() {
    // map → odom drifts, odom → base_link moves, base_link → lidar is static:
    // the composition is body_at(t) * body_sensor() again.
    let drift = |t: f64| Isometry3::new(Vector3::new(0.0, 0.02 * t, 0.0), Vector3::zeros());
    let mut msgs = lidar_and(
        |t| {
            let odom_base = drift(t).inverse() * body_at(t);
            Message::Tf(vec![stamped(t, "map", "odom", drift(t)), stamped(t, "odom", "base_link", odom_base)])
        },
        "/tf",
    );
    msgs.insert(0, Msg::new("/tf_static", Message::Tf(vec![stamped(0.0, "base_link", "lidar", body_sensor())]), 0.0));
    let dir = tempfile::tempdir().expect("tempdir");
    for container in CONTAINERS {
        let path = dir.path().join(format!("tf.{}", container.ext()));
        write_recording(&path, container, &msgs, true);
        let opts = RosOptions { sensors: vec![SensorTopic::new("/points")], ..options("/points", "/tf") };
        let replay = RosReplay::open(&path, &opts).expect("opens");
        assert_frames_on_the_wall(&replay, 9);
        // The same with the body frame named and the extrinsics from the config.
        let opts = RosOptions {
            body_frame: Some("base_link".into()),
            world_frame: Some("map".into()),
            ..options("/points", "/tf")
        };
        assert_frames_on_the_wall(&RosReplay::open(&path, &opts).expect("opens"), 9);
        // Without /tf_static the cloud's frame is in no tree: every frame says so.
        let no_static = dir.path().join(format!("no_static.{}", container.ext()));
        write_recording(&no_static, container, &msgs[1..], true);
        let opts = RosOptions { sensors: vec![SensorTopic::new("/points")], ..options("/points", "/tf") };
        for r in RosReplay::open(&no_static, &opts).expect("opens").frames() {
            let e = r.expect_err("no pose");
            assert!(!e.fatal && e.reason.contains("\"lidar\" is not in the transform tree"), "{e}");
        }
    }
}

#[test]
fn depth_images_with_camera_info_and_laser_scans() {
    let image = |t: f64| Image {
        header: header(t, "cam"),
        height: 2,
        width: 3,
        encoding: "16UC1".into(),
        is_bigendian: false,
        step: 6,
        data: vec![0xe8, 3, 0, 0, 0xd0, 7, 1, 0, 2, 0, 3, 0],
    };
    let info = |t: f64| CameraInfo::pinhole(header(t, "cam"), 3, 2, [500.0, 0.0, 1.5, 0.0, 510.0, 1.0, 0.0, 0.0, 1.0]);
    let scan = |t: f64| LaserScanMsg {
        header: header(t, "laser"),
        angle_min: -1.0,
        angle_max: 1.0,
        angle_increment: 0.5,
        time_increment: 0.0,
        scan_time: 0.1,
        range_min: 0.1,
        range_max: 8.0,
        ranges: vec![1.0, 2.0, 3.0, 4.0, 5.0],
        intensities: vec![],
    };
    let mut msgs = Vec::new();
    for k in 0..=10 {
        let t = 0.1 * k as f64;
        msgs.push(Msg::new("/odom", Message::Odometry(stamped(t, "odom", "base", body_at(t))), t));
        if k > 0 && k < 10 {
            msgs.push(Msg::new("/camera/depth/image_raw", Message::Image(image(t + 0.05)), t + 0.05));
            msgs.push(Msg::new("/camera/depth/camera_info", Message::CameraInfo(info(t + 0.05)), t + 0.05));
            msgs.push(Msg::new("/scan", Message::LaserScan(scan(t + 0.02)), t + 0.02));
        }
    }
    msgs.sort_by(|a, b| a.log_time_s.total_cmp(&b.log_time_s));
    let dir = tempfile::tempdir().expect("tempdir");
    for container in CONTAINERS {
        let path = dir.path().join(format!("cam.{}", container.ext()));
        write_recording(&path, container, &msgs, true);
        let replay = RosReplay::open(&path, &options("/camera/depth/image_raw", "/odom")).expect("opens");
        assert_eq!(replay.kind(), "depth camera");
        assert_eq!(replay.camera_info().map(|c| c.k[4]), Some(510.0), "the sibling camera_info is found");
        for (k, frame) in replay.frames().enumerate() {
            let frame = frame.expect("frame");
            let t = 0.1 * (k + 1) as f64 + 0.05;
            assert!(
                (frame.t_world_sensor.to_homogeneous() - (body_at(t) * body_sensor()).to_homogeneous()).abs().max()
                    < 1e-9
            );
            let Measurement::Depth(d) = frame.measurement else { panic!("depth") };
            assert_eq!((d.width, d.height, d.depth_m(0), d.depth_m(2), d.depth_m(3)), (3, 2, 1.0, 2.0, 0.001));
            assert!(d.depth_m(1).is_nan(), "0 is no return");
        }
        let replay = RosReplay::open(&path, &options("/scan", "/odom")).expect("opens");
        assert_eq!((replay.kind(), replay.len()), ("planar LiDAR", 9));
        let frame = replay.frames().next().expect("one").expect("frame");
        let Measurement::Scan(s) = frame.measurement else { panic!("scan") };
        assert_eq!((s.angle_min_rad, s.angle_increment_rad, s.ranges.len(), s.range.max_m), (-1.0, 0.5, 5, 8.0));
    }
}

#[test]
fn absent_topics_and_unknown_types_are_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut msgs = lidar_and(|t| Message::Odometry(stamped(t, "odom", "base", body_at(t))), "/odom");
    msgs.push(Msg::raw("/chatter", "std_msgs/String", vec![0, 0, 0, 0], 0.5));
    for container in CONTAINERS {
        let path = dir.path().join(format!("bad.{}", container.ext()));
        write_recording(&path, container, &msgs, true);
        let err = RosReplay::open(&path, &options("/velodyne_points", "/odom")).expect_err("absent").to_string();
        assert!(
            err.contains("/velodyne_points")
                && err.contains("/points (sensor_msgs/PointCloud2)")
                && err.contains(&*path.to_string_lossy()),
            "{err}"
        );
        let err = RosReplay::open(&path, &options("/chatter", "/odom")).expect_err("unknown type").to_string();
        assert!(err.contains("/chatter") && err.contains("std_msgs/String"), "{err}");
        let err = RosReplay::open(&path, &options("/points", "/ground_truth")).expect_err("no poses").to_string();
        assert!(err.contains("pose topic /ground_truth"), "{err}");
        let err = RosReplay::open(&path, &options("/points", "/points")).expect_err("not poses").to_string();
        assert!(err.contains("carries sensor_msgs/PointCloud2"), "{err}");
    }
}

#[test]
fn frames_without_poses_and_malformed_messages_fail_alone() {
    // Odometry only from 0.5 s to 1.5 s; cloud 2 is cut in half.
    let mut msgs: Vec<Msg> = lidar_and(|t| Message::Odometry(stamped(t, "odom", "base", body_at(t))), "/odom")
        .into_iter()
        .filter(|m| m.topic != "/odom" || (0.5..=1.5).contains(&m.log_time_s))
        .collect();
    let cloud2 = msgs.iter_mut().filter(|m| m.topic == "/points").nth(2).expect("cloud 2");
    cloud2.truncate_payload = true;
    let dir = tempfile::tempdir().expect("tempdir");
    for container in CONTAINERS {
        let path = dir.path().join(format!("gaps.{}", container.ext()));
        write_recording(&path, container, &msgs, true);
        let replay = RosReplay::open(&path, &options("/points", "/odom")).expect("opens");
        let results: Vec<_> = replay.frames().collect();
        assert_eq!(results.len(), 9);
        // Clouds at 0.13, 0.33 (before the poses), 0.53 (cut), 0.73..1.33 fine, 1.53, 1.73 (after).
        let ok: Vec<usize> = results.iter().enumerate().filter(|(_, r)| r.is_ok()).map(|(i, _)| i).collect();
        assert_eq!(ok, vec![3, 4, 5, 6]);
        let e0 = results[0].as_ref().expect_err("before");
        assert!(
            !e0.fatal && e0.topic == "/points" && e0.index == 0 && e0.reason.contains("before the first pose"),
            "{e0}"
        );
        let e2 = results[2].as_ref().expect_err("cut");
        assert!(!e2.fatal && e2.to_string().contains("message 2") && e2.reason.contains("PointCloud2"), "{e2}");
        let e8 = results[8].as_ref().expect_err("after");
        assert!(e8.reason.contains("after the last pose") && e8.stamp_s.is_some(), "{e8}");
    }
}

#[test]
fn truncated_recordings_keep_the_frames_before_the_cut() {
    let msgs = lidar_and(|t| Message::Odometry(stamped(t, "odom", "base", body_at(t))), "/odom");
    let dir = tempfile::tempdir().expect("tempdir");
    for container in CONTAINERS {
        let full = dir.path().join(format!("full.{}", container.ext()));
        write_recording(&full, container, &msgs, false);
        let bytes = std::fs::read(&full).expect("read");
        let mut seen_partial = false;
        for keep in [0.3, 0.5, 0.7, 0.9] {
            let cut = dir.path().join(format!("cut.{}", container.ext()));
            std::fs::write(&cut, &bytes[..(bytes.len() as f64 * keep) as usize]).expect("write");
            let replay = match RosReplay::open(&cut, &options("/points", "/odom")) {
                Ok(r) => r,
                Err(e) => panic!("{container:?} cut at {keep}: {e}"),
            };
            let results: Vec<_> = replay.frames().collect();
            let good = results.iter().take_while(|r| r.is_ok()).count();
            // Whatever follows the good frames is one fatal error, or nothing.
            assert!(results.len() <= good + 1, "{container:?}: {} results", results.len());
            if let Some(Err(e)) = results.get(good) {
                assert!(e.fatal && e.to_string().contains("cut."), "{e}");
            }
            seen_partial |= good > 0 && good < 9;
        }
        assert!(seen_partial, "{container:?}: no cut kept some frames and lost others");
    }
}

/// A second LiDAR on the robot, 0.1 m behind and 0.5 m up, turned half a turn.
fn rear_sensor() -> Isometry3<f64> {
    Isometry3::new(Vector3::new(-0.1, 0.0, 0.5), Vector3::new(0.0, 0.0, std::f64::consts::PI))
}

/// The wall seen from a sensor mounted at `mount` at `t`.
fn cloud_from(mount: Isometry3<f64>, t: f64, frame: &str) -> PointCloud2 {
    let t_sensor_world = (body_at(t) * mount).inverse();
    let pts: Vec<[f32; 3]> =
        wall_world().iter().map(|p| (t_sensor_world * p).coords.map(|v| v as f32).into()).collect();
    PointCloud2::from_points(header(t, frame), &pts)
}

#[test]
fn two_sensor_topics_replay_in_recorded_order_each_with_its_mount() {
    // The front LiDAR at 5 Hz from 0.13 s (its third cloud cut in half),
    // the rear one at 4 Hz from 0.2 s, odometry at 20 Hz.
    let mut msgs = lidar_and(|t| Message::Odometry(stamped(t, "odom", "base", body_at(t))), "/odom");
    msgs.iter_mut().filter(|m| m.topic == "/points").nth(2).expect("cloud 2").truncate_payload = true;
    for k in 0..7 {
        let t = 0.2 + 0.25 * k as f64;
        msgs.push(Msg::new("/rear/points", Message::PointCloud2(cloud_from(rear_sensor(), t, "rear")), t + 0.01));
    }
    msgs.sort_by(|a, b| a.log_time_s.total_cmp(&b.log_time_s));
    let front = SensorTopic { t_body_sensor: body_sensor(), ..SensorTopic::new("/points") };
    let rear = SensorTopic { t_body_sensor: rear_sensor(), ..SensorTopic::new("/rear/points") };
    let dir = tempfile::tempdir().expect("tempdir");
    for container in CONTAINERS {
        let path = dir.path().join(format!("two.{}", container.ext()));
        write_recording(&path, container, &msgs, true);
        let opts = RosOptions { sensors: vec![front.clone(), rear.clone()], ..options("/points", "/odom") };
        let replay = RosReplay::open(&path, &opts).expect("opens");
        assert_eq!((replay.len(), replay.len_of(0), replay.len_of(1)), (16, 9, 7));
        let got: Vec<_> = replay.sensor_frames().collect();
        assert_eq!(got.len(), 16);
        // In the recording's order: by log time.
        let want: Vec<_> = msgs
            .iter()
            .filter(|m| m.topic.ends_with("points"))
            .map(|m| usize::from(m.topic == "/rear/points"))
            .collect();
        assert_eq!(got.iter().map(|f| f.sensor).collect::<Vec<_>>(), want);
        let mut per_sensor = [0usize; 2];
        for f in &got {
            let (s, index) = (&f.sensor, per_sensor[f.sensor]);
            per_sensor[*s] += 1;
            assert_eq!(f.index, index, "sensor {s}: each frame's position among its sensor's");
            match &f.frame {
                // The cut cloud fails alone, named by its sensor's topic and index.
                Err(e) => {
                    assert!((*s, index) == (0, 2) && e.sensor == 0 && e.index == 2 && !e.fatal, "{e}");
                    assert!(e.to_string().contains("topic /points, message 2"), "{e}");
                }
                Ok(frame) => {
                    let Measurement::Points(cloud) = &frame.measurement else { panic!("points") };
                    for (p, want) in cloud.points.iter().zip(wall_world()) {
                        let world = frame.t_world_sensor * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                        assert!((world - want).norm() < 1e-5, "sensor {s} frame {index}: {world} vs {want}");
                    }
                }
            }
        }
        assert_eq!(per_sensor, [9, 7]);
        // `frames` is the first sensor's alone.
        assert_eq!(replay.frames().count(), 9);

        // One sensor's topic missing: the others replay, with a warning.
        let gone = SensorTopic::new("/side/points");
        let opts = RosOptions { sensors: vec![gone.clone(), rear.clone()], ..options("/points", "/odom") };
        let replay = RosReplay::open(&path, &opts).expect("opens without the side LiDAR");
        assert!(
            replay.warnings().iter().any(|w| w.contains("/side/points") && w.contains("no frames")),
            "{:?}",
            replay.warnings()
        );
        assert_eq!((replay.len_of(0), replay.len_of(1), replay.sensor_type_of(0)), (0, 7, None));
        assert!(replay.sensor_frames().all(|f| f.sensor == 1 && f.frame.is_ok()));
        // All of them missing, or two sensors on one topic, is refused.
        let opts = RosOptions { sensors: vec![gone.clone(), gone.clone()], ..options("/points", "/odom") };
        let err = RosReplay::open(&path, &opts).expect_err("one topic twice").to_string();
        assert!(err.contains("two sensors on topic /side/points"), "{err}");
        let opts = RosOptions { sensors: vec![gone, SensorTopic::new("/nothing")], ..options("/points", "/odom") };
        let err = RosReplay::open(&path, &opts).expect_err("none there").to_string();
        assert!(err.contains("none of the sensor topics") && err.contains("/rear/points"), "{err}");
    }
}
