//! Opening a bag, its topics, and the file access the message iterator
//! shares.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use super::format::{le_u32, op, split_record, Damage, Fields, MAGIC, MAX_HEADER_BYTES};
use super::messages::Messages;
use crate::{normalize_type, RawMessage, TopicInfo};
use edtmap_io::IoError;

/// A ROS 1 bag (format 2.0) opened for reading.
///
/// The chunk section is read record after record, so a bag that was never
/// closed (a recorder killed mid-run, header `index_pos` 0) or that was cut
/// short still gives every message before the damage. Uncompressed chunks
/// are parsed here; `bz2` and `lz4` chunks are decoded by the `rosbag`
/// crate, which can do so only in a bag whose header points at its index.
#[derive(Debug, Clone)]
pub struct BagReader {
    path: PathBuf,
    /// File length in bytes when opened.
    pub(super) file_len: u64,
    /// Offset of the first record after the bag header record.
    pub(super) chunks_at: u64,
    /// The header's `index_pos`: 0 in a bag never closed.
    pub(super) index_pos: u64,
    conn_count: Option<u32>,
    chunk_count: Option<u32>,
}

impl BagReader {
    /// Opens a bag: checks the `#ROSBAG V2.0` magic and bag header record.
    pub fn open(path: &Path) -> Result<Self, IoError> {
        let mut src = Source::open(path)?;
        let not_bag = |reason: &str| IoError::Dataset { path: path.to_path_buf(), reason: reason.to_string() };
        if src.len < MAGIC.len() as u64 + 8 {
            return Err(not_bag("not a ROS bag: too short for the `#ROSBAG V2.0` magic and header"));
        }
        let magic = src.read_at(0, MAGIC.len())?;
        if magic != MAGIC {
            return Err(not_bag(if magic.starts_with(b"#ROSBAG V") {
                "a ROS bag of a format other than 2.0, which is the only one read"
            } else {
                "not a ROS bag: it does not start with `#ROSBAG V2.0`"
            }));
        }
        let head = src.read_head(MAGIC.len() as u64)?;
        let end = head.data_at + u64::from(head.data_len);
        if end > src.len {
            return Err(src.damage(Damage::new(head.at, "truncated: the bag header record is cut short")));
        }
        let header = (|| {
            let fields = Fields::parse(&head.header)?;
            if fields.op()? != op::BAG_HEADER {
                return Err("the first record is not a bag header (op 0x03)".to_string());
            }
            let count = |name| if fields.has(name) { fields.u32(name).map(Some) } else { Ok(None) };
            Ok((fields.u64("index_pos")?, count("conn_count")?, count("chunk_count")?))
        })();
        let (index_pos, conn_count, chunk_count) =
            header.map_err(|r| src.damage(Damage::new(head.at, format!("bad bag header record: {r}"))))?;
        Ok(BagReader {
            path: path.to_path_buf(),
            file_len: src.len,
            chunks_at: end,
            index_pos,
            conn_count,
            chunk_count,
        })
    }

    /// The bag's topics with types and message counts: from the index when
    /// the bag was closed properly, else by scanning the chunks (a truncated
    /// bag still lists what it holds before the damage). Sorted by topic.
    pub fn topics(&self) -> Result<Vec<TopicInfo>, IoError> {
        let mut counts = BTreeMap::<(String, String), u64>::new();
        if let Some(index) = self.usable_index()? {
            for (id, (topic, msg_type)) in &index.conns {
                *counts.entry((topic.clone(), msg_type.clone())).or_default() +=
                    index.counts.get(id).copied().unwrap_or(0);
            }
        } else {
            let mut scan = Messages::new(self, &[]);
            for message in &mut scan {
                match message {
                    Ok(m) => *counts.entry((m.topic, m.msg_type)).or_default() += 1,
                    Err(e @ IoError::Io { .. }) => return Err(e),
                    Err(_) => break,
                }
            }
            for (topic, msg_type) in scan.connections() {
                counts.entry((topic.to_string(), msg_type.to_string())).or_default();
            }
        }
        let topics = counts.into_iter().map(|((topic, msg_type), messages)| TopicInfo { topic, msg_type, messages });
        Ok(topics.collect())
    }

    /// Messages on `topics` (all topics when empty) in file order (chunk
    /// after chunk, messages in a chunk in stored order).
    ///
    /// The iterator yields `Ok` messages until damage (truncation, a bad
    /// record, an unknown compression, an undefined connection id, ...),
    /// then one `Err` naming the file, the byte offset and what is wrong,
    /// then `None`. A bag never closed that ends on a record boundary ends
    /// without an error (nothing tells it from a recorder stopped between
    /// two writes); a closed bag cut anywhere before its index ends with
    /// one. The index section is not read for messages, so damage there
    /// does not stop them.
    pub fn messages<'a>(&'a self, topics: &'a [String]) -> Box<dyn Iterator<Item = Result<RawMessage, IoError>> + 'a> {
        Box::new(Messages::new(self, topics))
    }

    /// The file.
    pub(super) fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the header's `index_pos` points at an index inside the file.
    pub(super) fn has_index(&self) -> bool {
        self.index_pos != 0 && (self.chunks_at..=self.file_len).contains(&self.index_pos)
    }

    /// The index, if the bag has one that is whole and agrees with the
    /// header's counts.
    fn usable_index(&self) -> Result<Option<Index>, IoError> {
        if !self.has_index() {
            return Ok(None);
        }
        let mut src = Source::open(&self.path)?;
        let (index, damage) = read_index(&mut src, self.index_pos)?;
        let agrees = damage.is_none()
            && self.chunk_count.is_none_or(|n| n == index.chunk_infos)
            && self.conn_count.is_none_or(|n| n as usize == index.conns.len())
            && index.counts.keys().all(|id| index.conns.contains_key(id));
        if !agrees {
            tracing::debug!("{}: the index is damaged; scanning the chunks for the topics", self.path.display());
        }
        Ok(agrees.then_some(index))
    }
}

/// Longest index section read; a real one holds the connections and about
/// 100 bytes per chunk.
const MAX_INDEX_BYTES: u64 = 1 << 28;

/// What the index section says.
#[derive(Default)]
pub(super) struct Index {
    /// Connection id → (topic, type normalized).
    pub(super) conns: HashMap<u32, (String, String)>,
    /// Connection id → messages, summed over the chunk infos.
    counts: HashMap<u32, u64>,
    /// Chunk info records.
    chunk_infos: u32,
}

/// The index section from `index_pos` to the end of the file: what could
/// be read, and the damage that stopped the reading, if any.
pub(super) fn read_index(src: &mut Source, index_pos: u64) -> Result<(Index, Option<Damage>), IoError> {
    let mut index = Index::default();
    let len = src.len - index_pos;
    if len > MAX_INDEX_BYTES {
        return Ok((index, Some(Damage::new(index_pos, format!("an index section of {len} bytes is not plausible")))));
    }
    let bytes = src.read_at(index_pos, len as usize)?;
    let mut at = 0;
    while at < bytes.len() {
        let offset = index_pos + at as u64;
        let parsed = split_record(&bytes, at).and_then(|(record, next)| {
            let fields = Fields::parse(record.header)?;
            match fields.op()? {
                op::CONNECTION => {
                    let (id, topic, msg_type) = connection(&fields, record.data)?;
                    index.conns.entry(id).or_insert((topic, msg_type));
                }
                op::CHUNK_INFO => {
                    chunk_info(&fields, record.data, &mut index.counts)?;
                    index.chunk_infos += 1;
                }
                op::INDEX_DATA => {}
                other => return Err(format!("unexpected record (op {other:#04x}) in the index section")),
            }
            Ok(next)
        });
        match parsed {
            Ok(next) => at = next,
            Err(reason) => return Ok((index, Some(Damage::new(offset, reason)))),
        }
    }
    Ok((index, None))
}

/// A connection record's id, topic and type (normalized).
pub(super) fn connection(fields: &Fields<'_>, data: &[u8]) -> Result<(u32, String, String), String> {
    let id = fields.u32("conn")?;
    let topic = fields.str("topic")?.to_string();
    let msg_type = Fields::parse(data).and_then(|f| f.str("type").map(normalize_type));
    Ok((id, topic, msg_type.map_err(|r| format!("bad connection header: {r}"))?))
}

/// Adds a chunk info record's per-connection message counts to `counts`.
fn chunk_info(fields: &Fields<'_>, data: &[u8], counts: &mut HashMap<u32, u64>) -> Result<(), String> {
    let ver = fields.u32("ver")?;
    if ver != 1 {
        return Err(format!("chunk info version {ver} (only 1 is known)"));
    }
    let n = fields.u32("count")? as usize;
    if data.len() != n.saturating_mul(8) {
        return Err(format!("chunk info of {n} connections holds {} bytes", data.len()));
    }
    for entry in data.chunks_exact(8) {
        let (conn, count) = (le_u32(entry, 0), le_u32(entry, 4));
        *counts.entry(conn.unwrap_or_default()).or_default() += u64::from(count.unwrap_or_default());
    }
    Ok(())
}

/// A record's header as read from the file; the data is left in place.
pub(super) struct Head {
    /// Offset of the record.
    pub(super) at: u64,
    /// The header's bytes.
    pub(super) header: Vec<u8>,
    /// Offset of the data.
    pub(super) data_at: u64,
    /// Data length the record declares.
    pub(super) data_len: u32,
}

/// A bag file read at offsets, with errors that name it.
pub(super) struct Source {
    path: PathBuf,
    file: BufReader<File>,
    /// File length when opened.
    pub(super) len: u64,
    /// The reader's offset.
    pos: u64,
}

impl Source {
    pub(super) fn open(path: &Path) -> Result<Self, IoError> {
        // Streamed, so no size cap: the check is that it is a regular file.
        let (file, len) = edtmap_io::files::open_input(path, u64::MAX)?;
        Ok(Source { path: path.to_path_buf(), file: BufReader::with_capacity(1 << 16, file), len, pos: 0 })
    }

    /// The error for `damage` in this file.
    pub(super) fn damage(&self, damage: Damage) -> IoError {
        let reason = format!("byte {}: {}", damage.offset, damage.reason);
        IoError::Dataset { path: self.path.clone(), reason }
    }

    /// `n` bytes at `at`; the caller has checked they lie in the file.
    pub(super) fn read_at(&mut self, at: u64, n: usize) -> Result<Vec<u8>, IoError> {
        let io = |e| IoError::io(&self.path, e);
        if at != self.pos {
            self.file.seek_relative(at.wrapping_sub(self.pos) as i64).map_err(io)?;
        }
        let mut bytes = vec![0; n];
        self.file.read_exact(&mut bytes).map_err(|e| IoError::io(&self.path, e))?;
        self.pos = at + n as u64;
        Ok(bytes)
    }

    /// The header of the record at `at` and its data length; the data
    /// itself may lie past the end of the file.
    pub(super) fn read_head(&mut self, at: u64) -> Result<Head, IoError> {
        let cut = |what| Damage::new(at, format!("truncated: the file ends inside {what}"));
        if at + 4 > self.len {
            return Err(self.damage(cut("a record's header length")));
        }
        let header_len = le_u32(&self.read_at(at, 4)?, 0).unwrap_or_default();
        if header_len > MAX_HEADER_BYTES {
            return Err(self.damage(Damage::new(at, format!("a record header of {header_len} bytes is not plausible"))));
        }
        let data_at = at + 8 + u64::from(header_len);
        if data_at > self.len {
            return Err(self.damage(cut("a record header")));
        }
        let mut bytes = self.read_at(at + 4, header_len as usize + 4)?;
        let data_len = le_u32(&bytes, header_len as usize).unwrap_or_default();
        bytes.truncate(header_len as usize);
        Ok(Head { at, header: bytes, data_at, data_len })
    }
}
