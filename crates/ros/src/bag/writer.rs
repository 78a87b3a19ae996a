//! Writing bags: uncompressed chunks laid out as `rosbag record` lays them.

use std::collections::BTreeMap;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::format::{op, put_u32, record, time_bytes, BAG_HEADER_BYTES, MAGIC, MAX_CHUNK_BYTES};
use edtmap_io::files::AtomicFile;
use edtmap_io::IoError;

/// Chunk size at which a chunk is closed, as `rosbag record` defaults to.
pub const DEFAULT_CHUNK_BYTES: u32 = 768 * 1024;

/// Writes uncompressed ROS 1 bags (format 2.0), used by the tests and to
/// export recordings.
///
/// Records go to the file as they come, inside a chunk whose header is
/// patched when the chunk closes; [`BagWriter::finish`] then writes the
/// index. A writer dropped without `finish` leaves the bag as a recorder
/// killed mid-run does: header `index_pos` 0 and a last chunk whose header
/// still says 0 bytes.
#[derive(Debug)]
pub struct BagWriter {
    path: PathBuf,
    file: AtomicFile,
    /// Bytes written so far: the offset of the next record.
    pos: u64,
    /// By connection id.
    conns: Vec<Connection>,
    chunk: Option<OpenChunk>,
    /// Closed chunks.
    chunk_infos: Vec<ChunkInfo>,
    /// Chunk size in bytes at which a chunk is closed.
    chunk_bytes: u32,
}

#[derive(Debug)]
struct Connection {
    /// The whole connection record, written in the first chunk that uses it
    /// and again in the index.
    record: Vec<u8>,
    /// Whether a chunk holds the record yet.
    written: bool,
}

#[derive(Debug)]
struct OpenChunk {
    /// Offset of the chunk record, to patch its header.
    at: u64,
    /// Offset of its data.
    data_at: u64,
    /// Earliest and latest message times, nanoseconds.
    start_ns: u64,
    end_ns: u64,
    /// Connection id → its messages' (time, offset in the chunk data).
    index: BTreeMap<u32, Vec<([u8; 8], u32)>>,
}

#[derive(Debug)]
struct ChunkInfo {
    at: u64,
    start_ns: u64,
    end_ns: u64,
    /// Connection id → messages in the chunk.
    counts: BTreeMap<u32, u32>,
}

impl BagWriter {
    /// Starts the bag at `path` and writes its header. The bag replaces
    /// any file at `path` only when [`Self::finish`] succeeds.
    pub fn create(path: &Path) -> Result<Self, IoError> {
        let file = AtomicFile::create(path)?;
        let mut writer = BagWriter {
            path: path.to_path_buf(),
            file,
            pos: 0,
            conns: Vec::new(),
            chunk: None,
            chunk_infos: Vec::new(),
            chunk_bytes: DEFAULT_CHUNK_BYTES,
        };
        writer.put(MAGIC)?;
        writer.put(&bag_header(0, 0, 0))?;
        Ok(writer)
    }

    /// Closes chunks once they hold `bytes` bytes instead of the default
    /// [`DEFAULT_CHUNK_BYTES`].
    pub fn with_chunk_bytes(mut self, bytes: u32) -> Self {
        self.chunk_bytes = bytes.min(MAX_CHUNK_BYTES / 2);
        self
    }

    /// Registers a topic; `definition` is the message definition text (may
    /// be empty), md5sum the type's md5 ("*" allowed). Returns the
    /// connection id.
    pub fn add_connection(
        &mut self,
        topic: &str,
        msg_type: &str,
        md5sum: &str,
        definition: &str,
    ) -> Result<u32, IoError> {
        let id = self.conns.len() as u32;
        let mut header = Vec::new();
        for (name, value) in [
            ("topic", topic),
            ("type", msg_type),
            ("md5sum", md5sum),
            ("message_definition", definition),
            ("callerid", "/edtmap"),
        ] {
            super::format::put_field(&mut header, name, value.as_bytes());
        }
        if header.len() > (MAX_CHUNK_BYTES / 2) as usize {
            return Err(self.bad_data(format!("the definition of {msg_type} is too long ({} bytes)", definition.len())));
        }
        let fields: [(&str, &[u8]); 3] =
            [("op", &[op::CONNECTION]), ("conn", &id.to_le_bytes()), ("topic", topic.as_bytes())];
        self.conns.push(Connection { record: record(&fields, &header), written: false });
        Ok(id)
    }

    /// Writes a message on connection `conn` logged at `time_ns`
    /// (nanoseconds since the epoch); `data` is the serialized message.
    pub fn write(&mut self, conn: u32, time_ns: u64, data: &[u8]) -> Result<(), IoError> {
        let Some(connection) = self.conns.get(conn as usize) else {
            return Err(self.bad_data(format!("no connection {conn} was added")));
        };
        let Some(time) = time_bytes(time_ns) else {
            return Err(self.bad_data(format!("time {time_ns} ns is past what a ROS time holds (year 2106)")));
        };
        if data.len() > (MAX_CHUNK_BYTES / 2) as usize {
            return Err(self.bad_data(format!("a message of {} bytes is too long for a chunk", data.len())));
        }
        let conn_record = (!connection.written).then(|| connection.record.clone());
        if self.chunk.is_none() {
            self.open_chunk(time_ns)?;
        }
        if let Some(conn_record) = conn_record {
            self.put(&conn_record)?;
            self.conns[conn as usize].written = true;
        }
        let chunk = self.chunk.as_mut().expect("opened above");
        let offset = (self.pos - chunk.data_at) as u32;
        chunk.index.entry(conn).or_default().push((time, offset));
        chunk.start_ns = chunk.start_ns.min(time_ns);
        chunk.end_ns = chunk.end_ns.max(time_ns);
        let fields: [(&str, &[u8]); 3] = [("op", &[op::MESSAGE_DATA]), ("conn", &conn.to_le_bytes()), ("time", &time)];
        self.put(&record(&fields, data))?;
        if self.pos - self.chunk.as_ref().map_or(0, |c| c.data_at) >= u64::from(self.chunk_bytes) {
            self.close_chunk()?;
        }
        Ok(())
    }

    /// Writes index data, connections and chunk infos, patches the header's
    /// index_pos, and puts the bag in place. Dropped without it, the bag
    /// is not written at all.
    pub fn finish(mut self) -> Result<(), IoError> {
        self.close_chunk()?;
        let index_pos = self.pos;
        let mut index: Vec<u8> = self.conns.iter().flat_map(|c| c.record.iter().copied()).collect();
        for info in &self.chunk_infos {
            let mut data = Vec::new();
            for (&conn, &count) in &info.counts {
                put_u32(&mut data, conn);
                put_u32(&mut data, count);
            }
            let (start, end) =
                (time_bytes(info.start_ns).unwrap_or_default(), time_bytes(info.end_ns).unwrap_or_default());
            let fields: [(&str, &[u8]); 6] = [
                ("op", &[op::CHUNK_INFO]),
                ("ver", &1u32.to_le_bytes()),
                ("chunk_pos", &info.at.to_le_bytes()),
                ("start_time", &start),
                ("end_time", &end),
                ("count", &(info.counts.len() as u32).to_le_bytes()),
            ];
            index.extend(record(&fields, &data));
        }
        self.put(&index)?;
        let header = bag_header(index_pos, self.conns.len() as u32, self.chunk_infos.len() as u32);
        self.patch(MAGIC.len() as u64, &header)?;
        self.file.commit()
    }

    /// Puts the bag in place as a recorder killed mid-run leaves it: the
    /// chunks written so far, no index, header index_pos 0. For tests of
    /// the reader's recovery.
    pub fn finish_unindexed(self) -> Result<(), IoError> {
        self.file.commit()
    }

    /// Starts a chunk: its header with sizes 0 until it closes.
    fn open_chunk(&mut self, time_ns: u64) -> Result<(), IoError> {
        let at = self.pos;
        self.put(&chunk_header(0))?;
        let (start_ns, end_ns, index) = (time_ns, time_ns, BTreeMap::new());
        self.chunk = Some(OpenChunk { at, data_at: self.pos, start_ns, end_ns, index });
        Ok(())
    }

    /// Patches the open chunk's sizes and writes its index data records.
    fn close_chunk(&mut self) -> Result<(), IoError> {
        let Some(chunk) = self.chunk.take() else { return Ok(()) };
        let size = (self.pos - chunk.data_at) as u32;
        self.patch(chunk.at, &chunk_header(size))?;
        let mut counts = BTreeMap::new();
        for (&conn, entries) in &chunk.index {
            let mut data = Vec::with_capacity(entries.len() * 12);
            for (time, offset) in entries {
                data.extend_from_slice(time);
                put_u32(&mut data, *offset);
            }
            let count = entries.len() as u32;
            let fields: [(&str, &[u8]); 4] = [
                ("op", &[op::INDEX_DATA]),
                ("ver", &1u32.to_le_bytes()),
                ("conn", &conn.to_le_bytes()),
                ("count", &count.to_le_bytes()),
            ];
            self.put(&record(&fields, &data))?;
            counts.insert(conn, count);
        }
        self.chunk_infos.push(ChunkInfo { at: chunk.at, start_ns: chunk.start_ns, end_ns: chunk.end_ns, counts });
        Ok(())
    }

    /// Appends `bytes`.
    fn put(&mut self, bytes: &[u8]) -> Result<(), IoError> {
        self.file.write_all(bytes).map_err(|e| IoError::io(&self.path, e))?;
        self.pos += bytes.len() as u64;
        Ok(())
    }

    /// Overwrites the bytes at `at` with `bytes` and comes back to the end.
    fn patch(&mut self, at: u64, bytes: &[u8]) -> Result<(), IoError> {
        let io = |e| IoError::io(&self.path, e);
        self.file.seek(SeekFrom::Start(at)).map_err(io)?;
        self.file.write_all(bytes).map_err(io)?;
        self.file.seek(SeekFrom::Start(self.pos)).map_err(io)?;
        Ok(())
    }

    fn bad_data(&self, reason: String) -> IoError {
        IoError::BadData { path: self.path.clone(), reason }
    }
}

/// The bag header record, padded with spaces to [`BAG_HEADER_BYTES`].
pub(super) fn bag_header(index_pos: u64, conn_count: u32, chunk_count: u32) -> Vec<u8> {
    let fields: [(&str, &[u8]); 4] = [
        ("index_pos", &index_pos.to_le_bytes()),
        ("conn_count", &conn_count.to_le_bytes()),
        ("chunk_count", &chunk_count.to_le_bytes()),
        ("op", &[op::BAG_HEADER]),
    ];
    let header_len = record(&fields, &[]).len() - 8;
    record(&fields, &vec![b' '; BAG_HEADER_BYTES - header_len])
}

/// An uncompressed chunk's header and data length, `size` bytes.
fn chunk_header(size: u32) -> Vec<u8> {
    let fields: [(&str, &[u8]); 3] = [("op", &[op::CHUNK]), ("compression", b"none"), ("size", &size.to_le_bytes())];
    let mut out = record(&fields, &[]);
    out.truncate(out.len() - 4);
    put_u32(&mut out, size);
    out
}
