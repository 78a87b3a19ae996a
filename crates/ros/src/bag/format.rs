//! The record framing of bag format 2.0, shared by the reader and the
//! writer: every record is `u32` header length, header fields, `u32` data
//! length, data; a header field is `u32` length then `name=value`.

/// The first bytes of every version 2.0 bag.
pub(super) const MAGIC: &[u8] = b"#ROSBAG V2.0\n";
/// Bytes of the bag header record's header and padding together, so that
/// rewriting it on close never moves the chunks (as `rosbag` C++ writes it).
pub(super) const BAG_HEADER_BYTES: usize = 4096;
/// Longest record header accepted; real ones hold a few short fields.
pub(super) const MAX_HEADER_BYTES: u32 = 1 << 20;
/// Largest uncompressed chunk accepted before allocating it (`rosbag
/// record` writes 768 KiB chunks by default).
pub(super) const MAX_CHUNK_BYTES: u32 = 1 << 30;

/// Record opcodes (the `op` header field).
pub(super) mod op {
    pub(in super::super) const MESSAGE_DATA: u8 = 0x02;
    pub(in super::super) const BAG_HEADER: u8 = 0x03;
    pub(in super::super) const INDEX_DATA: u8 = 0x04;
    pub(in super::super) const CHUNK: u8 = 0x05;
    pub(in super::super) const CHUNK_INFO: u8 = 0x06;
    pub(in super::super) const CONNECTION: u8 = 0x07;
}

/// What is wrong at a byte offset of the file; the caller adds the path.
#[derive(Debug)]
pub(super) struct Damage {
    /// Byte offset in the file.
    pub(super) offset: u64,
    /// What is wrong there.
    pub(super) reason: String,
}

impl Damage {
    pub(super) fn new(offset: u64, reason: impl Into<String>) -> Self {
        Damage { offset, reason: reason.into() }
    }
}

/// Little-endian `u32` at `at`, if the bytes are there.
pub(super) fn le_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// A ROS time (`u32` seconds, `u32` nanoseconds) in nanoseconds.
pub(super) fn time_ns(secs: u32, nsecs: u32) -> u64 {
    u64::from(secs) * 1_000_000_000 + u64::from(nsecs)
}

/// The fields of a record header (or of a connection record's data, which
/// uses the same encoding), in stored order.
pub(super) struct Fields<'a> {
    fields: Vec<(&'a [u8], &'a [u8])>,
}

impl<'a> Fields<'a> {
    /// Splits `bytes` into fields; the error says what is malformed.
    pub(super) fn parse(mut bytes: &'a [u8]) -> Result<Self, String> {
        let mut fields = Vec::new();
        while !bytes.is_empty() {
            let len = le_u32(bytes, 0).ok_or("a header field is cut short")? as usize;
            let field = bytes.get(4..4 + len).ok_or("a header field runs past the header")?;
            let eq = field.iter().position(|&c| c == b'=').ok_or("a header field has no `=`")?;
            if eq == 0 {
                return Err("a header field has an empty name".into());
            }
            fields.push((&field[..eq], &field[eq + 1..]));
            bytes = &bytes[4 + len..];
        }
        Ok(Fields { fields })
    }

    fn get(&self, name: &str) -> Result<&'a [u8], String> {
        let found = self.fields.iter().find(|(n, _)| *n == name.as_bytes());
        found.map(|(_, v)| *v).ok_or_else(|| format!("the `{name}` field is missing"))
    }

    fn sized<const N: usize>(&self, name: &str) -> Result<[u8; N], String> {
        let v = self.get(name)?;
        v.try_into().map_err(|_| format!("the `{name}` field has {} bytes, not {N}", v.len()))
    }

    /// The record's opcode.
    pub(super) fn op(&self) -> Result<u8, String> {
        Ok(self.sized::<1>("op")?[0])
    }

    /// A little-endian `u32` field.
    pub(super) fn u32(&self, name: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.sized(name)?))
    }

    /// A little-endian `u64` field.
    pub(super) fn u64(&self, name: &str) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.sized(name)?))
    }

    /// A time field, in nanoseconds.
    pub(super) fn time_ns(&self, name: &str) -> Result<u64, String> {
        let v: [u8; 8] = self.sized(name)?;
        let secs = u32::from_le_bytes([v[0], v[1], v[2], v[3]]);
        Ok(time_ns(secs, u32::from_le_bytes([v[4], v[5], v[6], v[7]])))
    }

    /// A UTF-8 text field.
    pub(super) fn str(&self, name: &str) -> Result<&'a str, String> {
        std::str::from_utf8(self.get(name)?).map_err(|_| format!("the `{name}` field is not UTF-8"))
    }

    /// Whether the field is present.
    pub(super) fn has(&self, name: &str) -> bool {
        self.get(name).is_ok()
    }
}

/// One record held in memory: its header and its data.
pub(super) struct Record<'a> {
    /// The header's fields, unparsed.
    pub(super) header: &'a [u8],
    /// The data.
    pub(super) data: &'a [u8],
}

/// The record starting at `at` in `bytes` and where the next one starts;
/// `Err` says why it cannot be split (cut short, lengths past the end).
pub(super) fn split_record(bytes: &[u8], at: usize) -> Result<(Record<'_>, usize), String> {
    let cut = || "the record is cut short".to_string();
    let header_len = le_u32(bytes, at).ok_or_else(cut)? as usize;
    let header = bytes.get(at + 4..at + 4 + header_len).ok_or_else(cut)?;
    let data_at = at + 4 + header_len;
    let data_len = le_u32(bytes, data_at).ok_or_else(cut)? as usize;
    let data = bytes.get(data_at + 4..data_at + 4 + data_len).ok_or_else(cut)?;
    Ok((Record { header, data }, data_at + 4 + data_len))
}

/// Appends a header field `name=value` with its length.
pub(super) fn put_field(out: &mut Vec<u8>, name: &str, value: &[u8]) {
    put_u32(out, (name.len() + 1 + value.len()) as u32);
    out.extend_from_slice(name.as_bytes());
    out.push(b'=');
    out.extend_from_slice(value);
}

/// Appends a little-endian `u32`.
pub(super) fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

/// A time in nanoseconds as the 8 bytes of a ROS time; `None` past 2106.
pub(super) fn time_bytes(time_ns: u64) -> Option<[u8; 8]> {
    let secs = u32::try_from(time_ns / 1_000_000_000).ok()?;
    let nsecs = (time_ns % 1_000_000_000) as u32;
    let mut b = [0; 8];
    b[..4].copy_from_slice(&secs.to_le_bytes());
    b[4..].copy_from_slice(&nsecs.to_le_bytes());
    Some(b)
}

/// A whole record: header fields, then `data`.
pub(super) fn record(fields: &[(&str, &[u8])], data: &[u8]) -> Vec<u8> {
    let mut header = Vec::new();
    for (name, value) in fields {
        put_field(&mut header, name, value);
    }
    let mut out = Vec::with_capacity(8 + header.len() + data.len());
    put_u32(&mut out, header.len() as u32);
    out.extend_from_slice(&header);
    put_u32(&mut out, data.len() as u32);
    out.extend_from_slice(data);
    out
}
