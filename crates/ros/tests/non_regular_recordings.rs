//! The recording readers refuse a FIFO, a device or a folder given as a
//! bag or MCAP file, by its type and before opening it, instead of blocking
//! on the FIFO or reading the device forever. Each read runs on its own
//! thread under a timeout, so a regression fails instead of hanging.
#![cfg(unix)]

use edtmap_io::IoError;
use edtmap_ros::bag::BagReader;
use edtmap_ros::mcap::McapReader;
use edtmap_ros::{RosOptions, RosReplay};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

/// The error of `read`, which must fail within 10 s.
fn refusal(what: &str, read: impl FnOnce() -> Result<(), IoError> + Send + 'static) -> String {
    let (send, recv) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(read().err().map(|e| e.to_string()));
    });
    match recv.recv_timeout(Duration::from_secs(10)) {
        Ok(Some(err)) => err,
        Ok(None) => panic!("{what}: accepted"),
        Err(_) => panic!("{what}: still reading after 10 s (blocked on a FIFO or reading a device?)"),
    }
}

/// Replay options for a LiDAR posed by odometry.
fn ros_options() -> RosOptions {
    RosOptions {
        sensors: vec![edtmap_ros::SensorTopic::new("/points")],
        pose_topic: "/odom".into(),
        static_tf_topic: "/tf_static".into(),
        world_frame: None,
        body_frame: None,
        max_pose_gap_s: 0.1,
        depth_scale_m: 0.001,
    }
}

#[test]
fn recording_readers_refuse_fifos_devices_and_folders() {
    type Reader = fn(&Path) -> Result<(), IoError>;
    let readers: [(&str, Reader); 3] = [
        ("x.bag", |p| BagReader::open(p).map(drop)),
        ("x.mcap", |p| McapReader::open(p).map(drop)),
        ("z.bag", |p| RosReplay::open(p, &ros_options()).map(drop)),
    ];
    let tmp = tempfile::tempdir().expect("temp dir");
    for (name, read) in readers {
        let fifo = tmp.path().join(name);
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().is_ok_and(|s| s.success());
        assert!(made, "mkfifo {}", fifo.display());
        let shown = fifo.display().to_string();
        let err = refusal(name, move || read(&fifo));
        assert!(err.contains(&shown) && err.contains("FIFO"), "{name}: {err}");
        let err = refusal(name, move || read(Path::new("/dev/zero")));
        assert!(err.contains("/dev/zero") && err.contains("character device"), "{name}: {err}");
        let dir: PathBuf = tmp.path().to_path_buf();
        let err = refusal(name, move || read(&dir));
        assert!(err.contains("directory"), "{name}: {err}");
    }
}
