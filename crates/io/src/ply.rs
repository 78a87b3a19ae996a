//! PLY point clouds.
//!
//! [`write_ply`] writes binary little-endian `float x y z` and `uchar red
//! green blue` per vertex, readable by MeshLab, CloudCompare, Open3D and
//! Blender: occupied voxels, and EDT voxels coloured by distance.
//!
//! [`read_ply`] reads the `x`, `y`, `z` of the `vertex` element of any PLY
//! 1.0 file (`ascii`, `binary_little_endian` or `binary_big_endian`), of
//! any scalar type; other properties, list properties and other elements
//! are skipped. Counts in the header are checked against the file's size
//! before anything is allocated, so no header can make it allocate much
//! more than the file.

use crate::IoError;
use edtmap_core::sensor::PointCloud;
use std::io::Write;
use std::path::Path;

/// One coloured point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColouredPoint {
    /// Position, metres.
    pub xyz: [f32; 3],
    /// Colour: 8-bit red, green, blue.
    pub rgb: [u8; 3],
}

/// Writes `points` to `path` as a binary PLY; `comment` goes into the
/// header. The file is written atomically ([`crate::files::AtomicFile`]), so
/// a failed write leaves no partial file.
pub fn write_ply(path: &Path, points: &[ColouredPoint], comment: &str) -> Result<(), IoError> {
    let mut bytes = Vec::with_capacity(200 + points.len() * 15);
    let comment = comment.replace(['\n', '\r'], " ");
    write!(
        bytes,
        "ply\nformat binary_little_endian 1.0\ncomment {comment}\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        points.len()
    )
    .map_err(|e| IoError::io(path, e))?;
    for p in points {
        for c in p.xyz {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
        bytes.extend_from_slice(&p.rgb);
    }
    crate::files::write_atomic(path, &bytes)
}

/// Reads the points of a PLY file: the `x`, `y`, `z` of its `vertex`
/// element, in file order, rounded to `f32`.
///
/// # Errors
///
/// Every error names the file: [`IoError::Io`] when it cannot be read,
/// [`IoError::NotRegular`] or [`IoError::TooLarge`] when it is a FIFO, a
/// device or a folder or more than
/// [`MAX_CLOUD_BYTES`](crate::files::MAX_CLOUD_BYTES),
/// [`IoError::Truncated`] when fixed-size binary data is short, and
/// [`IoError::Dataset`] for the rest (a bad header line, an unknown type,
/// no `vertex` element or no `x`/`y`/`z`, a bad number at line N, data
/// that ends early).
pub fn read_ply(path: &Path) -> Result<PointCloud, IoError> {
    let bytes = crate::files::read_input(path, crate::files::MAX_CLOUD_BYTES)?;
    parse_ply(path, &bytes)
}

/// Parses the bytes of a PLY file (see [`read_ply`]); `path` only names it
/// in errors.
pub fn parse_ply(path: &Path, bytes: &[u8]) -> Result<PointCloud, IoError> {
    let header = PlyHeader::parse(path, bytes)?;
    let vertex =
        header.elements.iter().position(|e| e.name == "vertex").ok_or_else(|| ply_err(path, "no vertex element"))?;
    let coords = header.elements[vertex].coords(path)?;
    let points = match header.format {
        PlyFormat::Ascii => {
            let mut tokens = Tokens { data: bytes, pos: header.data_start, line: header.lines };
            for element in &header.elements[..vertex] {
                element.skip_ascii(path, &mut tokens)?;
            }
            header.elements[vertex].read_ascii(path, &mut tokens, coords)?
        }
        PlyFormat::Binary { big_endian } => {
            let mut pos = header.data_start;
            for element in &header.elements[..vertex] {
                element.walk_binary(path, bytes, &mut pos, big_endian, |_, _| {})?;
            }
            let element = &header.elements[vertex];
            let mut points = Vec::with_capacity(element.count_usize().min(bytes.len().saturating_sub(pos)));
            let mut p = [0.0f32; 3];
            element.walk_binary(path, bytes, &mut pos, big_endian, |k, b| {
                if let Some(axis) = coords.iter().position(|&c| c == k) {
                    p[axis] = element.props[k].1.scalar().map_or(f64::NAN, |s| s.decode(b, big_endian)) as f32;
                    if axis == 2 {
                        points.push(p);
                    }
                }
            })?;
            points
        }
    };
    Ok(PointCloud { points })
}

fn ply_err(path: &Path, reason: impl Into<String>) -> IoError {
    IoError::Dataset { path: path.to_path_buf(), reason: format!("PLY: {}", reason.into()) }
}

/// How a PLY file stores its data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PlyFormat {
    Ascii,
    Binary { big_endian: bool },
}

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The value of `b` (this type's size in bytes; missing bytes read 0).
    fn decode(self, b: &[u8], big: bool) -> f64 {
        fn arr<const N: usize>(b: &[u8], big: bool) -> [u8; N] {
            let mut a = [0; N];
            a.iter_mut().zip(b).for_each(|(o, i)| *o = *i);
            if big {
                a.reverse();
            }
            a
        }
        match self {
            Scalar::I8 => f64::from(i8::from_le_bytes(arr(b, big))),
            Scalar::U8 => f64::from(u8::from_le_bytes(arr(b, big))),
            Scalar::I16 => f64::from(i16::from_le_bytes(arr(b, big))),
            Scalar::U16 => f64::from(u16::from_le_bytes(arr(b, big))),
            Scalar::I32 => f64::from(i32::from_le_bytes(arr(b, big))),
            Scalar::U32 => f64::from(u32::from_le_bytes(arr(b, big))),
            Scalar::F32 => f64::from(f32::from_le_bytes(arr(b, big))),
            Scalar::F64 => f64::from_le_bytes(arr(b, big)),
        }
    }
}

/// A property: one scalar, or a list of scalars preceded by its length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Prop {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

impl Prop {
    fn scalar(self) -> Option<Scalar> {
        match self {
            Prop::Scalar(s) => Some(s),
            Prop::List { .. } => None,
        }
    }
}

/// An element of the header: its name, record count and properties.
#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<(String, Prop)>,
}

/// The parsed header.
#[derive(Debug)]
struct PlyHeader {
    format: PlyFormat,
    elements: Vec<Element>,
    /// Offset of the first data byte.
    data_start: usize,
    /// Header lines, `end_header` included.
    lines: usize,
}

impl PlyHeader {
    fn parse(path: &Path, bytes: &[u8]) -> Result<Self, IoError> {
        let (mut format, mut elements) = (None, Vec::<Element>::new());
        let (mut pos, mut line_no) = (0, 0);
        loop {
            let end = bytes[pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map(|n| pos + n)
                .ok_or_else(|| ply_err(path, "no end_header line"))?;
            line_no += 1;
            let at = |reason: String| ply_err(path, format!("header line {line_no}: {reason}"));
            let line = std::str::from_utf8(&bytes[pos..end]).map_err(|_| at("not text".into()))?.trim();
            pos = end + 1;
            let tokens: Vec<&str> = line.split_ascii_whitespace().collect();
            if line_no == 1 {
                if line != "ply" {
                    return Err(ply_err(path, "not a PLY file (the first line is not `ply`)"));
                }
                continue;
            }
            match tokens.as_slice() {
                ["end_header"] => break,
                [] | ["comment" | "obj_info", ..] => {}
                ["format", kind, version] => {
                    if format.is_some() {
                        return Err(at("format given twice".into()));
                    }
                    if *version != "1.0" {
                        return Err(at(format!("version {} is not supported (only 1.0)", shown(version))));
                    }
                    format = Some(match *kind {
                        "ascii" => PlyFormat::Ascii,
                        "binary_little_endian" => PlyFormat::Binary { big_endian: false },
                        "binary_big_endian" => PlyFormat::Binary { big_endian: true },
                        other => return Err(at(format!("unknown format {}", shown(other)))),
                    });
                }
                ["element", name, count] => {
                    let count = count.parse::<u64>().map_err(|_| {
                        at(format!("element {}: count {} is not a non-negative integer", shown(name), shown(count)))
                    })?;
                    elements.push(Element { name: (*name).to_string(), count, props: Vec::new() });
                }
                ["property", rest @ ..] => {
                    let element = elements.last_mut().ok_or_else(|| at("property before any element".into()))?;
                    let (name, prop) = parse_property(rest).map_err(at)?;
                    if element.props.iter().any(|(n, _)| n == name) {
                        return Err(at(format!(
                            "property {} listed twice in element {}",
                            shown(name),
                            shown(&element.name)
                        )));
                    }
                    element.props.push((name.to_string(), prop));
                }
                _ => return Err(at(format!("cannot read {}", shown(line)))),
            }
        }
        let format = format.ok_or_else(|| ply_err(path, "no format line"))?;
        Ok(PlyHeader { format, elements, data_start: pos, lines: line_no })
    }
}

/// At most 40 characters of `s`, quoted, for error messages.
fn shown(s: &str) -> String {
    format!("{:?}", s.chars().take(40).collect::<String>())
}

/// `type name` or `list count_type item_type name`.
fn parse_property<'a>(tokens: &[&'a str]) -> Result<(&'a str, Prop), String> {
    let ty = |t: &str| Scalar::from_name(t).ok_or_else(|| format!("unknown type {}", shown(t)));
    match *tokens {
        ["list", count, item, name] => {
            let count = ty(count)?;
            if matches!(count, Scalar::F32 | Scalar::F64) {
                return Err(format!("list {}: the length type must be an integer type", shown(name)));
            }
            Ok((name, Prop::List { count, item: ty(item)? }))
        }
        [scalar, name] => Ok((name, Prop::Scalar(ty(scalar)?))),
        _ => Err("expected `property TYPE NAME` or `property list COUNT_TYPE ITEM_TYPE NAME`".into()),
    }
}

/// Whitespace-separated tokens of ascii data, with their line numbers.
struct Tokens<'a> {
    data: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Tokens<'a> {
    /// The next token; at the end, `None`, the line staying at the last
    /// token's so that errors point at the record that ends early.
    fn next(&mut self) -> Option<&'a [u8]> {
        let line = self.line;
        while let Some(&b) = self.data.get(self.pos) {
            if !b.is_ascii_whitespace() {
                break;
            }
            self.line += usize::from(b == b'\n');
            self.pos += 1;
        }
        let start = self.pos;
        while self.data.get(self.pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            self.pos += 1;
        }
        if self.pos == start {
            self.line = line;
            return None;
        }
        Some(&self.data[start..self.pos])
    }

    /// The current line, 1-based, counting the header.
    fn line_no(&self) -> usize {
        self.line + 1
    }
}

impl Element {
    fn count_usize(&self) -> usize {
        usize::try_from(self.count).unwrap_or(usize::MAX)
    }

    /// Indices of `x`, `y`, `z` among the properties.
    fn coords(&self, path: &Path) -> Result<[usize; 3], IoError> {
        let mut out = [0; 3];
        for (o, axis) in out.iter_mut().zip(["x", "y", "z"]) {
            *o = self
                .props
                .iter()
                .position(|(n, _)| n == axis)
                .ok_or_else(|| ply_err(path, format!("element vertex has no property {axis}")))?;
            if self.props[*o].1.scalar().is_none() {
                return Err(ply_err(path, format!("vertex property {axis} is a list")));
            }
        }
        Ok(out)
    }

    /// Skips this element's ascii records.
    fn skip_ascii(&self, path: &Path, tokens: &mut Tokens<'_>) -> Result<(), IoError> {
        // An element without properties has nothing to read, however many records.
        if self.props.is_empty() {
            return Ok(());
        }
        for record in 0..self.count {
            self.ascii_record(path, tokens, record, |_, _, _| Ok(()))?;
        }
        Ok(())
    }

    /// The vertices of ascii data.
    fn read_ascii(&self, path: &Path, tokens: &mut Tokens<'_>, coords: [usize; 3]) -> Result<Vec<[f32; 3]>, IoError> {
        // A value takes at least two bytes with its separator.
        let mut points =
            Vec::with_capacity(self.count_usize().min(tokens.data.len().saturating_sub(tokens.pos) / 2 + 1));
        for record in 0..self.count {
            let mut p = [0.0f32; 3];
            self.ascii_record(path, tokens, record, |k, tok, line| {
                if let Some(axis) = coords.iter().position(|&c| c == k) {
                    let s = std::str::from_utf8(tok).ok();
                    p[axis] = s.and_then(|s| s.parse::<f64>().ok()).ok_or_else(|| {
                        let name = ["x", "y", "z"][axis];
                        ply_err(
                            path,
                            format!("line {line}: bad number {} for {name}", shown(&String::from_utf8_lossy(tok))),
                        )
                    })? as f32;
                }
                Ok(())
            })?;
            points.push(p);
        }
        Ok(points)
    }

    /// Reads one ascii record, handing each scalar property's token to `seen`.
    fn ascii_record<'a>(
        &self,
        path: &Path,
        tokens: &mut Tokens<'a>,
        record: u64,
        mut seen: impl FnMut(usize, &'a [u8], usize) -> Result<(), IoError>,
    ) -> Result<(), IoError> {
        let short = |line: usize| {
            ply_err(
                path,
                format!(
                    "line {line}: the data ends in record {record} of element {} ({} records promised)",
                    self.name, self.count
                ),
            )
        };
        for (k, (name, prop)) in self.props.iter().enumerate() {
            match prop {
                Prop::Scalar(_) => {
                    let tok = tokens.next().ok_or_else(|| short(tokens.line_no()))?;
                    seen(k, tok, tokens.line_no())?;
                }
                Prop::List { .. } => {
                    let tok = tokens.next().ok_or_else(|| short(tokens.line_no()))?;
                    let n = std::str::from_utf8(tok).ok().and_then(|s| s.parse::<u64>().ok()).ok_or_else(|| {
                        ply_err(
                            path,
                            format!(
                                "line {}: list {name}: bad length {}",
                                tokens.line_no(),
                                shown(&String::from_utf8_lossy(tok))
                            ),
                        )
                    })?;
                    for _ in 0..n {
                        tokens.next().ok_or_else(|| short(tokens.line_no()))?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Walks this element's binary records from `*pos`, handing each scalar
    /// property's bytes to `seen`.
    fn walk_binary(
        &self,
        path: &Path,
        bytes: &[u8],
        pos: &mut usize,
        big: bool,
        mut seen: impl FnMut(usize, &[u8]),
    ) -> Result<(), IoError> {
        let fixed: Option<Vec<Scalar>> = self.props.iter().map(|(_, p)| p.scalar()).collect();
        if let Some(fixed) = &fixed {
            // Check the whole element fits before reading any record.
            let size = fixed.iter().map(|s| s.size()).sum::<usize>() as u64;
            let need = self.count.saturating_mul(size);
            let left = bytes.len().saturating_sub(*pos) as u64;
            if need > left {
                return Err(IoError::Truncated { path: path.to_path_buf(), expected: need, actual: left });
            }
            if size == 0 {
                return Ok(());
            }
        }
        for record in 0..self.count {
            let short = || {
                ply_err(
                    path,
                    format!(
                        "truncated data: record {record} of element {} ({} promised) ends past the end of the file",
                        self.name, self.count
                    ),
                )
            };
            for (k, (_, prop)) in self.props.iter().enumerate() {
                match *prop {
                    Prop::Scalar(s) => seen(k, take(bytes, pos, s.size() as u64).ok_or_else(short)?),
                    Prop::List { count, item } => {
                        let n = count.decode(take(bytes, pos, count.size() as u64).ok_or_else(short)?, big);
                        if n < 0.0 {
                            return Err(ply_err(
                                path,
                                format!(
                                    "record {record} of element {}: list {} has length {n}",
                                    self.name, self.props[k].0
                                ),
                            ));
                        }
                        take(bytes, pos, (n as u64).saturating_mul(item.size() as u64)).ok_or_else(short)?;
                    }
                }
            }
        }
        Ok(())
    }
}

/// The next `n` bytes at `*pos`, advancing it; `None` past the end.
fn take<'a>(bytes: &'a [u8], pos: &mut usize, n: u64) -> Option<&'a [u8]> {
    let end = pos.checked_add(usize::try_from(n).ok()?)?;
    let out = bytes.get(*pos..end)?;
    *pos = end;
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_and_body_round_trip() {
        let dir = std::env::temp_dir().join(format!("edtmap-ply-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("p.ply");
        let points = [
            ColouredPoint { xyz: [1.5, -2.0, 0.25], rgb: [10, 20, 30] },
            ColouredPoint { xyz: [0.0, 0.0, 1e6], rgb: [255, 0, 7] },
        ];
        write_ply(&path, &points, "two\npoints").expect("written");
        let bytes = std::fs::read(&path).expect("read");
        let end = b"end_header\n";
        let at = bytes.windows(end.len()).position(|w| w == end).expect("header end") + end.len();
        let header = std::str::from_utf8(&bytes[..at]).expect("ascii header");
        assert!(header.starts_with("ply\nformat binary_little_endian 1.0\ncomment two points\nelement vertex 2\n"));
        let body = &bytes[at..];
        assert_eq!(body.len(), 2 * 15);
        let f = |k: usize| f32::from_le_bytes(body[k..k + 4].try_into().expect("4 bytes"));
        assert_eq!([f(0), f(4), f(8)], [1.5, -2.0, 0.25]);
        assert_eq!(&body[12..15], &[10, 20, 30]);
        assert_eq!(f(15 + 8), 1e6);
        assert_eq!(&body[27..30], &[255, 0, 7]);
        std::fs::remove_dir_all(&dir).ok();
    }
}
