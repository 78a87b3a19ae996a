//! ROS recordings: ROS 1 bags ([`bag`]) and ROS 2 MCAP files ([`mcap`]),
//! read as raw messages, and the message types edtmap maps from ([`msg`]);
//! any recording, folders too, opened as `[dataset]` ([`config`]) says
//! ([`recording`]).
//!
//! Both containers give [`RawMessage`]s in file order; a recording that is
//! cut short or corrupt yields the messages before the damage and then one
//! error naming the file and the byte offset, so a replay keeps what it
//! already integrated.

pub mod bag;
pub mod config;
mod convert;
pub mod mcap;
pub mod msg;
#[cfg(test)]
mod msg_tests;
pub mod poses;
pub mod recording;
pub mod replay;
pub mod tf;
mod wire;
pub mod writer;

pub use replay::{FrameError, RosOptions, RosReplay, SensorFrame, SensorTopic};
pub use writer::RecordingWriter;

use std::path::Path;

/// How a message's bytes are serialized.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 1: little-endian, packed, `u32` length before strings and
    /// variable arrays.
    Ros1,
    /// ROS 2: CDR with its 4-byte encapsulation header (either byte order),
    /// fields aligned to their size.
    Cdr,
}

/// One message as stored in a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct RawMessage {
    /// The topic, e.g. `/velodyne_points`.
    pub topic: String,
    /// The message type as `package/Type` (`sensor_msgs/PointCloud2`); ROS 2
    /// names (`sensor_msgs/msg/PointCloud2`) are given without `/msg/`.
    pub msg_type: String,
    /// Time the recorder logged the message, nanoseconds since the epoch.
    pub log_time_ns: u64,
    /// The serialized message.
    pub data: Vec<u8>,
    /// How `data` is serialized.
    pub encoding: Encoding,
}

/// A topic of a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// The topic name.
    pub topic: String,
    /// Its message type as `package/Type`.
    pub msg_type: String,
    /// Messages on it.
    pub messages: u64,
}

/// `sensor_msgs/msg/PointCloud2` → `sensor_msgs/PointCloud2`.
pub fn normalize_type(name: &str) -> String {
    name.replacen("/msg/", "/", 1)
}

/// Whether `path` is a file, to be read as a recording (bag or MCAP, told
/// apart by their magic bytes, whatever the name: a killed `rosbag record`
/// leaves `NAME.bag.active`); folders are read as [`edtmap_io::dataset`]s.
pub fn is_recording(path: &Path) -> bool {
    path.is_file()
}
