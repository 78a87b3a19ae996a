//! ROS 2 MCAP files ([mcap.dev](https://mcap.dev/spec)), read as raw
//! messages.
//!
//! The file is streamed, a piece at a time, through the `mcap` crate's
//! sans-I/O [`LinearReader`], so memory grows with the largest chunk, not
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

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::fs::File;
use std::io::{ErrorKind, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use ::mcap::records::{op, ChunkHeader, MessageHeader, Record};
use ::mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use ::mcap::{parse_record, McapError, MAGIC};

use super::{normalize_type, Encoding, RawMessage, TopicInfo};
use crate::IoError;

/// Largest decompressed chunk read, bytes: a chunk that claims more is
/// taken for damage rather than allocated.
const MAX_CHUNK_BYTES: u64 = 1 << 30;
/// Largest summary section read, bytes: a bigger one is skipped for a scan.
const MAX_SUMMARY_BYTES: u64 = 1 << 28;
/// Bytes read from the file at a time.
const READ_BYTES: usize = 1 << 20;
/// Opcode and body length in front of every record, bytes.
const RECORD_PREFIX: usize = 1 + 8;
/// The footer record: prefix, summary start, summary offset start, CRC.
const FOOTER_BYTES: usize = RECORD_PREFIX + 8 + 8 + 4;

/// A ROS 2 MCAP file opened for reading.
///
/// ```no_run
/// # fn main() -> Result<(), edtmap_io::IoError> {
/// use edtmap_io::ros::mcap::McapReader;
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
    /// Opens an MCAP file: checks the magic.
    pub fn open(path: &Path) -> Result<Self, IoError> {
        let mut file = File::open(path).map_err(|e| IoError::io(path, e))?;
        let mut magic = [0; 8];
        match file.read_exact(&mut magic) {
            Ok(()) if magic[..] == *MAGIC => Ok(Self {
                path: path.to_path_buf(),
            }),
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
        let mut file = File::open(&self.path).map_err(|e| IoError::io(&self.path, e))?;
        if let Some(topics) = summary_topics(&mut file, &self.path)? {
            return Ok(topics);
        }
        let mut scan = Stream::new(&self.path, None)?;
        for item in scan.by_ref() {
            if let Err(e) = item {
                tracing::debug!("{e}; listing the topics before the damage");
            }
        }
        let counts = scan
            .decoder
            .channels
            .into_values()
            .map(|c| (c.topic, c.msg_type, c.messages));
        Ok(topic_list(counts))
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
    IoError::Dataset {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

/// One list entry per topic and type, counts of its channels summed.
fn topic_list(channels: impl IntoIterator<Item = (String, String, u64)>) -> Vec<TopicInfo> {
    let mut merged = BTreeMap::<(String, String), u64>::new();
    for (topic, msg_type, messages) in channels {
        *merged.entry((topic, msg_type)).or_default() += messages;
    }
    merged
        .into_iter()
        .map(|((topic, msg_type), messages)| TopicInfo {
            topic,
            msg_type,
            messages,
        })
        .collect()
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

/// Topics from the summary section, or `None` when the file has none or one
/// that fails its checks (footer, CRC, records, statistics).
fn summary_topics(file: &mut File, path: &Path) -> Result<Option<Vec<TopicInfo>>, IoError> {
    let io = |e| IoError::io(path, e);
    let len = file.metadata().map_err(io)?.len();
    let tail_len = (FOOTER_BYTES + MAGIC.len()) as u64;
    let Some(footer_at) = len.checked_sub(tail_len).filter(|&at| at >= MAGIC.len() as u64) else {
        return Ok(None);
    };
    let mut tail = [0; FOOTER_BYTES + 8];
    file.seek(SeekFrom::Start(footer_at)).map_err(io)?;
    file.read_exact(&mut tail).map_err(io)?;
    let (footer, magic) = tail.split_at(FOOTER_BYTES);
    if *magic != *MAGIC || footer[0] != op::FOOTER || footer[1..RECORD_PREFIX] != 20u64.to_le_bytes() {
        return Ok(None);
    }
    let Ok(Record::Footer(footer_record)) = parse_record(op::FOOTER, &footer[RECORD_PREFIX..]) else {
        return Ok(None);
    };
    let start = footer_record.summary_start;
    if start < MAGIC.len() as u64 || start > footer_at || footer_at - start > MAX_SUMMARY_BYTES {
        return Ok(None);
    }
    let mut section = vec![0; (footer_at - start) as usize];
    file.seek(SeekFrom::Start(start)).map_err(io)?;
    file.read_exact(&mut section).map_err(io)?;
    if footer_record.summary_crc != 0 {
        // The CRC covers the section and the footer up to the CRC field.
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(&section);
        hasher.update(&footer[..FOOTER_BYTES - 4]);
        if hasher.finalize() != footer_record.summary_crc {
            tracing::debug!(
                "{}: the summary CRC does not match; scanning for the topics",
                path.display()
            );
            return Ok(None);
        }
    }
    Ok(parse_summary(&section))
}

/// Topics from the summary section's schema, channel and statistics
/// records; `None` when one is malformed, the statistics are missing or do
/// not count the channels listed.
fn parse_summary(section: &[u8]) -> Option<Vec<TopicInfo>> {
    let mut schemas = HashMap::new();
    let mut channels = BTreeMap::new();
    let mut statistics = None;
    for record in split_records(section) {
        let (_, opcode, body) = record.ok()?;
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::STATISTICS) {
            continue;
        }
        match parse_record(opcode, body).ok()? {
            Record::Schema { header, .. } if header.id != 0 => {
                schemas.insert(header.id, normalize_type(&header.name));
            }
            Record::Channel(channel) => {
                channels.insert(channel.id, channel);
            }
            Record::Statistics(stats) => statistics = Some(stats),
            _ => {}
        }
    }
    let statistics = statistics?;
    if u32::try_from(channels.len()).ok()? != statistics.channel_count {
        return None;
    }
    let counts = channels.into_values().map(|c| {
        let messages = statistics.channel_message_counts.get(&c.id).copied().unwrap_or(0);
        (
            c.topic,
            schemas.get(&c.schema_id).cloned().unwrap_or_default(),
            messages,
        )
    });
    Some(topic_list(counts))
}

/// A channel as the data section defines it.
struct Channel {
    topic: String,
    /// Normalized schema name; `""` without a schema.
    msg_type: String,
    message_encoding: String,
    /// Whether its messages are handed out.
    wanted: bool,
    /// Messages seen on it so far.
    messages: u64,
}

/// The schemas and channels seen so far and the messages decoded but not
/// yet handed out.
struct Decoder<'a> {
    /// Topics whose messages are handed out (all when empty); `None` only
    /// counts them.
    topics: Option<&'a [String]>,
    /// Schema ID → normalized name.
    schemas: HashMap<u16, String>,
    channels: BTreeMap<u16, Channel>,
    ready: VecDeque<RawMessage>,
}

impl Decoder<'_> {
    /// Takes a schema, channel or message record; ignores other records.
    fn record(&mut self, opcode: u8, body: &[u8]) -> Result<(), String> {
        if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) {
            return Ok(());
        }
        match parse_record(opcode, body).map_err(|e| describe(&e))? {
            // ID 0 means "no schema" to a channel.
            Record::Schema { header, .. } if header.id != 0 => {
                self.schemas
                    .entry(header.id)
                    .or_insert_with(|| normalize_type(&header.name));
            }
            Record::Channel(c) => {
                let wanted = self.topics.is_some_and(|t| t.is_empty() || t.contains(&c.topic));
                let msg_type = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                let channel = Channel {
                    topic: c.topic,
                    msg_type,
                    message_encoding: c.message_encoding,
                    wanted,
                    messages: 0,
                };
                self.channels.entry(c.id).or_insert(channel);
            }
            Record::Message { header, data } => self.message(&header, &data)?,
            _ => {}
        }
        Ok(())
    }

    fn message(&mut self, header: &MessageHeader, data: &[u8]) -> Result<(), String> {
        let Some(channel) = self.channels.get_mut(&header.channel_id) else {
            return Err(format!(
                "a message on channel {} that no channel record defines",
                header.channel_id
            ));
        };
        channel.messages += 1;
        if !channel.wanted {
            return Ok(());
        }
        let encoding = match channel.message_encoding.as_str() {
            "cdr" => Encoding::Cdr,
            "ros1" => Encoding::Ros1,
            other => {
                return Err(format!(
                    "topic {} has message encoding {other:?}; only \"cdr\" (ROS 2) and \"ros1\" are read",
                    channel.topic
                ))
            }
        };
        self.ready.push_back(RawMessage {
            topic: channel.topic.clone(),
            msg_type: channel.msg_type.clone(),
            log_time_ns: header.log_time,
            data: data.to_vec(),
            encoding,
        });
        Ok(())
    }

    /// Takes every record of a chunk, after checking its CRC.
    fn chunk(&mut self, body: &[u8]) -> Result<(), String> {
        let Record::Chunk { header, data } = parse_record(op::CHUNK, body).map_err(|e| describe(&e))? else {
            return Err("not a chunk".into());
        };
        if header.uncompressed_size > MAX_CHUNK_BYTES {
            return Err(format!(
                "the chunk claims {} bytes uncompressed, more than the {MAX_CHUNK_BYTES} read",
                header.uncompressed_size
            ));
        }
        if !header.compression.is_empty() {
            return self.compressed_chunk(&header, body);
        }
        if data.len() as u64 != header.uncompressed_size {
            return Err(format!(
                "the uncompressed chunk holds {} bytes but claims {}",
                data.len(),
                header.uncompressed_size
            ));
        }
        if header.uncompressed_crc != 0 && crc32fast::hash(&data) != header.uncompressed_crc {
            return Err(format!("chunk CRC mismatch (expected {:08X})", header.uncompressed_crc));
        }
        for record in split_records(&data) {
            let (at, opcode, body) = record?;
            self.record(opcode, body)
                .map_err(|e| format!("record at byte {at} of the chunk's records: {e}"))?;
        }
        Ok(())
    }

    /// Decompresses a chunk with a `LinearReader` fed the chunk record alone
    /// and limited to the chunk's stated sizes; it checks the CRC of the
    /// whole chunk before handing out its first record.
    fn compressed_chunk(&mut self, header: &ChunkHeader, body: &[u8]) -> Result<(), String> {
        let limit = usize::try_from(header.uncompressed_size.max(body.len() as u64))
            .map_err(|_| "the chunk is too large for this machine".to_string())?;
        let mut reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_skip_start_magic(true)
                .with_skip_end_magic(true)
                .with_validate_chunk_crcs(true)
                .with_prevalidate_chunk_crcs(true)
                .with_record_length_limit(limit),
        );
        let mut prefix = [op::CHUNK; RECORD_PREFIX];
        prefix[1..].copy_from_slice(&(body.len() as u64).to_le_bytes());
        let mut source = prefix.chain(body);
        while let Some(event) = reader.next_event() {
            match event.map_err(|e| describe(&e))? {
                LinearReadEvent::ReadRequest(n) => {
                    let got = source
                        .read(reader.insert(n.min(READ_BYTES)))
                        .map_err(|e| e.to_string())?;
                    reader.notify_read(got);
                }
                LinearReadEvent::Record { opcode, data } => self.record(opcode, data)?,
            }
        }
        Ok(())
    }
}

/// What is wrong, in words, for an error of the `mcap` crate.
fn describe(error: &McapError) -> String {
    match error {
        McapError::Parse(e) => format!("malformed record ({e})"),
        McapError::UnexpectedEoc => "a record runs past the end of its chunk".into(),
        McapError::UnsupportedCompression(c) => format!("chunk compression {c:?} is not supported (zstd, lz4 are)"),
        e => e.to_string(),
    }
}

/// The data section's messages, record after record, from a file read a
/// piece at a time.
struct Stream<'a> {
    path: &'a Path,
    file: File,
    file_len: u64,
    reader: LinearReader,
    /// Offset of the next top-level record.
    at: u64,
    decoder: Decoder<'a>,
    /// The damage found, handed out after the messages before it.
    error: Option<IoError>,
    done: bool,
}

impl<'a> Stream<'a> {
    fn new(path: &'a Path, topics: Option<&'a [String]>) -> Result<Self, IoError> {
        let file = File::open(path).map_err(|e| IoError::io(path, e))?;
        let file_len = file.metadata().map_err(|e| IoError::io(path, e))?.len();
        let limit = usize::try_from(file_len).unwrap_or(usize::MAX);
        let reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_emit_chunks(true)
                .with_validate_data_section_crc(true)
                .with_record_length_limit(limit),
        );
        let decoder = Decoder {
            topics,
            schemas: HashMap::new(),
            channels: BTreeMap::new(),
            ready: VecDeque::new(),
        };
        Ok(Self {
            path,
            file,
            file_len,
            reader,
            at: MAGIC.len() as u64,
            decoder,
            error: None,
            done: false,
        })
    }

    /// Advances by one reader event: reads from the file, or takes one
    /// top-level record.
    fn step(&mut self) -> Result<(), IoError> {
        let Some(event) = self.reader.next_event() else {
            self.done = true;
            return Ok(());
        };
        let (opcode, body) = match event {
            Ok(LinearReadEvent::Record { opcode, data }) => (opcode, data),
            Ok(LinearReadEvent::ReadRequest(n)) => {
                let buf = self.reader.insert(n.min(READ_BYTES));
                let got = read_some(&mut self.file, buf).map_err(|e| IoError::io(self.path, e))?;
                self.reader.notify_read(got);
                return Ok(());
            }
            Err(e) => return Err(dataset(self.path, damage(self.at, self.file_len, &e))),
        };
        let at = self.at;
        self.at += (RECORD_PREFIX + body.len()) as u64;
        let result = match opcode {
            op::DATA_END | op::FOOTER => {
                self.done = true;
                return Ok(());
            }
            op::CHUNK => self
                .decoder
                .chunk(body)
                .map_err(|e| format!("the chunk at byte {at}: {e}")),
            _ => self
                .decoder
                .record(opcode, body)
                .map_err(|e| format!("the record at byte {at}: {e}")),
        };
        result.map_err(|reason| dataset(self.path, reason))
    }
}

impl Iterator for Stream<'_> {
    type Item = Result<RawMessage, IoError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(message) = self.decoder.ready.pop_front() {
                return Some(Ok(message));
            }
            if let Some(error) = self.error.take() {
                self.done = true;
                return Some(Err(error));
            }
            if self.done {
                return None;
            }
            if let Err(error) = self.step() {
                self.error = Some(error);
            }
        }
    }
}

/// The damage the top-level reader found at the record at byte `at`.
fn damage(at: u64, file_len: u64, error: &McapError) -> String {
    match error {
        McapError::UnexpectedEof if at >= file_len => {
            format!("truncated at byte {at}: the file ends before the data end record")
        }
        McapError::UnexpectedEof => {
            format!("truncated: the file ({file_len} bytes) ends inside the record at byte {at}")
        }
        McapError::BadMagic => "not an MCAP file: it does not start with the MCAP magic".into(),
        e => format!("the record at byte {at}: {}", describe(e)),
    }
}

/// Reads into `buf`, retrying when interrupted; 0 at the end of the file.
fn read_some(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    loop {
        match file.read(buf) {
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            result => return result,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use ::mcap::{Compression, WriteOptions};
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    use super::*;

    const TOPICS: [(&str, &str); 3] = [
        ("/velodyne_points", "sensor_msgs/msg/PointCloud2"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/odom", "nav_msgs/msg/Odometry"),
    ];
    const MESSAGES: usize = 48;
    const PER_CHUNK: usize = 8;

    /// The messages of the test recordings: the topics in turn, payloads of
    /// varying length behind a CDR header.
    fn expected() -> Vec<RawMessage> {
        (0..MESSAGES)
            .map(|i| {
                let (topic, msg_type) = TOPICS[i % TOPICS.len()];
                let mut data = vec![0, 1, 0, 0];
                data.extend((0..(i * 7) % 40 + 1).map(|k| (i * 3 + k) as u8));
                let (topic, msg_type) = (topic.to_string(), normalize_type(msg_type));
                RawMessage {
                    topic,
                    msg_type,
                    log_time_ns: 1_000 + 10 * i as u64,
                    data,
                    encoding: Encoding::Cdr,
                }
            })
            .collect()
    }

    fn expected_topics(messages: &[RawMessage]) -> Vec<TopicInfo> {
        topic_list(messages.iter().map(|m| (m.topic.clone(), m.msg_type.clone(), 1)))
    }

    /// A recording of `expected()`, a chunk per `PER_CHUNK` messages when
    /// chunked.
    fn recording(options: WriteOptions) -> Vec<u8> {
        let mut writer = options
            .chunk_size(None)
            .create(Cursor::new(Vec::new()))
            .expect("writer");
        let mut channels = Vec::new();
        for (topic, msg_type) in TOPICS {
            let schema = writer
                .add_schema(msg_type, "ros2msg", b"# the definition")
                .expect("schema");
            channels.push(
                writer
                    .add_channel(schema, topic, "cdr", &BTreeMap::new())
                    .expect("channel"),
            );
        }
        for (i, message) in expected().iter().enumerate() {
            let header = MessageHeader {
                channel_id: channels[i % TOPICS.len()],
                sequence: i as u32,
                log_time: message.log_time_ns,
                publish_time: message.log_time_ns,
            };
            writer.write_to_known_channel(&header, &message.data).expect("message");
            if (i + 1) % PER_CHUNK == 0 {
                writer.flush().expect("flush");
            }
        }
        writer.finish().expect("finish");
        writer.into_inner().into_inner()
    }

    fn variants() -> Vec<(&'static str, WriteOptions)> {
        vec![
            ("uncompressed", WriteOptions::new().compression(None)),
            ("zstd", WriteOptions::new().compression(Some(Compression::Zstd))),
            ("lz4", WriteOptions::new().compression(Some(Compression::Lz4))),
            ("unchunked", WriteOptions::new().use_chunks(false)),
        ]
    }

    fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
        let path = dir.path().join(name);
        replace(&path, bytes);
        path
    }

    /// Writes a new file at `path`: truncating the old one instead would
    /// make ext4 flush it to disk on close, a thousand times a test.
    fn replace(path: &Path, bytes: &[u8]) {
        let _ = std::fs::remove_file(path);
        std::fs::write(path, bytes).expect("write the test file");
    }

    fn read(path: &Path, topics: &[String]) -> Vec<Result<RawMessage, IoError>> {
        McapReader::open(path).expect("open").messages(topics).collect()
    }

    /// Leading `Ok` messages and the errors after them.
    fn split(items: Vec<Result<RawMessage, IoError>>) -> (Vec<RawMessage>, Vec<IoError>) {
        let mut messages = Vec::new();
        let mut errors = Vec::new();
        for item in items {
            match item {
                Ok(message) if errors.is_empty() => messages.push(message),
                Ok(message) => panic!("message {message:?} after an error"),
                Err(e) => errors.push(e),
            }
        }
        (messages, errors)
    }

    /// Top-level records `(offset, opcode)` up to the footer.
    fn top_records(bytes: &[u8]) -> Vec<(usize, u8)> {
        split_records(&bytes[MAGIC.len()..])
            .map_while(Result::ok)
            .map(|(at, opcode, _)| (at + MAGIC.len(), opcode))
            .collect()
    }

    fn offsets_of(bytes: &[u8], opcode: u8) -> Vec<usize> {
        top_records(bytes)
            .into_iter()
            .filter(|&(_, op)| op == opcode)
            .map(|(at, _)| at)
            .collect()
    }

    #[test]
    fn reads_back_what_was_written() {
        let dir = tempfile::tempdir().expect("temp dir");
        let all = expected();
        for (name, options) in variants() {
            let path = write(&dir, &format!("{name}.mcap"), &recording(options));
            let mcap = McapReader::open(&path).expect("open");
            let mut file = File::open(&path).expect("file");
            assert!(
                summary_topics(&mut file, &path).expect("summary").is_some(),
                "{name}: no summary read"
            );
            assert_eq!(mcap.topics().expect("topics"), expected_topics(&all), "{name}");
            let topic_list = mcap.topics().expect("topics");
            assert_eq!(topic_list[0].msg_type, "nav_msgs/Odometry");
            assert_eq!(topic_list.iter().map(|t| t.messages).sum::<u64>(), MESSAGES as u64);
            let messages: Vec<_> = mcap.messages(&[]).collect::<Result<_, _>>().expect("messages");
            assert_eq!(messages, all, "{name}");
            let tf = ["/tf".to_string()];
            let messages: Vec<_> = mcap.messages(&tf).collect::<Result<_, _>>().expect("messages");
            let want: Vec<_> = all.iter().filter(|m| m.topic == "/tf").cloned().collect();
            assert_eq!(messages, want, "{name}");
            assert!(mcap.messages(&["/nothing".to_string()]).next().is_none());
        }
    }

    #[test]
    fn topics_without_a_summary_come_from_a_scan() {
        let dir = tempfile::tempdir().expect("temp dir");
        let options = WriteOptions::new()
            .emit_summary_records(false)
            .emit_summary_offsets(false);
        let path = write(&dir, "bare.mcap", &recording(options));
        let mut file = File::open(&path).expect("file");
        assert!(summary_topics(&mut file, &path).expect("summary").is_none());
        let mcap = McapReader::open(&path).expect("open");
        assert_eq!(mcap.topics().expect("topics"), expected_topics(&expected()));
        assert_eq!(split(read(&path, &[])).0, expected());
    }

    #[test]
    fn damaged_summary_falls_back_to_a_scan() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut bytes = recording(WriteOptions::new());
        let statistics = top_records(&bytes)
            .into_iter()
            .find(|&(_, op)| op == op::STATISTICS)
            .expect("stats");
        bytes[statistics.0 + RECORD_PREFIX] ^= 0x40; // the message count
        let path = write(&dir, "summary.mcap", &bytes);
        let mut file = File::open(&path).expect("file");
        assert!(
            summary_topics(&mut file, &path).expect("summary").is_none(),
            "CRC mismatch unseen"
        );
        let mcap = McapReader::open(&path).expect("open");
        assert_eq!(mcap.topics().expect("topics"), expected_topics(&expected()));
        let (messages, errors) = split(read(&path, &[]));
        assert!(messages == expected() && errors.is_empty(), "{errors:?}");
    }

    #[test]
    fn killed_recorder_gives_every_complete_chunk() {
        let dir = tempfile::tempdir().expect("temp dir");
        for (name, options) in variants().into_iter().take(3) {
            let bytes = recording(options);
            let data_end = offsets_of(&bytes, op::DATA_END)[0];
            let last_chunk = *offsets_of(&bytes, op::CHUNK).last().expect("chunks");
            for (cut, kept) in [(data_end, MESSAGES), (last_chunk + 40, MESSAGES - PER_CHUNK)] {
                let path = write(&dir, &format!("{name}-{cut}.mcap"), &bytes[..cut]);
                let (messages, errors) = split(read(&path, &[]));
                assert_eq!(messages, expected()[..kept], "{name} cut at {cut}");
                assert_eq!(errors.len(), 1, "{name} cut at {cut}");
                let error = errors[0].to_string();
                assert!(
                    error.contains("truncated") && error.contains(&path.display().to_string()),
                    "{error}"
                );
                let topics = McapReader::open(&path).expect("open").topics().expect("topics");
                assert_eq!(topics, expected_topics(&expected()[..kept]), "{name} cut at {cut}");
            }
        }
    }

    #[test]
    fn truncation_anywhere_gives_a_prefix_then_one_error() {
        let dir = tempfile::tempdir().expect("temp dir");
        let all = expected();
        for (name, options) in variants() {
            let bytes = recording(options);
            let data_end = offsets_of(&bytes, op::DATA_END)[0] + RECORD_PREFIX + 4;
            let path = dir.path().join(format!("{name}.mcap"));
            let mut kept_before = 0;
            // Every offset of the start and around each record boundary,
            // every 11th elsewhere.
            let starts: Vec<_> = top_records(&bytes).into_iter().map(|(at, _)| at).collect();
            let near_start = |cut: usize| starts.iter().any(|&at| cut.abs_diff(at) <= 10);
            for cut in (0..bytes.len()).filter(|&cut| cut < 400 || cut % 11 == 0 || near_start(cut)) {
                replace(&path, &bytes[..cut]);
                let Ok(mcap) = McapReader::open(&path) else {
                    assert!(cut < MAGIC.len(), "{name}: open failed with {cut} bytes");
                    continue;
                };
                let (messages, errors) = split(mcap.messages(&[]).collect());
                assert_eq!(messages, all[..messages.len()], "{name} cut at {cut}");
                assert!(
                    messages.len() >= kept_before,
                    "{name} cut at {cut}: fewer messages than a shorter cut"
                );
                kept_before = messages.len();
                if cut < data_end {
                    assert_eq!(errors.len(), 1, "{name} cut at {cut}");
                    assert!(errors[0].to_string().contains("byte"), "{}", errors[0]);
                } else {
                    assert!(
                        errors.is_empty() && messages.len() == MESSAGES,
                        "{name} cut at {cut}: {errors:?}"
                    );
                }
                let counted: u64 = mcap.topics().expect("topics").iter().map(|t| t.messages).sum();
                assert!(
                    counted >= messages.len() as u64 && counted <= MESSAGES as u64,
                    "{name} cut at {cut}"
                );
            }
        }
    }

    /// A recording with a JSON, a ROS 1 and a schema-less CDR channel besides
    /// a ROS 2 one.
    fn mixed_recording() -> Vec<u8> {
        let mut writer = WriteOptions::new().create(Cursor::new(Vec::new())).expect("writer");
        let json = writer.add_schema("Chat", "jsonschema", b"{}").expect("schema");
        let tf = writer
            .add_schema("tf2_msgs/msg/TFMessage", "ros2msg", b"")
            .expect("schema");
        let ros1 = writer.add_schema("sensor_msgs/Imu", "ros1msg", b"").expect("schema");
        let none = BTreeMap::new();
        let channels = [
            writer.add_channel(tf, "/tf", "cdr", &none).expect("channel"),
            writer.add_channel(json, "/chat", "json", &none).expect("channel"),
            writer.add_channel(ros1, "/imu", "ros1", &none).expect("channel"),
            writer.add_channel(0, "/raw", "cdr", &none).expect("channel"),
        ];
        for (i, &channel_id) in channels.iter().cycle().take(8).enumerate() {
            let header = MessageHeader {
                channel_id,
                sequence: i as u32,
                log_time: i as u64,
                publish_time: 0,
            };
            writer.write_to_known_channel(&header, &[i as u8; 8]).expect("message");
        }
        writer.finish().expect("finish");
        writer.into_inner().into_inner()
    }

    #[test]
    fn other_encodings_are_refused_only_when_asked_for() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = write(&dir, "mixed.mcap", &mixed_recording());
        let topics = |names: &[&str]| names.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let (messages, errors) = split(read(&path, &topics(&["/tf", "/imu", "/raw"])));
        assert!(errors.is_empty(), "{errors:?}");
        let kinds: Vec<_> = messages
            .iter()
            .map(|m| (m.topic.as_str(), m.msg_type.as_str(), m.encoding))
            .collect();
        let round = [
            ("/tf", "tf2_msgs/TFMessage", Encoding::Cdr),
            ("/imu", "sensor_msgs/Imu", Encoding::Ros1),
            ("/raw", "", Encoding::Cdr),
        ];
        assert_eq!(kinds, [round, round].concat());
        for asked in [topics(&["/chat"]), vec![]] {
            let (messages, errors) = split(read(&path, &asked));
            assert_eq!(
                messages.len(),
                usize::from(asked.is_empty()),
                "the /tf message before the first /chat one"
            );
            assert_eq!(errors.len(), 1);
            let error = errors[0].to_string();
            assert!(error.contains("/chat") && error.contains("\"json\""), "{error}");
        }
        let listed = McapReader::open(&path).expect("open").topics().expect("topics");
        let listed: Vec<_> = listed
            .iter()
            .map(|t| (t.topic.as_str(), t.msg_type.as_str(), t.messages))
            .collect();
        let want = [
            ("/chat", "Chat", 2),
            ("/imu", "sensor_msgs/Imu", 2),
            ("/raw", "", 2),
            ("/tf", "tf2_msgs/TFMessage", 2),
        ];
        assert_eq!(listed, want);
    }

    #[test]
    fn garbage_is_not_an_mcap_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut rng = StdRng::seed_from_u64(7);
        let noise: Vec<u8> = (0..1000).map(|_| rng.random()).collect();
        for (name, bytes) in [("noise", &noise[..]), ("empty", &[][..]), ("short", &MAGIC[..5])] {
            let path = write(&dir, name, bytes);
            let error = McapReader::open(&path).expect_err(name).to_string();
            assert!(error.contains("not an MCAP file") && error.contains(name), "{error}");
        }
        let error = McapReader::open(&dir.path().join("missing.mcap")).expect_err("missing");
        assert!(matches!(error, IoError::Io { .. }), "{error}");
        let path = write(&dir, "magic-only.mcap", MAGIC);
        let mcap = McapReader::open(&path).expect("open");
        assert_eq!(mcap.topics().expect("topics"), vec![]);
        let (messages, errors) = split(mcap.messages(&[]).collect());
        assert!(messages.is_empty() && errors.len() == 1 && errors[0].to_string().contains("truncated"));
    }

    #[test]
    fn damaged_chunk_gives_no_message() {
        let dir = tempfile::tempdir().expect("temp dir");
        for (name, options) in variants().into_iter().take(3) {
            let mut bytes = recording(options);
            let third = offsets_of(&bytes, op::CHUNK)[2];
            let len = u64::from_le_bytes(bytes[third + 1..third + RECORD_PREFIX].try_into().expect("8 bytes"));
            bytes[third + RECORD_PREFIX + len as usize - 20] ^= 0x10;
            let path = write(&dir, &format!("{name}.mcap"), &bytes);
            let (messages, errors) = split(read(&path, &[]));
            assert_eq!(messages, expected()[..2 * PER_CHUNK], "{name}");
            assert_eq!(errors.len(), 1, "{name}");
            let error = errors[0].to_string();
            assert!(error.contains(&format!("the chunk at byte {third}")), "{name}: {error}");
        }
    }

    #[test]
    fn unknown_compression_is_named() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut bytes = recording(WriteOptions::new().compression(Some(Compression::Zstd)));
        let second = offsets_of(&bytes, op::CHUNK)[1];
        let at = second
            + bytes[second..]
                .windows(4)
                .position(|w| w == b"zstd")
                .expect("compression");
        bytes[at..at + 4].copy_from_slice(b"brot");
        let path = write(&dir, "brot.mcap", &bytes);
        let (messages, errors) = split(read(&path, &[]));
        assert_eq!(messages, expected()[..PER_CHUNK]);
        assert!(
            errors.len() == 1 && errors[0].to_string().contains("\"brot\""),
            "{errors:?}"
        );
    }

    #[test]
    fn mutated_files_never_panic() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut originals: Vec<Vec<u8>> = variants().into_iter().map(|(_, options)| recording(options)).collect();
        originals.push(mixed_recording());
        // Without chunk CRCs, damage inside a chunk reaches the record walk.
        for compression in [None, Some(Compression::Lz4), Some(Compression::Zstd)] {
            originals.push(recording(
                WriteOptions::new().compression(compression).calculate_chunk_crcs(false),
            ));
        }
        let cases: usize = std::env::var("MCAP_FUZZ_CASES")
            .ok()
            .and_then(|n| n.parse().ok())
            .unwrap_or(2000);
        let mut outcomes = [0usize; 5];
        let path = dir.path().join("mutant.mcap");
        let mut rng = StdRng::seed_from_u64(2024);
        for case in 0..cases {
            let mut bytes = originals[case % originals.len()].clone();
            for _ in 0..rng.random_range(1..=4) {
                let at = rng.random_range(0..bytes.len());
                match rng.random_range(0..4) {
                    0 => bytes[at] ^= 1 << rng.random_range(0..8),
                    1 => bytes[at] = rng.random(),
                    2 => bytes
                        .splice(at..at, (0..rng.random_range(1..16)).map(|_| rng.random::<u8>()))
                        .for_each(drop),
                    _ => bytes.truncate(at.max(1)),
                }
            }
            replace(&path, &bytes);
            let Ok(mcap) = McapReader::open(&path) else {
                outcomes[0] += 1;
                continue;
            };
            let _ = mcap.topics();
            let (messages, errors) = split(mcap.messages(&[]).collect());
            assert!(
                errors.len() <= 1,
                "case {case}: {} messages, errors {errors:?}",
                messages.len()
            );
            outcomes[1 + 2 * usize::from(!errors.is_empty()) + usize::from(messages.is_empty())] += 1;
        }
        eprintln!("not opened; no damage seen: messages, none; damage: after messages, before any: {outcomes:?}");
    }
}
