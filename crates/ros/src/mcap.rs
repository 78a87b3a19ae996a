//! ROS 2 MCAP files ([mcap.dev](https://mcap.dev/spec)), read as raw
//! messages.
//!
//! The file is streamed, a piece at a time, through the `mcap` crate's
//! sans-I/O [`LinearReader`](::mcap::sans_io::LinearReader), so memory grows with the largest chunk, not
//! with the recording. The reader hands chunks over whole and this module
//! opens them: an uncompressed chunk is walked here with every length
//! checked against the chunk, a compressed one goes through a second
//! `LinearReader` limited to the chunk's stated size, which decompresses it
//! and checks its CRC before the first record comes out. So a damaged chunk
//! gives no message, and a recording killed mid-run (no data end record, no
//! summary, the last chunk cut) gives every message of its complete chunks
//! and then one error.
//!
//! [`McapReader::topics`] trusts the summary section only when its CRC, its
//! records and its statistics record check out; otherwise it counts the
//! messages with a scan of the data section.

mod stream;
mod summary;
#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};

use ::mcap::MAGIC;

use super::{RawMessage, TopicInfo};
use edtmap_io::IoError;
use stream::Stream;
use summary::summary_topics;

/// Opcode and body length in front of every record, bytes.
const RECORD_PREFIX: usize = 1 + 8;

/// A ROS 2 MCAP file opened for reading.
///
/// ```no_run
/// # fn main() -> Result<(), edtmap_io::IoError> {
/// use edtmap_ros::mcap::McapReader;
///
/// let mcap = McapReader::open(std::path::Path::new("run.mcap"))?;
/// for topic in mcap.topics()? {
///     println!("{} [{}]: {} messages", topic.topic, topic.msg_type, topic.messages);
/// }
/// for message in mcap.messages(&["/velodyne_points".to_string()]) {
///     let message = message?;
///     println!("{} at {} ns: {} bytes", message.topic, message.log_time_ns, message.data.len());
/// }
/// # Ok(())
/// # }
/// ```
#[derive(Debug, Clone)]
pub struct McapReader {
    path: PathBuf,
}

impl McapReader {
    /// Opens an MCAP file: checks that it is a regular file (streamed, so
    /// of any size) and its magic.
    pub fn open(path: &Path) -> Result<Self, IoError> {
        let (mut file, _) = edtmap_io::files::open_input(path, u64::MAX)?;
        let mut magic = [0; 8];
        match file.read_exact(&mut magic) {
            Ok(()) if magic[..] == *MAGIC => Ok(Self { path: path.to_path_buf() }),
            Ok(()) => Err(dataset(path, "not an MCAP file: it does not start with the MCAP magic")),
            Err(e) if e.kind() == ErrorKind::UnexpectedEof => {
                Err(dataset(path, "not an MCAP file: shorter than the MCAP magic"))
            }
            Err(e) => Err(IoError::io(path, e)),
        }
    }

    /// Topics with their types (schema names, normalized:
    /// `sensor_msgs/msg/PointCloud2` → `sensor_msgs/PointCloud2`; `""` for
    /// a channel without a schema) and message counts, sorted by topic: from
    /// the summary's statistics when the file has a valid summary, else by
    /// a scan (a truncated file lists what it holds before the damage).
    pub fn topics(&self) -> Result<Vec<TopicInfo>, IoError> {
        let (mut file, _) = edtmap_io::files::open_input(&self.path, u64::MAX)?;
        if let Some(topics) = summary_topics(&mut file, &self.path)? {
            return Ok(topics);
        }
        Ok(topic_list(stream::scan(&self.path)?))
    }

    /// Messages on `topics` (all when empty) in file order. Yields `Ok`
    /// messages until damage (truncation, bad CRC, bad chunk, unknown
    /// compression...) or a message of an asked-for topic in an encoding
    /// other than `cdr` or `ros1`, then one `Err` naming the file, the byte
    /// offset and what is wrong, then `None`. Never panics on any bytes.
    pub fn messages<'a>(&'a self, topics: &'a [String]) -> Box<dyn Iterator<Item = Result<RawMessage, IoError>> + 'a> {
        match Stream::new(&self.path, Some(topics)) {
            Ok(stream) => Box::new(stream),
            Err(e) => Box::new(std::iter::once(Err(e))),
        }
    }
}

fn dataset(path: &Path, reason: impl Into<String>) -> IoError {
    IoError::Dataset { path: path.to_path_buf(), reason: reason.into() }
}

/// One list entry per topic and type, counts of its channels summed.
fn topic_list(channels: impl IntoIterator<Item = (String, String, u64)>) -> Vec<TopicInfo> {
    let mut merged = BTreeMap::<(String, String), u64>::new();
    for (topic, msg_type, messages) in channels {
        *merged.entry((topic, msg_type)).or_default() += messages;
    }
    merged.into_iter().map(|((topic, msg_type), messages)| TopicInfo { topic, msg_type, messages }).collect()
}

/// Splits `bytes` into records `(offset in bytes, opcode, body)`; a record
/// whose length runs past the end gives one `Err` and ends the walk.
fn split_records(bytes: &[u8]) -> impl Iterator<Item = Result<(usize, u8, &[u8]), String>> + '_ {
    let mut at = 0;
    std::iter::from_fn(move || {
        if at >= bytes.len() {
            return None;
        }
        let record = (|| {
            let (&opcode, rest) = bytes[at..].split_first()?;
            let (len, rest) = rest.split_first_chunk::<8>()?;
            let body = rest.get(..usize::try_from(u64::from_le_bytes(*len)).ok()?)?;
            Some((opcode, body))
        })();
        let here = at;
        match record {
            Some((opcode, body)) => {
                at += RECORD_PREFIX + body.len();
                Some(Ok((here, opcode, body)))
            }
            None => {
                at = bytes.len();
                Some(Err(format!("the record at byte {here} runs past the end")))
            }
        }
    })
}
