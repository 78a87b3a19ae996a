//! Writing recordings: ROS 1 bags (edtmap's [`BagWriter`]) or ROS 2 MCAP
//! files (the `mcap` crate's writer, CDR messages with `ros2msg` schemas),
//! chosen by the file's extension.

use super::bag::BagWriter;
use super::msg::Message;
use super::Encoding;
use edtmap_io::files::AtomicFile;
use edtmap_io::IoError;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

enum Sink {
    Bag(Box<BagWriter>),
    Mcap(Box<mcap::Writer<AtomicFile>>),
}

/// A recording being written, one message at a time.
pub struct RecordingWriter {
    path: PathBuf,
    sink: Sink,
    channels: HashMap<String, u32>,
    sequence: u32,
}

impl std::fmt::Debug for RecordingWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordingWriter").field("path", &self.path).finish_non_exhaustive()
    }
}

fn mcap_error(path: &Path, e: mcap::McapError) -> IoError {
    IoError::Dataset { path: path.to_path_buf(), reason: format!("writing MCAP: {e}") }
}

impl RecordingWriter {
    /// Creates `path`: a `.bag` or an `.mcap`, with each writer's default
    /// chunk size.
    pub fn create(path: &Path) -> Result<Self, IoError> {
        Self::create_with_chunk_bytes(path, None)
    }

    /// Creates `path` with chunks of about `chunk_bytes` (small chunks let a
    /// cut file keep more of what was written before the cut).
    pub fn create_with_chunk_bytes(path: &Path, chunk_bytes: Option<u32>) -> Result<Self, IoError> {
        let sink = match path.extension().and_then(|e| e.to_str()) {
            Some("bag") => {
                let w = BagWriter::create(path)?;
                Sink::Bag(Box::new(match chunk_bytes {
                    Some(b) => w.with_chunk_bytes(b),
                    None => w,
                }))
            }
            Some("mcap") => {
                let file = AtomicFile::create(path)?;
                let mut options = mcap::WriteOptions::new();
                if let Some(b) = chunk_bytes {
                    options = options.chunk_size(Some(u64::from(b)));
                }
                Sink::Mcap(Box::new(options.create(file).map_err(|e| mcap_error(path, e))?))
            }
            _ => {
                return Err(IoError::Dataset {
                    path: path.to_path_buf(),
                    reason: "a recording is written as .bag (ROS 1) or .mcap (ROS 2)".into(),
                })
            }
        };
        Ok(RecordingWriter { path: path.to_path_buf(), sink, channels: HashMap::new(), sequence: 0 })
    }

    /// The channel (or connection) of `topic`, registered on first use.
    fn channel(&mut self, topic: &str, msg_type: &str) -> Result<u32, IoError> {
        if let Some(&c) = self.channels.get(topic) {
            return Ok(c);
        }
        let c = match &mut self.sink {
            Sink::Bag(w) => w.add_connection(topic, msg_type, "*", "")?,
            Sink::Mcap(w) => {
                let ros2_name = msg_type.replacen('/', "/msg/", 1);
                let schema = w.add_schema(&ros2_name, "ros2msg", b"").map_err(|e| mcap_error(&self.path, e))?;
                u32::from(w.add_channel(schema, topic, "cdr", &BTreeMap::new()).map_err(|e| mcap_error(&self.path, e))?)
            }
        };
        self.channels.insert(topic.to_string(), c);
        Ok(c)
    }

    /// How this container serializes messages: ROS 1 in bags, CDR in MCAP.
    pub fn encoding(&self) -> Encoding {
        match self.sink {
            Sink::Bag(_) => Encoding::Ros1,
            Sink::Mcap(_) => Encoding::Cdr,
        }
    }

    /// Writes `msg` on `topic`, logged at `log_time_ns`.
    pub fn write(&mut self, topic: &str, msg: &Message, log_time_ns: u64) -> Result<(), IoError> {
        self.write_raw(topic, msg.type_name(), &msg.encode(self.encoding()), log_time_ns)
    }

    /// Writes bytes already serialized in [`Self::encoding`] as a message of
    /// type `msg_type` (`package/Type`) on `topic`.
    pub fn write_raw(&mut self, topic: &str, msg_type: &str, data: &[u8], log_time_ns: u64) -> Result<(), IoError> {
        let channel = self.channel(topic, msg_type)?;
        self.sequence = self.sequence.wrapping_add(1);
        match &mut self.sink {
            Sink::Bag(w) => w.write(channel, log_time_ns, data),
            Sink::Mcap(w) => {
                let channel_id = u16::try_from(channel).map_err(|_| IoError::Dataset {
                    path: self.path.clone(),
                    reason: "more than 65535 MCAP channels".into(),
                })?;
                let header = mcap::records::MessageHeader {
                    channel_id,
                    sequence: self.sequence,
                    log_time: log_time_ns,
                    publish_time: log_time_ns,
                };
                w.write_to_known_channel(&header, data).map_err(|e| mcap_error(&self.path, e))
            }
        }
    }

    /// Closes the file (the bag's index, or the MCAP summary and footer)
    /// and puts it in place; until then any file at the path is untouched.
    /// Dropped without it, nothing is written.
    pub fn finish(self) -> Result<(), IoError> {
        match self.sink {
            Sink::Bag(w) => w.finish(),
            Sink::Mcap(mut w) => {
                w.finish().map_err(|e| mcap_error(&self.path, e))?;
                w.into_inner().commit()
            }
        }
    }

    /// Puts the file in place as a recorder killed mid-run leaves it: a
    /// bag without its index; an MCAP file is closed whole (tests cut it
    /// themselves). For tests of the readers' recovery.
    pub fn finish_unindexed(self) -> Result<(), IoError> {
        match self.sink {
            Sink::Bag(w) => w.finish_unindexed(),
            sink @ Sink::Mcap(_) => RecordingWriter { sink, ..self }.finish(),
        }
    }
}
