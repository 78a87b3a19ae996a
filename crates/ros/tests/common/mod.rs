//! Writes ROS recordings for the tests through `RecordingWriter`: bags
//! with edtmap's hand-written writer, MCAP files with the `mcap` crate's.
#![allow(dead_code)] // each test file uses part of it

use edtmap_ros::msg::Message;
use edtmap_ros::{Encoding, RecordingWriter};
use std::path::Path;

/// Which container to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Container {
    /// ROS 1 bag.
    Bag,
    /// ROS 2 MCAP.
    Mcap,
}

impl Container {
    /// The file extension.
    pub(crate) fn ext(self) -> &'static str {
        match self {
            Container::Bag => "bag",
            Container::Mcap => "mcap",
        }
    }
}

/// One message to record.
pub(crate) struct Msg {
    pub(crate) topic: String,
    pub(crate) msg_type: String,
    pub(crate) message: Option<Message>,
    pub(crate) raw: Vec<u8>,
    pub(crate) log_time_s: f64,
    /// Store only the first half of the serialized message.
    pub(crate) truncate_payload: bool,
}

impl Msg {
    pub(crate) fn new(topic: &str, message: Message, log_time_s: f64) -> Self {
        Msg {
            topic: topic.into(),
            msg_type: message.type_name().into(),
            message: Some(message),
            raw: Vec::new(),
            log_time_s,
            truncate_payload: false,
        }
    }

    pub(crate) fn raw(topic: &str, msg_type: &str, raw: Vec<u8>, log_time_s: f64) -> Self {
        Msg { topic: topic.into(), msg_type: msg_type.into(), message: None, raw, log_time_s, truncate_payload: false }
    }

    fn bytes(&self, encoding: Encoding) -> Vec<u8> {
        let mut b = match &self.message {
            Some(m) => m.encode(encoding),
            None => self.raw.clone(),
        };
        if self.truncate_payload {
            b.truncate(b.len() / 2);
        }
        b
    }
}

/// Writes `msgs` in order; `finish` closes the file properly (index or
/// summary), else a bag is left as a recorder killed mid-run leaves it (the
/// MCAP writer always closes its file: tests cut it themselves). Chunks are
/// small, so that a cut file keeps whole chunks before the cut.
pub(crate) fn write_recording(path: &Path, container: Container, msgs: &[Msg], finish: bool) {
    assert!(path.extension().is_some_and(|e| e == container.ext()), "{} is not a .{}", path.display(), container.ext());
    let mut w = RecordingWriter::create_with_chunk_bytes(path, Some(4096)).expect("create recording");
    for m in msgs {
        let log_time_ns = (m.log_time_s * 1e9).round() as u64;
        w.write_raw(&m.topic, &m.msg_type, &m.bytes(w.encoding()), log_time_ns).expect("write");
    }
    if finish {
        w.finish().expect("finish");
    } else {
        w.finish_unindexed().expect("finish unindexed");
    }
}
