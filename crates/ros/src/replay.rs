//! A ROS recording replayed as sensor frames with poses: the sensor topic
//! decoded into measurements, each placed at its stamp by the pose topic
//! (odometry, stamped poses or transforms, or the `/tf` tree) and the
//! sensor's extrinsics.
//!
//! Opening reads the small topics first (poses, camera info) in one pass;
//! the sensor messages then stream one at a time. A message that cannot
//! become a frame (undecodable, no pose at its stamp) is a
//! [`FrameError`] for that frame alone; damage to the file ends the
//! stream with a fatal one, after every frame before it.

use super::bag::BagReader;
use super::mcap::McapReader;
use super::msg::{CameraInfo, Message, StampedTransform};
use super::poses::{measurement, Poses};
use super::{RawMessage, TopicInfo};
use edtmap_core::sensor::Frame;
use edtmap_io::IoError;
use nalgebra::Isometry3;
use std::io::Read;
use std::path::{Path, PathBuf};

/// One sensor of a recording or a live node: its topic and its mount.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorTopic {
    /// The sensor's topic: `PointCloud2`, `Image` (depth) or `LaserScan`.
    pub topic: String,
    /// Camera intrinsics for depth images; by default the image topic's
    /// sibling `camera_info`, when the recording has it.
    pub camera_info_topic: Option<String>,
    /// `T_body_sensor`: the sensor's pose on the robot.
    pub t_body_sensor: Isometry3<f64>,
}

impl SensorTopic {
    /// A sensor on `topic` with its camera info beside it (when a depth
    /// camera) and mounted at the body frame's origin.
    pub fn new(topic: &str) -> Self {
        SensorTopic { topic: topic.into(), camera_info_topic: None, t_body_sensor: Isometry3::identity() }
    }

    /// The camera info topic: the configured one, else the image topic's
    /// sibling `camera_info` (`/camera/depth/image` → `/camera/depth/camera_info`).
    pub fn camera_info(&self) -> String {
        self.camera_info_topic.clone().unwrap_or_else(|| match self.topic.rsplit_once('/') {
            Some((parent, _)) => format!("{parent}/camera_info"),
            None => "camera_info".into(),
        })
    }
}

/// How to turn a recording into frames: topics, frames and extrinsics.
#[derive(Debug, Clone, PartialEq)]
pub struct RosOptions {
    /// The sensors, in the mapper's order: one or more.
    pub sensors: Vec<SensorTopic>,
    /// Where poses come from: `Odometry`, `PoseStamped`,
    /// `TransformStamped` or `TFMessage` (`/tf`).
    pub pose_topic: String,
    /// With `/tf`: the static transforms' topic.
    pub static_tf_topic: String,
    /// With `/tf`: the fixed frame (default: the root of the tree).
    pub world_frame: Option<String>,
    /// With `/tf`: the frame the extrinsics are given in (default: the
    /// sensor message's own frame, so the tree supplies the extrinsics).
    pub body_frame: Option<String>,
    /// Largest time between two poses that a frame is interpolated across.
    pub max_pose_gap_s: f64,
    /// Metres per unit of 16-bit depth images.
    pub depth_scale_m: f32,
}

/// A sensor message that did not become a frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: topic {topic}, message {index}{}: {reason}", file.display(), stamp_s.map(|s| format!(" (stamp {s:.6} s)")).unwrap_or_default())]
pub struct FrameError {
    /// The recording.
    pub file: PathBuf,
    /// The sensor's position in [`RosOptions::sensors`].
    pub sensor: usize,
    /// The sensor topic.
    pub topic: String,
    /// The message's position on the topic, from 0.
    pub index: usize,
    /// Its stamp, when it was read.
    pub stamp_s: Option<f64>,
    /// What went wrong.
    pub reason: String,
    /// Whether the rest of the recording is unreadable too.
    pub fatal: bool,
}

/// Recorders that leave stamps empty: a pose at the time it was logged,
/// as for sensor messages.
fn with_log_time(msg: Message, log_time_ns: u64) -> Message {
    let fix = |mut t: StampedTransform| {
        if t.header.stamp_ns == 0 {
            t.header.stamp_ns = i64::try_from(log_time_ns).unwrap_or(i64::MAX);
        }
        t
    };
    match msg {
        Message::Tf(ts) => Message::Tf(ts.into_iter().map(fix).collect()),
        Message::Odometry(t) => Message::Odometry(fix(t)),
        Message::PoseStamped(t) => Message::PoseStamped(fix(t)),
        Message::TransformStamped(t) => Message::TransformStamped(fix(t)),
        other => other,
    }
}

/// The two containers.
enum Container {
    Bag(BagReader),
    Mcap(McapReader),
}

impl Container {
    /// Opens a bag or MCAP file, told apart by its magic bytes.
    fn open(path: &Path) -> Result<Self, IoError> {
        let mut magic = [0u8; 8];
        let (mut f, _) = edtmap_io::files::open_input(path, u64::MAX)?;
        let n = f.read(&mut magic).map_err(|e| IoError::io(path, e))?;
        match &magic[..n] {
            m if m.starts_with(b"#ROSBAG") => Ok(Container::Bag(BagReader::open(path)?)),
            m if m.starts_with(b"\x89MCAP") => Ok(Container::Mcap(McapReader::open(path)?)),
            _ => Err(IoError::Dataset {
                path: path.to_path_buf(),
                reason: "neither a ROS 1 bag (#ROSBAG) nor an MCAP file".into(),
            }),
        }
    }

    fn topics(&self) -> Result<Vec<TopicInfo>, IoError> {
        match self {
            Container::Bag(b) => b.topics(),
            Container::Mcap(m) => m.topics(),
        }
    }

    fn messages<'a>(&'a self, topics: &'a [String]) -> Box<dyn Iterator<Item = Result<RawMessage, IoError>> + 'a> {
        match self {
            Container::Bag(b) => b.messages(topics),
            Container::Mcap(m) => m.messages(topics),
        }
    }
}

const SENSOR_TYPES: [&str; 3] = ["sensor_msgs/PointCloud2", "sensor_msgs/Image", "sensor_msgs/LaserScan"];
const POSE_TYPES: [&str; 5] = [
    "nav_msgs/Odometry",
    "geometry_msgs/PoseStamped",
    "geometry_msgs/TransformStamped",
    "tf2_msgs/TFMessage",
    "tf/tfMessage",
];

/// One sensor topic of a recording as it was found.
#[derive(Debug, Clone)]
struct Found {
    /// Its message type (`sensor_msgs/PointCloud2`, ...); `None` when the
    /// recording lacks the topic.
    msg_type: Option<String>,
    /// Messages on it, per the recording's index.
    messages: u64,
    /// Its camera info topic, when it has one.
    info_topic: Option<String>,
    /// The first camera info there.
    camera: Option<CameraInfo>,
}

/// A ROS recording opened for replay.
pub struct RosReplay {
    path: PathBuf,
    container: Container,
    opts: RosOptions,
    sensors: Vec<Found>,
    /// The sensor topics the recording has.
    present: Vec<String>,
    poses: Poses,
    warnings: Vec<String>,
}

impl std::fmt::Debug for RosReplay {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RosReplay").field("path", &self.path).field("sensors", &self.sensors).finish_non_exhaustive()
    }
}

fn bad(path: &Path, reason: String) -> IoError {
    IoError::Dataset { path: path.to_path_buf(), reason }
}

fn find<'a>(
    path: &Path,
    topics: &'a [TopicInfo],
    name: &str,
    role: &str,
    types: &[&str],
) -> Result<&'a TopicInfo, IoError> {
    let listing = || topics.iter().map(|t| format!("{} ({})", t.topic, t.msg_type)).collect::<Vec<_>>().join(", ");
    let t = topics
        .iter()
        .find(|t| t.topic == name)
        .ok_or_else(|| bad(path, format!("{role} topic {name} is not in the recording; it holds {}", listing())))?;
    if !types.contains(&t.msg_type.as_str()) {
        return Err(bad(path, format!("{role} topic {name} carries {}, not one of {}", t.msg_type, types.join(", "))));
    }
    Ok(t)
}

impl RosReplay {
    /// Opens `path` (a `.bag` or `.mcap`), checks the topics, and reads the
    /// poses and the camera intrinsics.
    ///
    /// With one sensor, its topic must be in the recording. With several, a
    /// sensor whose topic the recording lacks gives no frames and a warning
    /// (see [`Self::warnings`]), and the others are replayed; at least one
    /// must be there. A topic of the wrong message type is an error.
    pub fn open(path: &Path, opts: &RosOptions) -> Result<Self, IoError> {
        if opts.sensors.is_empty() {
            return Err(bad(path, "no sensor topic to replay".into()));
        }
        for (k, s) in opts.sensors.iter().enumerate() {
            if opts.sensors[..k].iter().any(|o| o.topic == s.topic) {
                return Err(bad(path, format!("two sensors on topic {}: each sensor needs its own topic", s.topic)));
            }
        }
        let container = Container::open(path)?;
        let topics = container.topics()?;
        let pose = find(path, &topics, &opts.pose_topic, "pose", &POSE_TYPES)?;
        let is_tf = pose.msg_type.ends_with("TFMessage") || pose.msg_type.ends_with("tfMessage");
        let mut warnings = Vec::new();
        let mut sensors = Vec::new();
        for s in &opts.sensors {
            let sensor = match find(path, &topics, &s.topic, "sensor", &SENSOR_TYPES) {
                Ok(t) => t,
                Err(e) if opts.sensors.len() > 1 && !topics.iter().any(|t| t.topic == s.topic) => {
                    warnings.push(format!("{e}: that sensor gives no frames"));
                    sensors.push(Found { msg_type: None, messages: 0, info_topic: None, camera: None });
                    continue;
                }
                Err(e) => return Err(e),
            };
            let info_topic = match &s.camera_info_topic {
                Some(t) => Some(find(path, &topics, t, "camera info", &["sensor_msgs/CameraInfo"])?.topic.clone()),
                None if sensor.msg_type == "sensor_msgs/Image" => {
                    let sibling = s.camera_info();
                    topics
                        .iter()
                        .find(|t| t.topic == sibling && t.msg_type == "sensor_msgs/CameraInfo")
                        .map(|t| t.topic.clone())
                }
                None => None,
            };
            sensors.push(Found {
                msg_type: Some(sensor.msg_type.clone()),
                messages: sensor.messages,
                info_topic,
                camera: None,
            });
        }
        if sensors.iter().all(|s| s.msg_type.is_none()) {
            let listing = topics.iter().map(|t| format!("{} ({})", t.topic, t.msg_type)).collect::<Vec<_>>().join(", ");
            let wanted = opts.sensors.iter().map(|s| s.topic.as_str()).collect::<Vec<_>>().join(", ");
            return Err(bad(
                path,
                format!("none of the sensor topics {wanted} is in the recording; it holds {listing}"),
            ));
        }
        let mut read = vec![pose.topic.clone()];
        if is_tf && topics.iter().any(|t| t.topic == opts.static_tf_topic) {
            read.push(opts.static_tf_topic.clone());
        }
        for info in sensors.iter().filter_map(|s| s.info_topic.clone()) {
            if !read.contains(&info) {
                read.push(info);
            }
        }
        let present = opts.sensors.iter().zip(&sensors).filter(|(_, f)| f.msg_type.is_some());
        let present = present.map(|(s, _)| s.topic.clone()).collect();
        let mut replay = RosReplay {
            path: path.to_path_buf(),
            sensors,
            present,
            opts: opts.clone(),
            poses: Poses::new(is_tf, opts),
            warnings,
            container,
        };
        replay.read_poses(&read, is_tf)?;
        Ok(replay)
    }

    /// One pass over the pose, static-tf and camera-info topics.
    fn read_poses(&mut self, topics: &[String], is_tf: bool) -> Result<(), IoError> {
        let mut undecodable = 0usize;
        let mut poses = Poses::new(is_tf, &self.opts);
        for item in self.container.messages(topics) {
            let raw = match item {
                Ok(raw) => raw,
                Err(e) => {
                    // Damage: keep the poses before it; frames after it fail anyway.
                    self.warnings.push(format!("poses read up to damage: {e}"));
                    break;
                }
            };
            match Message::decode(&raw.msg_type, &raw.data, raw.encoding).map(|m| with_log_time(m, raw.log_time_ns)) {
                Ok(Message::CameraInfo(info)) => {
                    for s in self.sensors.iter_mut().filter(|s| s.info_topic.as_ref() == Some(&raw.topic)) {
                        s.camera.get_or_insert_with(|| info.clone());
                    }
                }
                Ok(
                    msg @ (Message::Tf(_)
                    | Message::Odometry(_)
                    | Message::PoseStamped(_)
                    | Message::TransformStamped(_)),
                ) => {
                    let is_static = raw.topic == self.opts.static_tf_topic && raw.topic != self.opts.pose_topic;
                    poses.add(&msg, is_static, &self.opts).map_err(|e| bad(&self.path, e))?;
                }
                Ok(_) => {}
                Err(e) => {
                    if undecodable == 0 {
                        self.warnings.push(format!(
                            "{}: topic {}: skipping undecodable messages, the first: {e}",
                            self.path.display(),
                            raw.topic
                        ));
                    }
                    undecodable += 1;
                    tracing::debug!("{}: undecodable message {undecodable} on {}: {e}", self.path.display(), raw.topic);
                }
            }
        }
        if poses.is_empty() {
            return Err(bad(&self.path, format!("pose topic {} holds no readable pose", self.opts.pose_topic)));
        }
        self.poses = poses;
        Ok(())
    }

    /// The first sensor topic's message type (`sensor_msgs/PointCloud2`, ...).
    pub fn sensor_type(&self) -> &str {
        self.sensor_type_of(0).unwrap_or("")
    }

    /// Sensor `i`'s message type; `None` when the recording lacks its topic.
    pub fn sensor_type_of(&self, i: usize) -> Option<&str> {
        self.sensors.get(i).and_then(|s| s.msg_type.as_deref())
    }

    /// The sensor kind the first sensor's frames are, as `Sensor::kind` names it.
    pub fn kind(&self) -> &'static str {
        self.kind_of(0).unwrap_or("point cloud")
    }

    /// The sensor kind sensor `i`'s frames are; `None` when the recording
    /// lacks its topic.
    pub fn kind_of(&self, i: usize) -> Option<&'static str> {
        self.sensor_type_of(i).map(|t| match t {
            "sensor_msgs/Image" => "depth camera",
            "sensor_msgs/LaserScan" => "planar LiDAR",
            _ => "point cloud",
        })
    }

    /// Messages on the sensor topics together, per the recording's index.
    pub fn len(&self) -> usize {
        self.sensors.iter().map(|s| s.messages as usize).sum()
    }

    /// Messages on sensor `i`'s topic, per the recording's index.
    pub fn len_of(&self, i: usize) -> usize {
        self.sensors.get(i).map_or(0, |s| s.messages as usize)
    }

    /// Whether the sensor topics are empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The first sensor's first camera info, for depth images.
    pub fn camera_info(&self) -> Option<&CameraInfo> {
        self.camera_info_of(0)
    }

    /// Sensor `i`'s first camera info, for depth images.
    pub fn camera_info_of(&self, i: usize) -> Option<&CameraInfo> {
        self.sensors.get(i).and_then(|s| s.camera.as_ref())
    }

    /// What was noticed while opening (undecodable pose messages, damage,
    /// a sensor's missing topic).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    fn frame(&self, raw: &RawMessage, sensor: usize, index: usize) -> Result<Frame, FrameError> {
        let fail = |stamp_s: Option<f64>, reason: String| FrameError {
            file: self.path.clone(),
            sensor,
            topic: raw.topic.clone(),
            index,
            stamp_s,
            reason,
            fatal: false,
        };
        let msg = Message::decode(&raw.msg_type, &raw.data, raw.encoding).map_err(|e| fail(None, e))?;
        let (measurement, stamp_ns, frame_id) = measurement(msg, self.opts.depth_scale_m).map_err(|e| fail(None, e))?;
        // Recorders that leave stamps empty: the time the message was logged.
        let stamp_s = if stamp_ns == 0 { raw.log_time_ns as f64 * 1e-9 } else { stamp_ns as f64 * 1e-9 };
        let mount = &self.opts.sensors[sensor].t_body_sensor;
        let t_world_sensor =
            self.poses.sensor_pose(stamp_s, &frame_id, mount, &self.opts).map_err(|e| fail(Some(stamp_s), e))?;
        Ok(Frame { stamp_s, t_world_sensor, measurement })
    }

    /// The first sensor's frames in file order; damage ends them with a
    /// fatal error. With several sensors, see [`Self::sensor_frames`].
    pub fn frames(&self) -> impl Iterator<Item = Result<Frame, FrameError>> + '_ {
        // The first sensor's topic leads `present` when the recording has it.
        let first = usize::from(self.sensors[0].msg_type.is_some());
        self.stream(&self.present[..first]).map(|f| f.frame)
    }

    /// Every sensor's frames in the order the recording holds them (the
    /// order they were recorded in), each with its sensor and its position
    /// among that sensor's messages. Damage ends them with a fatal error
    /// (given as the first sensor's).
    pub fn sensor_frames(&self) -> impl Iterator<Item = SensorFrame> + '_ {
        self.stream(&self.present)
    }

    /// The frames of the sensor topics `topics`, in file order.
    fn stream<'a>(&'a self, topics: &'a [String]) -> impl Iterator<Item = SensorFrame> + 'a {
        let mut counts = vec![0usize; self.opts.sensors.len()];
        let mut done = false;
        self.container.messages(topics).map_while(move |item| {
            if done {
                return None;
            }
            Some(match item {
                Ok(raw) => {
                    let sensor = self.opts.sensors.iter().position(|s| s.topic == raw.topic).unwrap_or(0);
                    let index = counts[sensor];
                    counts[sensor] += 1;
                    SensorFrame { sensor, index, frame: self.frame(&raw, sensor, index) }
                }
                Err(e) => {
                    done = true;
                    let error = FrameError {
                        file: self.path.clone(),
                        sensor: 0,
                        topic: topics.join(", "),
                        index: counts[0],
                        stamp_s: None,
                        reason: format!("the recording is damaged here, the rest is unreadable: {e}"),
                        fatal: true,
                    };
                    SensorFrame { sensor: 0, index: counts[0], frame: Err(error) }
                }
            })
        })
    }
}

/// A sensor message of a recording as a frame, or why it is not one.
#[derive(Debug)]
pub struct SensorFrame {
    /// Its sensor's position in [`RosOptions::sensors`].
    pub sensor: usize,
    /// Its position among its sensor's messages, from 0.
    pub index: usize,
    /// The frame, or the error that took its place.
    pub frame: Result<Frame, FrameError>,
}
