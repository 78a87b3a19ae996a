//! The bytes of an `.npy` header, read and checked before `npyz` parses
//! them: the header's length is checked against the file and a cap before
//! it is allocated, and a dictionary that names a key twice is refused
//! (Python's `dict` keeps the last value silently).

use std::io::Read;
use std::path::Path;

use crate::IoError;

/// Largest header read: NumPy itself refuses headers over 10 000 bytes
/// unless told otherwise; an obstacle grid's takes 128.
pub(super) const MAX_HEADER_BYTES: u64 = 1 << 20;

fn not_npy(path: &Path, reason: impl Into<String>) -> IoError {
    IoError::NotNpy { path: path.into(), reason: reason.into() }
}

/// The magic, version, header length and header text of the npy file
/// `path` of `file_len` bytes, read from `r` at its start.
pub(super) fn read_header_bytes(path: &Path, r: &mut impl Read, file_len: u64) -> Result<Vec<u8>, IoError> {
    let mut bytes = vec![0; 8];
    r.read_exact(&mut bytes).map_err(|_| not_npy(path, "shorter than the npy magic and version"))?;
    if &bytes[..6] != b"\x93NUMPY" {
        return Err(not_npy(path, "magic not found for NPY file"));
    }
    let len_bytes = match bytes[6] {
        1 => 2,
        2 | 3 => 4,
        major => {
            return Err(not_npy(path, format!("format version {major}.{} is not supported (1, 2 or 3)", bytes[7])))
        }
    };
    let mut len = [0u8; 4];
    r.read_exact(&mut len[..len_bytes]).map_err(|_| not_npy(path, "the file ends in the header length"))?;
    bytes.extend_from_slice(&len[..len_bytes]);
    let header_len = u64::from(u32::from_le_bytes(len));
    let start = bytes.len() as u64;
    if header_len > MAX_HEADER_BYTES || start + header_len > file_len {
        return Err(not_npy(
            path,
            format!("the header length field says {header_len} bytes, the file has {} after it and at most {MAX_HEADER_BYTES} are read", file_len.saturating_sub(start)),
        ));
    }
    let mut text = vec![0; header_len as usize];
    r.read_exact(&mut text).map_err(|e| IoError::io(path, e))?;
    if let Some(key) = duplicate_key(&text) {
        return Err(not_npy(path, format!("the header names the key {key:?} twice")));
    }
    bytes.extend_from_slice(&text);
    Ok(bytes)
}

/// The first key that a Python dict literal names twice, if any. Keys are
/// the string literals at the dict's top level followed by `:`.
pub(super) fn duplicate_key(text: &[u8]) -> Option<String> {
    let mut keys: Vec<&[u8]> = Vec::new();
    let (mut depth, mut i) = (0usize, 0usize);
    while let Some(&c) = text.get(i) {
        match c {
            b'{' | b'(' | b'[' => depth += 1,
            b'}' | b')' | b']' => depth = depth.saturating_sub(1),
            b'\'' | b'"' => {
                let end = string_end(text, i);
                let literal = &text[i + 1..end.saturating_sub(1).max(i + 1)];
                let next = text[end..].iter().find(|b| !b.is_ascii_whitespace());
                if depth == 1 && next == Some(&b':') {
                    if keys.contains(&literal) {
                        return Some(String::from_utf8_lossy(literal).into_owned());
                    }
                    keys.push(literal);
                }
                i = end;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    None
}

/// The index just past the string literal opening at `start` (its
/// closing quote; the end of `text` when it is not closed).
fn string_end(text: &[u8], start: usize) -> usize {
    let quote = text[start];
    let mut i = start + 1;
    while let Some(&c) = text.get(i) {
        match c {
            b'\\' => i += 2,
            c if c == quote => return i + 1,
            _ => i += 1,
        }
    }
    text.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duplicate_keys_are_found_at_the_top_level_only() {
        assert_eq!(duplicate_key(b"{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3), }"), None);
        assert_eq!(duplicate_key(b"{'descr': '|u1', 'shape': (2,), 'shape': (2, 3), }").as_deref(), Some("shape"));
        // Either quote spells the same key.
        assert_eq!(duplicate_key(b"{\"descr\": '<i4', 'descr': '|b1'}").as_deref(), Some("descr"));
        // A value that looks like a key, or a quote escaped inside a string.
        assert_eq!(duplicate_key(b"{'descr': [('descr', '<i4')], 'x': 'a\\'b', 'shape': ()}"), None);
        assert_eq!(duplicate_key(b"{'a': 1, 'b': 2, 'a': 3"), Some("a".into()));
    }
}
