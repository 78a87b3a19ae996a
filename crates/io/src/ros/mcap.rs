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
        let counts = scan.decoder.channels.into_values().map(|c| (c.topic, c.msg_type, c.messages));
        Ok(topic_list(counts))
    }

    /// Messages on `topics` (all when empty) in file order. Yields `Ok`
    /// messages until damage (truncation, bad CRC, bad chunk, unknown
    /// compression...) or a message of an asked-for topic in an encoding
    /// other than `cdr` or `ros1`, then one `Err` naming the file, the byte
    /// offset and what is wrong, then `None`. Never panics on any bytes.
    pub fn messages<'a>(
        &'a self,
        topics: &'a [String],
    ) -> Box<dyn Iterator<Item = Result<RawMessage, IoError>> + 'a> {
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
            tracing::debug!("{}: the summary CRC does not match; scanning for the topics", path.display());
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
        (c.topic, schemas.get(&c.schema_id).cloned().unwrap_or_default(), messages)
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
                self.schemas.entry(header.id).or_insert_with(|| normalize_type(&header.name));
            }
            Record::Channel(c) => {
                let wanted = self.topics.is_some_and(|t| t.is_empty() || t.contains(&c.topic));
                let msg_type = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                let channel =
                    Channel { topic: c.topic, msg_type, message_encoding: c.message_encoding, wanted, messages: 0 };
                self.channels.entry(c.id).or_insert(channel);
            }
            Record::Message { header, data } => self.message(&header, &data)?,
            _ => {}
        }
        Ok(())
    }

    fn message(&mut self, header: &MessageHeader, data: &[u8]) -> Result<(), String> {
        let Some(channel) = self.channels.get_mut(&header.channel_id) else {
            return Err(format!("a message on channel {} that no channel record defines", header.channel_id));
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
            self.record(opcode, body).map_err(|e| format!("record at byte {at} of the chunk's records: {e}"))?;
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
                    let got = source.read(reader.insert(n.min(READ_BYTES))).map_err(|e| e.to_string())?;
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
        let decoder = Decoder { topics, schemas: HashMap::new(), channels: BTreeMap::new(), ready: VecDeque::new() };
        Ok(Self { path, file, file_len, reader, at: MAGIC.len() as u64, decoder, error: None, done: false })
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
            op::CHUNK => self.decoder.chunk(body).map_err(|e| format!("the chunk at byte {at}: {e}")),
            _ => self.decoder.record(opcode, body).map_err(|e| format!("the record at byte {at}: {e}")),
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
