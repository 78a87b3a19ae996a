//! The data section read record after record: schemas, channels, messages
//! and chunks, the chunks checked and opened here.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::path::Path;

use ::mcap::records::{op, ChunkHeader, MessageHeader, Record};
use ::mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use ::mcap::{parse_record, McapError, MAGIC};

use super::{dataset, split_records, RECORD_PREFIX};
use crate::{normalize_type, Encoding, RawMessage};
use edtmap_io::IoError;

/// Largest decompressed chunk read, bytes: a chunk that claims more is
/// taken for damage rather than allocated.
const MAX_CHUNK_BYTES: u64 = 1 << 30;
/// Bytes read from the file at a time.
const READ_BYTES: usize = 1 << 20;

/// A channel as the data section defines it.
pub(super) struct Channel {
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
pub(super) struct Decoder<'a> {
    /// Topics whose messages are handed out (all when empty); `None` only
    /// counts them.
    topics: Option<&'a [String]>,
    /// Schema ID → normalized name.
    schemas: HashMap<u16, String>,
    channels: BTreeMap<u16, Channel>,
    ready: VecDeque<RawMessage>,
    /// The zstd context, made at the first zstd chunk and kept.
    zstd: Option<zstd::bulk::Decompressor<'static>>,
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
        match header.compression.as_str() {
            "" => self.records(&header, &data),
            "zstd" => {
                let records = self.unzstd(&header, &data)?;
                self.records(&header, &records)
            }
            _ => self.compressed_chunk(&header, body),
        }
    }

    /// A zstd chunk's records, decoded in one call straight into a buffer
    /// of the chunk's stated size: no streaming window beside it.
    fn unzstd(&mut self, header: &ChunkHeader, data: &[u8]) -> Result<Vec<u8>, String> {
        let size = header.uncompressed_size as usize;
        let mut out = Vec::new();
        out.try_reserve_exact(size).map_err(|_| format!("cannot allocate the chunk's {size} bytes uncompressed"))?;
        let zstd = match &mut self.zstd {
            Some(z) => z,
            None => self.zstd.insert(zstd::bulk::Decompressor::new().map_err(|e| format!("zstd: {e}"))?),
        };
        zstd.decompress_to_buffer(data, &mut out).map_err(|e| format!("zstd data do not decode ({e})"))?;
        Ok(out)
    }

    /// Takes the records of a chunk's uncompressed bytes, after checking
    /// their size and CRC.
    fn records(&mut self, header: &ChunkHeader, data: &[u8]) -> Result<(), String> {
        if data.len() as u64 != header.uncompressed_size {
            return Err(format!(
                "the chunk holds {} bytes uncompressed but claims {}",
                data.len(),
                header.uncompressed_size
            ));
        }
        if header.uncompressed_crc != 0 && crc32fast::hash(data) != header.uncompressed_crc {
            return Err(format!("chunk CRC mismatch (expected {:08X})", header.uncompressed_crc));
        }
        for record in split_records(data) {
            let (at, opcode, body) = record?;
            self.record(opcode, body).map_err(|e| format!("record at byte {at} of the chunk's records: {e}"))?;
        }
        Ok(())
    }

    /// Decompresses a chunk (lz4) with a `LinearReader` fed the chunk record alone
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

/// Every channel's topic, message type and message count, counted with a
/// read of the data section up to its end or its first damage.
pub(super) fn scan(path: &Path) -> Result<Vec<(String, String, u64)>, IoError> {
    let mut scan = Stream::new(path, None)?;
    for item in scan.by_ref() {
        if let Err(e) = item {
            tracing::debug!("{e}; listing the topics before the damage");
        }
    }
    Ok(scan.decoder.channels.into_values().map(|c| (c.topic, c.msg_type, c.messages)).collect())
}

/// The data section's messages, record after record, from a file read a
/// piece at a time.
pub(super) struct Stream<'a> {
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
    pub(super) fn new(path: &'a Path, topics: Option<&'a [String]>) -> Result<Self, IoError> {
        // Streamed, so no size cap: the check is that it is a regular file.
        let (file, file_len) = edtmap_io::files::open_input(path, u64::MAX)?;
        let limit = usize::try_from(file_len).unwrap_or(usize::MAX);
        let reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_emit_chunks(true)
                .with_validate_data_section_crc(true)
                .with_record_length_limit(limit),
        );
        let decoder =
            Decoder { topics, schemas: HashMap::new(), channels: BTreeMap::new(), ready: VecDeque::new(), zstd: None };
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
