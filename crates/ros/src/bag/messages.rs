//! The message iterator: the chunk section read record after record.

use std::collections::{HashMap, VecDeque};

use rosbag::{ChunkRecord, MessageRecord, RosBag};

use super::format::{op, split_record, Damage, Fields, MAX_CHUNK_BYTES};
use super::reader::{connection, read_index, BagReader, Head, Source};
use crate::{normalize_type, Encoding, RawMessage};
use edtmap_io::IoError;

/// A record found in a chunk (or, in a bag never closed, after the
/// placeholder header of its last chunk).
enum Entry {
    /// Connection id → topic and type.
    Connection { id: u32, topic: String, msg_type: String },
    /// A message and the offset of its record (of its chunk when compressed).
    Message { at: u64, conn: u32, time_ns: u64, data: Vec<u8> },
}

/// Messages of a bag in file order; see [`BagReader::messages`].
pub(super) struct Messages<'a> {
    bag: &'a BagReader,
    topics: &'a [String],
    /// The file, opened on the first call to `next`.
    src: Option<Source>,
    /// Offset of the next record of the chunk section.
    at: u64,
    /// Connection id → (topic, type), from whichever record came first.
    conns: HashMap<u32, (String, String)>,
    /// Records of the chunk being read, then the damage that ended it.
    pending: VecDeque<Entry>,
    pending_damage: Option<Damage>,
    /// For compressed chunks, opened when the first one is met.
    rosbag: Option<RosBag>,
    done: bool,
}

impl<'a> Messages<'a> {
    pub(super) fn new(bag: &'a BagReader, topics: &'a [String]) -> Self {
        let (pending, pending_damage, rosbag) = (VecDeque::new(), None, None);
        let conns = HashMap::new();
        Messages { bag, topics, src: None, at: bag.chunks_at, conns, pending, pending_damage, rosbag, done: false }
    }

    /// The connections met so far, as (topic, type).
    pub(super) fn connections(&self) -> impl Iterator<Item = (&str, &str)> {
        self.conns.values().map(|(topic, msg_type)| (topic.as_str(), msg_type.as_str()))
    }

    /// Opens the file and takes the connections the index defines, so a
    /// bag that keeps them only there still reads.
    fn start(&mut self) -> Result<(), IoError> {
        let mut src = Source::open(self.bag.path())?;
        if self.bag.has_index() {
            let (index, _damage) = read_index(&mut src, self.bag.index_pos)?;
            self.conns = index.conns;
        }
        self.src = Some(src);
        Ok(())
    }

    /// The next message or damage from `pending`, skipping other topics.
    fn next_pending(&mut self) -> Option<Result<RawMessage, Damage>> {
        while let Some(entry) = self.pending.pop_front() {
            match entry {
                Entry::Connection { id, topic, msg_type } => {
                    self.conns.entry(id).or_insert((topic, msg_type));
                }
                Entry::Message { at, conn, time_ns, data } => {
                    let Some((topic, msg_type)) = self.conns.get(&conn) else {
                        let reason = format!("a message on connection {conn}, which no connection record defines");
                        return Some(Err(Damage::new(at, reason)));
                    };
                    if self.topics.is_empty() || self.topics.contains(topic) {
                        let (topic, msg_type) = (topic.clone(), msg_type.clone());
                        return Some(Ok(RawMessage {
                            topic,
                            msg_type,
                            log_time_ns: time_ns,
                            data,
                            encoding: Encoding::Ros1,
                        }));
                    }
                }
            }
        }
        self.pending_damage.take().map(Err)
    }

    /// Reads the next record of the chunk section into `pending`; `false`
    /// at the end of the section.
    fn advance(&mut self) -> Result<bool, IoError> {
        let bag = self.bag;
        if self.src.is_none() {
            self.start()?;
        }
        let src = self.src.as_mut().expect("opened above");
        let end = if bag.has_index() { bag.index_pos } else { src.len };
        if self.at >= end {
            if bag.index_pos > src.len {
                let reason =
                    format!("truncated: the file ends before the index the header places at byte {}", bag.index_pos);
                return Err(src.damage(Damage::new(src.len, reason)));
            }
            return Ok(false);
        }
        let head = src.read_head(self.at)?;
        let next = head.data_at + u64::from(head.data_len);
        let fields = Fields::parse(&head.header);
        let op = fields.as_ref().map_err(Clone::clone).and_then(|f| f.op());
        let op = op.map_err(|r| src.damage(Damage::new(head.at, format!("bad record header: {r}"))))?;
        let past_end = (next > end).then(|| {
            let reason = if next > src.len {
                format!("truncated: the record needs {} bytes, the file ends at byte {}", next - head.at, src.len)
            } else {
                format!("the record runs into the index at byte {end}")
            };
            Damage::new(head.at, reason)
        });
        match op {
            op::CHUNK => {
                let fields = fields.map_err(|r| src.damage(Damage::new(head.at, r)))?;
                self.read_chunk(&head, &fields, end, past_end)?;
            }
            op::INDEX_DATA if past_end.is_none() => {}
            // A recorder killed mid-chunk leaves the chunk's header with
            // sizes 0, then the chunk's records.
            op::CONNECTION | op::MESSAGE_DATA if past_end.is_none() => {
                let src = self.src.as_mut().expect("opened above");
                let data = src.read_at(head.data_at, head.data_len as usize)?;
                let mut record = (Vec::new(), None);
                let fields = fields.map_err(|r| src.damage(Damage::new(head.at, r)))?;
                push_entry(&fields, &data, head.at, &mut record);
                self.pending.extend(record.0);
                self.pending_damage = record.1;
            }
            op::INDEX_DATA | op::CONNECTION | op::MESSAGE_DATA => {
                return Err(src.damage(past_end.expect("checked by the arms above")));
            }
            other => {
                let reason = format!("unexpected record (op {other:#04x}) in the chunk section");
                return Err(src.damage(Damage::new(head.at, reason)));
            }
        }
        self.at = next;
        Ok(true)
    }

    /// Reads the chunk record `head` into `pending`; `past_end` says why the
    /// chunk does not lie wholly before `end`, if it does not.
    fn read_chunk(
        &mut self,
        head: &Head,
        fields: &Fields<'_>,
        end: u64,
        past_end: Option<Damage>,
    ) -> Result<(), IoError> {
        let src = self.src.as_mut().expect("opened by advance");
        let at = head.at;
        let bad = |r: String| Damage::new(at, format!("bad chunk header: {r}"));
        let (compression, size) = match (fields.str("compression"), fields.u32("size")) {
            (Ok(c), Ok(s)) => (c, s),
            (Err(r), _) | (_, Err(r)) => return Err(src.damage(bad(r))),
        };
        if size > MAX_CHUNK_BYTES {
            return Err(src.damage(Damage::new(at, format!("a chunk of {size} bytes uncompressed is not plausible"))));
        }
        match compression {
            "none" => {
                if size != head.data_len {
                    let reason = format!("an uncompressed chunk of {size} bytes that stores {}", head.data_len);
                    return Err(src.damage(Damage::new(at, reason)));
                }
                // Of a chunk cut short, the records before the cut.
                let stored = end.min(head.data_at + u64::from(head.data_len)) - head.data_at;
                let data = src.read_at(head.data_at, stored as usize)?;
                let (entries, damage) = parse_chunk(&data, head.data_at);
                self.pending.extend(entries);
                self.pending_damage = damage.or(past_end);
            }
            "bz2" | "lz4" => {
                if let Some(damage) = past_end {
                    return Err(src.damage(damage));
                }
                let entries = self.decode_compressed(at, compression)?;
                self.pending.extend(entries);
            }
            other => return Err(src.damage(Damage::new(at, format!("unknown chunk compression `{other}`")))),
        }
        Ok(())
    }

    /// The records of the compressed chunk at `at`, decoded by `rosbag`.
    fn decode_compressed(&mut self, at: u64, compression: &str) -> Result<Vec<Entry>, IoError> {
        let src = self.src.as_ref().expect("opened by advance");
        if !self.bag.has_index() {
            let reason = format!(
                "a {compression} chunk in a bag without an index (never closed?): compressed chunks are \
                 decoded by the rosbag crate, which needs the index; `rosbag reindex` the bag first"
            );
            return Err(src.damage(Damage::new(at, reason)));
        }
        let rosbag = match &mut self.rosbag {
            Some(rosbag) => rosbag,
            None => {
                let opened = RosBag::new(self.bag.path());
                let rosbag =
                    opened.map_err(|e| src.damage(Damage::new(0, format!("the rosbag crate refuses the bag: {e}"))))?;
                // `rosbag` maps the file and slices its chunk section up to
                // `index_pos`: the file must not have shrunk since it was
                // checked.
                let now = std::fs::metadata(self.bag.path()).map_err(|e| IoError::io(self.bag.path(), e))?.len();
                if now != self.bag.file_len {
                    return Err(src.damage(Damage::new(now, "the file changed length while being read")));
                }
                self.rosbag.insert(rosbag)
            }
        };
        let rosbag_error = |e: rosbag::Error| src.damage(Damage::new(at, format!("{compression} chunk: {e}")));
        let mut records = rosbag.chunk_records();
        records.seek(at).map_err(rosbag_error)?;
        let chunk = match records.next() {
            Some(Ok(ChunkRecord::Chunk(chunk))) => chunk,
            Some(Err(e)) => return Err(rosbag_error(e)),
            _ => return Err(src.damage(Damage::new(at, "the rosbag crate reads no chunk here"))),
        };
        let mut entries = Vec::new();
        for record in chunk.messages() {
            entries.push(match record.map_err(rosbag_error)? {
                MessageRecord::Connection(c) => {
                    Entry::Connection { id: c.id, topic: c.storage_topic.to_string(), msg_type: normalize_type(c.tp) }
                }
                MessageRecord::MessageData(m) => {
                    Entry::Message { at, conn: m.conn_id, time_ns: m.time, data: m.data.to_vec() }
                }
            });
        }
        Ok(entries)
    }
}

/// The records of an uncompressed chunk whose data starts at byte `base`,
/// and the damage that ends them early, if any.
fn parse_chunk(data: &[u8], base: u64) -> (Vec<Entry>, Option<Damage>) {
    let mut out = (Vec::new(), None);
    let mut at = 0;
    while at < data.len() && out.1.is_none() {
        let offset = base + at as u64;
        match split_record(data, at).and_then(|(record, next)| Ok((Fields::parse(record.header)?, record.data, next))) {
            Ok((fields, record_data, next)) => {
                push_entry(&fields, record_data, offset, &mut out);
                at = next;
            }
            Err(reason) => out.1 = Some(Damage::new(offset, format!("bad record in a chunk: {reason}"))),
        }
    }
    out
}

/// Adds the connection or message record at `at` to `out.0`, or its
/// damage as `out.1`.
fn push_entry(fields: &Fields<'_>, data: &[u8], at: u64, out: &mut (Vec<Entry>, Option<Damage>)) {
    let entry = fields.op().and_then(|op| match op {
        op::CONNECTION => {
            connection(fields, data).map(|(id, topic, msg_type)| Entry::Connection { id, topic, msg_type })
        }
        op::MESSAGE_DATA => {
            let (conn, time_ns) = (fields.u32("conn")?, fields.time_ns("time")?);
            Ok(Entry::Message { at, conn, time_ns, data: data.to_vec() })
        }
        other => Err(format!("unexpected record (op {other:#04x}) in a chunk")),
    });
    match entry {
        Ok(entry) => out.0.push(entry),
        Err(reason) => out.1 = Some(Damage::new(at, reason)),
    }
}

impl Iterator for Messages<'_> {
    type Item = Result<RawMessage, IoError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(found) = self.next_pending() {
                if found.is_err() {
                    self.done = true;
                    self.pending.clear();
                }
                let src = self.src.as_ref()?;
                return Some(found.map_err(|d| src.damage(d)));
            }
            if self.done {
                return None;
            }
            match self.advance() {
                Ok(true) => {}
                Ok(false) => self.done = true,
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
        }
    }
}
