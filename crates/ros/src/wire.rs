//! The two wire formats of ROS messages, read and written field by field.
//!
//! ROS 1 packs fields little-endian with no padding; strings and variable
//! arrays carry a `u32` length. ROS 2 uses CDR: a 4-byte encapsulation
//! header (`00 01` little-endian, `00 00` big-endian), then fields aligned
//! to their own size counted from the end of that header, and strings
//! whose length counts a terminating NUL. One reader and one writer serve
//! both, so every message type is described once.

use super::Encoding;

/// Reads fields from a serialized message; every read is bounds-checked.
pub(crate) struct WireReader<'a> {
    data: &'a [u8],
    pos: usize,
    origin: usize,
    cdr: bool,
    big_endian: bool,
}

/// What went wrong decoding: the field and why.
pub(crate) type WireResult<T> = Result<T, String>;

impl<'a> WireReader<'a> {
    /// A reader over `data` in `encoding`; CDR data starts with its
    /// encapsulation header.
    pub(crate) fn new(data: &'a [u8], encoding: Encoding) -> WireResult<Self> {
        match encoding {
            Encoding::Ros1 => Ok(WireReader { data, pos: 0, origin: 0, cdr: false, big_endian: false }),
            Encoding::Cdr => {
                let header = data.get(..4).ok_or("shorter than the 4-byte CDR header")?;
                let big_endian = match header[..2] {
                    [0, 0] => true,
                    [0, 1] => false,
                    _ => return Err(format!("CDR representation {:02x}{:02x} is not plain CDR", header[0], header[1])),
                };
                Ok(WireReader { data, pos: 4, origin: 4, cdr: true, big_endian })
            }
        }
    }

    fn take(&mut self, n: usize, what: &str) -> WireResult<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.data.len());
        let end = end.ok_or_else(|| {
            format!("{what}: needs {n} bytes at offset {}, the message has {}", self.pos, self.data.len())
        })?;
        let bytes = &self.data[self.pos..end];
        self.pos = end;
        Ok(bytes)
    }

    fn align(&mut self, n: usize) {
        if self.cdr {
            let rel = self.pos - self.origin;
            self.pos += (n - rel % n) % n;
        }
    }

    fn array<const N: usize>(&mut self, what: &str) -> WireResult<[u8; N]> {
        self.align(N);
        let b = self.take(N, what)?;
        let mut out = [0u8; N];
        out.copy_from_slice(b);
        if self.big_endian {
            out.reverse();
        }
        Ok(out)
    }

    /// A `uint8` or `bool`.
    pub(crate) fn u8(&mut self, what: &str) -> WireResult<u8> {
        Ok(self.take(1, what)?[0])
    }

    /// A `uint32`.
    pub(crate) fn u32(&mut self, what: &str) -> WireResult<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    /// An `int32`.
    pub(crate) fn i32(&mut self, what: &str) -> WireResult<i32> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }

    /// A `float32`.
    pub(crate) fn f32(&mut self, what: &str) -> WireResult<f32> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }

    /// A `float64`.
    pub(crate) fn f64(&mut self, what: &str) -> WireResult<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    /// Length of a string or variable array, checked against the bytes
    /// left (each element takes at least `min_elem` bytes).
    fn len(&mut self, what: &str, min_elem: usize) -> WireResult<usize> {
        let n = self.u32(what)? as usize;
        let left = self.data.len() - self.pos;
        if n.saturating_mul(min_elem.max(1)) > left {
            return Err(format!("{what}: length {n} at offset {} exceeds the {left} bytes left", self.pos - 4));
        }
        Ok(n)
    }

    /// A `string`.
    pub(crate) fn string(&mut self, what: &str) -> WireResult<String> {
        let n = self.len(what, 1)?;
        let mut bytes = self.take(n, what)?;
        if self.cdr {
            // CDR counts the terminating NUL; tolerate writers that omit it.
            if let [head @ .., 0] = bytes {
                bytes = head;
            }
        }
        String::from_utf8(bytes.to_vec()).map_err(|_| format!("{what}: not UTF-8"))
    }

    /// A `uint8[]`.
    pub(crate) fn bytes(&mut self, what: &str) -> WireResult<Vec<u8>> {
        let n = self.len(what, 1)?;
        Ok(self.take(n, what)?.to_vec())
    }

    /// A `float32[]`.
    pub(crate) fn f32s(&mut self, what: &str) -> WireResult<Vec<f32>> {
        let n = self.len(what, 4)?;
        (0..n).map(|_| self.f32(what)).collect()
    }

    /// A `float64[]`.
    pub(crate) fn f64s(&mut self, what: &str) -> WireResult<Vec<f64>> {
        let n = self.len(what, 8)?;
        (0..n).map(|_| self.f64(what)).collect()
    }

    /// A fixed `float64[N]`.
    pub(crate) fn f64_array<const N: usize>(&mut self, what: &str) -> WireResult<[f64; N]> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }

    /// Count of a variable array of structs, each at least `min_elem` bytes.
    pub(crate) fn seq_len(&mut self, what: &str, min_elem: usize) -> WireResult<usize> {
        self.len(what, min_elem)
    }

    /// Whether the message was ROS 1 (whose headers carry a `seq`).
    pub(crate) fn is_ros1(&self) -> bool {
        !self.cdr
    }
}

/// Writes fields of a message, mirroring [`WireReader`].
pub(crate) struct WireWriter {
    data: Vec<u8>,
    origin: usize,
    cdr: bool,
}

impl WireWriter {
    /// An empty message in `encoding` (CDR little-endian).
    pub(crate) fn new(encoding: Encoding) -> Self {
        match encoding {
            Encoding::Ros1 => WireWriter { data: Vec::new(), origin: 0, cdr: false },
            Encoding::Cdr => WireWriter { data: vec![0, 1, 0, 0], origin: 4, cdr: true },
        }
    }

    /// The serialized message.
    pub(crate) fn finish(self) -> Vec<u8> {
        self.data
    }

    fn align(&mut self, n: usize) {
        if self.cdr {
            let rel = self.data.len() - self.origin;
            self.data.resize(self.data.len() + (n - rel % n) % n, 0);
        }
    }

    pub(crate) fn is_ros1(&self) -> bool {
        !self.cdr
    }

    pub(crate) fn u8(&mut self, v: u8) {
        self.data.push(v);
    }

    pub(crate) fn u32(&mut self, v: u32) {
        self.align(4);
        self.data.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn i32(&mut self, v: i32) {
        self.align(4);
        self.data.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn f32(&mut self, v: f32) {
        self.align(4);
        self.data.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn f64(&mut self, v: f64) {
        self.align(8);
        self.data.extend_from_slice(&v.to_le_bytes());
    }

    fn len(&mut self, n: usize) {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }

    pub(crate) fn string(&mut self, s: &str) {
        if self.cdr {
            self.len(s.len() + 1);
            self.data.extend_from_slice(s.as_bytes());
            self.data.push(0);
        } else {
            self.len(s.len());
            self.data.extend_from_slice(s.as_bytes());
        }
    }

    pub(crate) fn bytes(&mut self, b: &[u8]) {
        self.len(b.len());
        self.data.extend_from_slice(b);
    }

    pub(crate) fn f32s(&mut self, v: &[f32]) {
        self.len(v.len());
        v.iter().for_each(|&x| self.f32(x));
    }

    pub(crate) fn f64s(&mut self, v: &[f64]) {
        self.len(v.len());
        v.iter().for_each(|&x| self.f64(x));
    }

    pub(crate) fn f64_array(&mut self, v: &[f64]) {
        v.iter().for_each(|&x| self.f64(x));
    }

    pub(crate) fn seq_len(&mut self, n: usize) {
        self.len(n);
    }
}
