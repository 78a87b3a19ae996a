//! Writes ROS recordings for the tests: bags with edtmap's hand-written
//! writer, MCAP files with the `mcap` crate's.
#![allow(dead_code)] // each test file uses part of it

use edtmap_io::ros::bag::BagWriter;
use edtmap_io::ros::msg::Message;
use edtmap_io::ros::Encoding;
use std::collections::{BTreeMap, HashMap};
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
        Msg { topic: topic.into(), msg_type: message.type_name().into(), message: Some(message), raw: Vec::new(), log_time_s, truncate_payload: false }
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
/// summary), else it is left as a recorder killed mid-run leaves it.
pub(crate) fn write_recording(path: &Path, container: Container, msgs: &[Msg], finish: bool) {
    let ns = |t: f64| (t * 1e9).round() as u64;
    match container {
        Container::Bag => {
            let mut w = BagWriter::create(path).expect("create bag");
            let mut conns = HashMap::new();
            for m in msgs {
                let conn = match conns.get(&m.topic) {
                    Some(c) => *c,
                    None => {
                        let c = w.add_connection(&m.topic, &m.msg_type, "*", "").expect("connection");
                        conns.insert(m.topic.clone(), c);
                        c
                    }
                };
                w.write(conn, ns(m.log_time_s), &m.bytes(Encoding::Ros1)).expect("write");
            }
            if finish {
                w.finish().expect("finish");
            }
        }
        Container::Mcap => {
            let file = std::io::BufWriter::new(std::fs::File::create(path).expect("create mcap"));
            // Small chunks, so that a cut file keeps whole chunks before the cut.
            let mut w = mcap::WriteOptions::new().chunk_size(Some(4096)).create(file).expect("mcap writer");
            let mut channels = HashMap::new();
            for (seq, m) in msgs.iter().enumerate() {
                let channel = match channels.get(&m.topic) {
                    Some(c) => *c,
                    None => {
                        let ros2_name = m.msg_type.replacen('/', "/msg/", 1);
                        let schema = w.add_schema(&ros2_name, "ros2msg", b"").expect("schema");
                        let c = w.add_channel(schema, &m.topic, "cdr", &BTreeMap::new()).expect("channel");
                        channels.insert(m.topic.clone(), c);
                        c
                    }
                };
                let header = mcap::records::MessageHeader { channel_id: channel, sequence: seq as u32, log_time: ns(m.log_time_s), publish_time: ns(m.log_time_s) };
                w.write_to_known_channel(&header, &m.bytes(Encoding::Cdr)).expect("write");
            }
            // The crate's writer always closes the file; tests cut it
            // themselves to play a recorder killed mid-run.
            let _ = finish;
            w.finish().expect("finish");
        }
    }
}
