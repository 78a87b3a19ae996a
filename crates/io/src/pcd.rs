//! Point clouds in PCL's PCD format.
//!
//! Headers of versions 0.5 to 0.7 are read: `VERSION`, `FIELDS` (or the
//! older `COLUMNS`), `SIZE`, `TYPE`, `COUNT` (optional, 1 each by default),
//! `WIDTH`, `HEIGHT` (optional, 1), `VIEWPOINT` (optional, identity),
//! `POINTS` (optional, `WIDTH × HEIGHT`) and `DATA`; `#` lines are comments.
//! `DATA ascii` and `DATA binary` (little-endian, one point after the other,
//! as PCL writes them) are supported; `binary_compressed` is refused with
//! [`IoError::PcdUnsupportedData`].
//!
//! Only the fields `x`, `y`, `z` are read; they must be `F` of size 4 or 8
//! and count 1. Every other field, of any type, size and count, is skipped
//! (`SIZE × COUNT` bytes in binary data, `COUNT` values in ascii data).
//!
//! The data must hold exactly `POINTS` points: fewer, or more (the rest
//! would be silently dropped), is refused. What is allocated is bounded
//! by the data's length, not by `POINTS` (binary data is checked against
//! `POINTS` × point size first), so no header can make the reader
//! allocate much more than the file.

use std::path::Path;

use edtmap_core::sensor::PointCloud;

use crate::IoError;

/// Reads the point cloud of a PCD file: its `x`, `y`, `z` fields, in
/// metres, in the sensor frame.
///
/// Points are returned in file order, `POINTS` of them. Non-finite points
/// (PCL writes NaN for "no return") are kept as they are; the consumer
/// decides what they mean. Float64 coordinates are rounded to `f32`.
///
/// When the header's `VIEWPOINT` (the sensor's pose `tx ty tz qw qx qy qz`
/// in the frame of the stored points) is not the identity, the points are
/// moved into the sensor frame: `p_sensor = q⁻¹ (p − t)`.
///
/// # Errors
///
/// Every error names the file:
/// * [`IoError::Io`]: the file cannot be read;
/// * [`IoError::NotRegular`], [`IoError::TooLarge`]: the path is a FIFO,
///   a device or a folder, or a file of more than
///   [`MAX_CLOUD_BYTES`](crate::files::MAX_CLOUD_BYTES);
/// * [`IoError::PcdHeader`]: the header is malformed or inconsistent
///   (no `DATA` line, `FIELDS`/`SIZE`/`TYPE`/`COUNT` of different lengths,
///   a bad number, `WIDTH × HEIGHT ≠ POINTS`, a repeated keyword, binary
///   data longer than `POINTS` points, ...);
/// * [`IoError::PcdField`]: `x`, `y` or `z` is missing or not `F4`/`F8`;
/// * [`IoError::PcdUnsupportedData`]: `DATA` is neither `ascii` nor
///   `binary` (e.g. `binary_compressed`);
/// * [`IoError::Truncated`]: binary data shorter than
///   `POINTS × point size`;
/// * [`IoError::PcdAscii`]: in ascii data, a bad number in `x`, `y` or `z`,
///   a line with the wrong number of values, or fewer or more lines than
///   `POINTS`.
pub fn read_pcd(path: &Path) -> Result<PointCloud, IoError> {
    let bytes = crate::files::read_input(path, crate::files::MAX_CLOUD_BYTES)?;
    parse_pcd(path, &bytes)
}

/// How the points are stored after the header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Binary,
}

/// One field of a point, as the header describes it.
#[derive(Debug)]
struct Field<'a> {
    name: &'a str,
    size: usize,
    kind: char,
    count: usize,
}

/// Where a coordinate field lies in a point.
#[derive(Debug, Clone, Copy)]
struct Coord {
    /// Byte offset in a binary point.
    offset: usize,
    /// Value index in an ascii line.
    column: usize,
    /// 4 or 8.
    size: usize,
}

/// The parsed header.
#[derive(Debug)]
struct Header {
    /// `x`, `y`, `z`.
    coords: [Coord; 3],
    /// Bytes per binary point.
    point_size: usize,
    /// Values per ascii line.
    values_per_point: usize,
    points: usize,
    viewpoint: [f64; 7],
    encoding: Encoding,
    /// Offset of the first data byte.
    data_start: usize,
    /// Number of header lines (the DATA line included).
    header_lines: usize,
}

const IDENTITY_VIEWPOINT: [f64; 7] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];

/// Parses the bytes of a PCD file (see [`read_pcd`]); `path` only names
/// it in errors.
pub fn parse_pcd(path: &Path, bytes: &[u8]) -> Result<PointCloud, IoError> {
    let header = parse_header(path, bytes)?;
    let data = bytes.get(header.data_start..).unwrap_or(&[]);
    let mut points = match header.encoding {
        Encoding::Binary => read_binary(path, &header, data)?,
        Encoding::Ascii => read_ascii(path, &header, data)?,
    };
    if header.viewpoint != IDENTITY_VIEWPOINT {
        to_sensor_frame(&header.viewpoint, &mut points);
    }
    Ok(PointCloud { points })
}

fn header_err(path: &Path, reason: impl Into<String>) -> IoError {
    IoError::PcdHeader { path: path.into(), reason: reason.into() }
}

/// The values of each keyword of the header, before interpretation.
#[derive(Default)]
struct RawHeader<'a> {
    version: Option<Vec<&'a str>>,
    fields: Option<Vec<&'a str>>,
    size: Option<Vec<&'a str>>,
    kind: Option<Vec<&'a str>>,
    count: Option<Vec<&'a str>>,
    width: Option<Vec<&'a str>>,
    height: Option<Vec<&'a str>>,
    viewpoint: Option<Vec<&'a str>>,
    points: Option<Vec<&'a str>>,
}

/// The header's last line: `DATA <value>`.
struct DataLine<'a> {
    value: &'a str,
    /// Offset of the first data byte.
    start: usize,
    /// Number of header lines, this one included.
    lines: usize,
}

/// Parses the header: each step checks one part, in the order the errors
/// are reported (keywords, DATA, VERSION, fields, x/y/z, point count,
/// viewpoint).
fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, IoError> {
    let (raw, data) = read_keywords(path, bytes)?;
    let encoding = Encoding::parse(path, data.value)?;
    check_version(path, raw.version.as_deref())?;
    let fields = parse_fields(path, &raw)?;
    let layout = Layout::of(path, &fields)?;
    let points = point_count(path, &raw)?;
    let viewpoint = parse_viewpoint(path, raw.viewpoint.as_deref())?;
    Ok(Header {
        coords: layout.coords,
        point_size: layout.point_size,
        values_per_point: layout.values_per_point,
        points,
        viewpoint,
        encoding,
        data_start: data.start,
        header_lines: data.lines,
    })
}

/// Reads the header's lines up to DATA, each keyword's values unparsed;
/// comments and blank lines are skipped.
fn read_keywords<'a>(path: &Path, bytes: &'a [u8]) -> Result<(RawHeader<'a>, DataLine<'a>), IoError> {
    let mut raw = RawHeader::default();
    let mut pos = 0;
    let mut line_no = 0;
    loop {
        if pos >= bytes.len() {
            return Err(header_err(path, "no DATA line"));
        }
        let end = bytes[pos..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |n| pos + n);
        let next = (end + 1).min(bytes.len());
        line_no += 1;
        let line = std::str::from_utf8(&bytes[pos..end])
            .map_err(|_| header_err(path, format!("line {line_no} is not text (no DATA line before it)")))?;
        pos = next;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut tokens = line.split_ascii_whitespace();
        let keyword = tokens.next().unwrap_or_default();
        let values: Vec<&str> = tokens.collect();
        if keyword == "DATA" {
            return match values.as_slice() {
                [v] => Ok((raw, DataLine { value: v, start: next, lines: line_no })),
                _ => Err(header_err(path, format!("line {line_no}: DATA needs one value, got {values:?}"))),
            };
        }
        raw.set(path, line_no, keyword, values)?;
    }
}

impl<'a> RawHeader<'a> {
    /// Keeps the values of one keyword line; unknown and repeated keywords
    /// are refused.
    fn set(&mut self, path: &Path, line_no: usize, keyword: &str, values: Vec<&'a str>) -> Result<(), IoError> {
        let slot = match keyword {
            "VERSION" => &mut self.version,
            "FIELDS" | "COLUMNS" => &mut self.fields,
            "SIZE" => &mut self.size,
            "TYPE" => &mut self.kind,
            "COUNT" => &mut self.count,
            "WIDTH" => &mut self.width,
            "HEIGHT" => &mut self.height,
            "VIEWPOINT" => &mut self.viewpoint,
            "POINTS" => &mut self.points,
            _ => {
                let shown: String = keyword.chars().take(40).collect();
                return Err(header_err(path, format!("line {line_no}: unknown keyword {shown:?}")));
            }
        };
        if slot.is_some() {
            return Err(header_err(path, format!("line {line_no}: {keyword} given twice")));
        }
        *slot = Some(values);
        Ok(())
    }
}

impl Encoding {
    /// The encoding a DATA line names.
    fn parse(path: &Path, value: &str) -> Result<Self, IoError> {
        match value {
            "ascii" => Ok(Encoding::Ascii),
            "binary" => Ok(Encoding::Binary),
            other => Err(IoError::PcdUnsupportedData { path: path.into(), encoding: other.chars().take(40).collect() }),
        }
    }
}

/// VERSION is optional; its value is not interpreted.
fn check_version(path: &Path, version: Option<&[&str]>) -> Result<(), IoError> {
    match version {
        Some(v) if v.len() != 1 => Err(header_err(path, format!("VERSION needs one value, got {v:?}"))),
        _ => Ok(()),
    }
}

/// The fields from FIELDS, SIZE, TYPE and COUNT (default: 1 each), which
/// must list as many values.
fn parse_fields<'a>(path: &Path, raw: &RawHeader<'a>) -> Result<Vec<Field<'a>>, IoError> {
    let names = raw.fields.as_deref().ok_or_else(|| header_err(path, "no FIELDS line"))?;
    if names.is_empty() {
        return Err(header_err(path, "FIELDS lists no field"));
    }
    let sizes = raw.size.as_deref().ok_or_else(|| header_err(path, "no SIZE line"))?;
    let kinds = raw.kind.as_deref().ok_or_else(|| header_err(path, "no TYPE line"))?;
    let ones = vec!["1"; names.len()];
    let counts = raw.count.as_deref().unwrap_or(&ones);
    for (keyword, list) in [("SIZE", sizes), ("TYPE", kinds), ("COUNT", counts)] {
        if list.len() != names.len() {
            return Err(header_err(
                path,
                format!(
                    "FIELDS lists {} fields ({}) but {keyword} has {} values",
                    names.len(),
                    names.join(" "),
                    list.len()
                ),
            ));
        }
    }
    names
        .iter()
        .zip(sizes)
        .zip(kinds)
        .zip(counts)
        .map(|(((name, size), kind), count)| Field::parse(path, name, size, kind, count))
        .collect()
}

impl<'a> Field<'a> {
    /// One field from its SIZE, TYPE and COUNT values.
    fn parse(path: &Path, name: &'a str, size: &str, kind: &str, count: &str) -> Result<Self, IoError> {
        let size = positive(size)
            .ok_or_else(|| header_err(path, format!("SIZE of field {name}: {size:?} is not a positive integer")))?;
        let count = positive(count)
            .ok_or_else(|| header_err(path, format!("COUNT of field {name}: {count:?} is not a positive integer")))?;
        let kind = match kind {
            "F" => 'F',
            "I" => 'I',
            "U" => 'U',
            _ => return Err(header_err(path, format!("TYPE of field {name}: {kind:?} is not F, I or U"))),
        };
        Ok(Field { name, size, kind, count })
    }

    /// Refuses a coordinate field stored other than as one float32 or
    /// float64.
    fn check_coordinate(&self, path: &Path) -> Result<(), IoError> {
        let field_err = |reason: String| IoError::PcdField { path: path.into(), field: self.name.into(), reason };
        if self.kind != 'F' || !(self.size == 4 || self.size == 8) {
            return Err(field_err(format!(
                "TYPE {} SIZE {} is not supported (expected F 4 or F 8)",
                self.kind, self.size
            )));
        }
        if self.count != 1 {
            return Err(field_err(format!("COUNT {} is not supported (expected 1)", self.count)));
        }
        Ok(())
    }
}

/// Where x, y and z lie in a point, and how big a point is.
struct Layout {
    coords: [Coord; 3],
    /// Bytes per binary point.
    point_size: usize,
    /// Values per ascii line.
    values_per_point: usize,
}

impl Layout {
    /// The layout of `fields`, which must hold x, y and z once each.
    fn of(path: &Path, fields: &[Field<'_>]) -> Result<Self, IoError> {
        let mut point_size = 0usize;
        let mut values_per_point = 0usize;
        let mut coords: [Option<Coord>; 3] = [None; 3];
        for field in fields {
            if let Some(axis) = AXES.iter().position(|&n| n == field.name) {
                if coords[axis].is_some() {
                    return Err(IoError::PcdField {
                        path: path.into(),
                        field: field.name.into(),
                        reason: "listed twice in FIELDS".into(),
                    });
                }
                field.check_coordinate(path)?;
                coords[axis] = Some(Coord { offset: point_size, column: values_per_point, size: field.size });
            }
            point_size = field
                .size
                .checked_mul(field.count)
                .and_then(|n| point_size.checked_add(n))
                .ok_or_else(|| header_err(path, format!("point size overflows at field {}", field.name)))?;
            values_per_point = values_per_point
                .checked_add(field.count)
                .ok_or_else(|| header_err(path, format!("values per point overflow at field {}", field.name)))?;
        }
        let names: Vec<&str> = fields.iter().map(|f| f.name).collect();
        let found = |axis: usize| {
            coords[axis].ok_or_else(|| IoError::PcdField {
                path: path.into(),
                field: AXES[axis].into(),
                reason: format!("missing (FIELDS: {})", names.join(" ")),
            })
        };
        Ok(Layout { coords: [found(0)?, found(1)?, found(2)?], point_size, values_per_point })
    }
}

/// The coordinate fields, in order.
const AXES: [&str; 3] = ["x", "y", "z"];

/// The value of a keyword that takes one non-negative integer, if given.
fn single_count(path: &Path, keyword: &str, values: Option<&[&str]>) -> Result<Option<usize>, IoError> {
    match values {
        None => Ok(None),
        Some([v]) => v
            .parse::<usize>()
            .map(Some)
            .map_err(|_| header_err(path, format!("{keyword}: {v:?} is not a non-negative integer"))),
        Some(v) => Err(header_err(path, format!("{keyword} needs one value, got {v:?}"))),
    }
}

/// The number of points: POINTS, or WIDTH × HEIGHT (HEIGHT 1 by default),
/// which must agree when both are given.
fn point_count(path: &Path, raw: &RawHeader<'_>) -> Result<usize, IoError> {
    let width = single_count(path, "WIDTH", raw.width.as_deref())?;
    let height = single_count(path, "HEIGHT", raw.height.as_deref())?;
    let declared = single_count(path, "POINTS", raw.points.as_deref())?;
    let grid = match width {
        Some(w) => Some(
            w.checked_mul(height.unwrap_or(1))
                .ok_or_else(|| header_err(path, format!("WIDTH {w} × HEIGHT {} overflows", height.unwrap_or(1))))?,
        ),
        None => None,
    };
    match (declared, grid) {
        (Some(p), Some(g)) if p != g => Err(header_err(
            path,
            format!("POINTS {p} differs from WIDTH {} × HEIGHT {} = {g}", width.unwrap_or(0), height.unwrap_or(1)),
        )),
        (Some(p), _) => Ok(p),
        (None, Some(g)) => Ok(g),
        (None, None) => Err(header_err(path, "neither POINTS nor WIDTH given")),
    }
}

/// The sensor's pose `tx ty tz qw qx qy qz` (identity when not given): finite
/// numbers, a quaternion with a direction.
fn parse_viewpoint(path: &Path, values: Option<&[&str]>) -> Result<[f64; 7], IoError> {
    let v = match values {
        None => return Ok(IDENTITY_VIEWPOINT),
        Some(v) if v.len() == 7 => v,
        Some(v) => {
            return Err(header_err(path, format!("VIEWPOINT needs 7 values (tx ty tz qw qx qy qz), got {}", v.len())))
        }
    };
    let mut vp = [0.0; 7];
    for (out, s) in vp.iter_mut().zip(v) {
        *out = s
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| header_err(path, format!("VIEWPOINT: {s:?} is not a finite number")))?;
    }
    let qn = vp[3..].iter().map(|q| q * q).sum::<f64>().sqrt();
    if !(qn > 1e-6 && qn.is_finite()) {
        return Err(header_err(path, format!("VIEWPOINT: quaternion {:?} has no direction", &vp[3..])));
    }
    Ok(vp)
}

fn positive(s: &str) -> Option<usize> {
    s.parse::<usize>().ok().filter(|&n| n > 0)
}

fn read_binary(path: &Path, header: &Header, data: &[u8]) -> Result<Vec<[f32; 3]>, IoError> {
    let expected = header.points.checked_mul(header.point_size).ok_or_else(|| {
        header_err(path, format!("POINTS {} × point size {} bytes overflows", header.points, header.point_size))
    })?;
    if data.len() < expected {
        return Err(IoError::Truncated { path: path.into(), expected: expected as u64, actual: data.len() as u64 });
    }
    if data.len() > expected {
        return Err(header_err(
            path,
            format!(
                "POINTS {} × {} bytes a point is {expected} bytes of binary data, the file has {} ({} bytes past the last point)",
                header.points,
                header.point_size,
                data.len(),
                data.len() - expected
            ),
        ));
    }
    if header.points == 0 {
        return Ok(Vec::new());
    }
    let read = |point: &[u8], c: Coord| -> f32 {
        let bytes = &point[c.offset..c.offset + c.size];
        match bytes.try_into() {
            Ok(b4) => f32::from_le_bytes(b4),
            Err(_) => bytes.try_into().map_or(f32::NAN, |b8| f64::from_le_bytes(b8) as f32),
        }
    };
    let [cx, cy, cz] = header.coords;
    Ok(data[..expected].chunks_exact(header.point_size).map(|p| [read(p, cx), read(p, cy), read(p, cz)]).collect())
}

fn read_ascii(path: &Path, header: &Header, data: &[u8]) -> Result<Vec<[f32; 3]>, IoError> {
    // A value takes at least two bytes with its separator: no bogus POINTS
    // can make this allocate much more than the file.
    let mut points = Vec::with_capacity(header.points.min(data.len() / 2 + 1));
    let mut line_no = header.header_lines;
    let mut tokens: Vec<&[u8]> = Vec::with_capacity(header.values_per_point.min(4096));
    for line in data.split(|&b| b == b'\n') {
        if points.len() == header.points {
            break;
        }
        line_no += 1;
        tokens.clear();
        tokens.extend(line.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty()));
        if tokens.is_empty() {
            continue;
        }
        if tokens.len() != header.values_per_point {
            return Err(IoError::PcdAscii {
                path: path.into(),
                line: line_no,
                reason: format!("expected {} values, found {}", header.values_per_point, tokens.len()),
            });
        }
        let mut p = [0.0f32; 3];
        for (axis, (out, c)) in p.iter_mut().zip(header.coords).enumerate() {
            let tok = tokens[c.column];
            *out = std::str::from_utf8(tok).ok().and_then(|s| s.parse::<f32>().ok()).ok_or_else(|| {
                let shown: String = String::from_utf8_lossy(tok).chars().take(40).collect();
                IoError::PcdAscii {
                    path: path.into(),
                    line: line_no,
                    reason: format!("field {}: {shown:?} is not a number", ["x", "y", "z"][axis]),
                }
            })?;
        }
        points.push(p);
    }
    if points.len() < header.points {
        return Err(IoError::PcdAscii {
            path: path.into(),
            line: line_no,
            reason: format!("the header promises {} points, the data has {}", header.points, points.len()),
        });
    }
    refuse_extra_lines(path, header, data, line_no)?;
    Ok(points)
}

/// Refuses ascii data with points after the `POINTS` the header promises
/// (`line_no` is the line of the last one read); blank lines may follow.
fn refuse_extra_lines(path: &Path, header: &Header, data: &[u8], line_no: usize) -> Result<(), IoError> {
    let mut lines = data.split(|&b| b == b'\n').enumerate().skip(line_no - header.header_lines);
    let Some((first, _)) = lines.find(|(_, l)| l.iter().any(|b| !b.is_ascii_whitespace())) else { return Ok(()) };
    let extra = 1 + lines.filter(|(_, l)| l.iter().any(|b| !b.is_ascii_whitespace())).count();
    Err(IoError::PcdAscii {
        path: path.into(),
        line: header.header_lines + first + 1,
        reason: format!(
            "POINTS is {0} but the data has {1} lines of points ({extra} past the first {0})",
            header.points,
            header.points + extra
        ),
    })
}

/// Moves points given in the viewpoint's frame into the sensor frame:
/// `p_sensor = q⁻¹ (p − t)`, `q` normalised.
fn to_sensor_frame(viewpoint: &[f64; 7], points: &mut [[f32; 3]]) {
    let [tx, ty, tz, qw, qx, qy, qz] = *viewpoint;
    let n = (qw * qw + qx * qx + qy * qy + qz * qz).sqrt();
    // The inverse rotation: the conjugate of the unit quaternion.
    let (w, u) = (qw / n, [-qx / n, -qy / n, -qz / n]);
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    for p in points {
        let v = [f64::from(p[0]) - tx, f64::from(p[1]) - ty, f64::from(p[2]) - tz];
        // v' = v + 2w (u × v) + 2 u × (u × v)
        let c1 = cross(u, v);
        let c2 = cross(u, c1);
        for k in 0..3 {
            p[k] = (v[k] + 2.0 * w * c1[k] + 2.0 * c2[k]) as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};
    use std::path::PathBuf;

    /// The real scan shipped in the repository's `data/`, relative to this crate.
    const REAL_SCAN: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/velodyne-pair/251370668.pcd");

    fn name() -> PathBuf {
        PathBuf::from("cloud.pcd")
    }

    fn header(fields: &str, size: &str, kind: &str, count: &str, points: usize, data: &str) -> String {
        format!(
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {kind}\nCOUNT {count}\n\
             WIDTH {points}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA {data}\n"
        )
    }

    /// A binary file with fields `x y z intensity` (F4 each) of `points`.
    fn binary_xyzi(points: &[[f32; 4]]) -> Vec<u8> {
        let mut bytes = header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", points.len(), "binary").into_bytes();
        for p in points {
            for v in p {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        bytes
    }

    fn message(e: &IoError) -> String {
        e.to_string()
    }

    #[test]
    fn reads_the_real_scan() {
        let path = PathBuf::from(REAL_SCAN);
        let bytes = std::fs::read(&path).expect("readable");
        let head = String::from_utf8_lossy(&bytes[..400.min(bytes.len())]).into_owned();
        let declared: usize = head
            .lines()
            .find_map(|l| l.strip_prefix("POINTS "))
            .and_then(|n| n.trim().parse().ok())
            .expect("POINTS line");
        let cloud = read_pcd(&path).expect("valid PCD");
        assert_eq!(cloud.points.len(), declared);
        assert!(declared > 60_000, "{declared} points");
        let finite: Vec<&[f32; 3]> = cloud.points.iter().filter(|p| p.iter().all(|v| v.is_finite())).collect();
        assert!(finite.len() * 10 >= cloud.points.len() * 9, "{} of {} finite", finite.len(), cloud.points.len());
        let ranges: Vec<f32> = finite.iter().map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()).collect();
        let max = ranges.iter().copied().fold(0.0f32, f32::max);
        assert!(max < 200.0 && max > 10.0, "max range {max} m");
        let near = ranges.iter().filter(|&&r| r < 100.0).count();
        assert!(near * 10 >= ranges.len() * 9, "{near} of {} within 100 m", ranges.len());
        // The byte layout: the first point is the first 12 data bytes.
        let data_start = bytes.len() - declared * 16;
        let x0 = f32::from_le_bytes(bytes[data_start..data_start + 4].try_into().expect("4 bytes"));
        assert_eq!(cloud.points[0][0].to_bits(), x0.to_bits());
    }

    #[test]
    fn reads_binary_f4_and_skips_other_fields() {
        let pts = [[1.0, 2.0, 3.0, 0.5], [-4.5, 0.25, 1e3, 7.0], [f32::NAN, f32::NAN, f32::NAN, 0.0]];
        let cloud = parse_pcd(&name(), &binary_xyzi(&pts)).expect("valid");
        assert_eq!(cloud.points.len(), 3);
        assert_eq!(cloud.points[0], [1.0, 2.0, 3.0]);
        assert_eq!(cloud.points[1], [-4.5, 0.25, 1e3]);
        assert!(cloud.points[2].iter().all(|v| v.is_nan()), "NaN kept");
    }

    #[test]
    fn reads_an_ascii_file_written_here() {
        let text = "# written by the test\r\nVERSION .7\r\nFIELDS rgb x normal y z label\r\nSIZE 4 4 4 4 4 2\r\n\
                    TYPE U F F F F I\r\nCOUNT 1 1 3 1 1 2\r\nWIDTH 2\r\nHEIGHT 2\r\nVIEWPOINT 0 0 0 1 0 0 0\r\nPOINTS 4\r\nDATA ascii\r\n\
                    4286611584 1.5 0 0 1 -2.25 3 7 -1\r\n\
                    0 nan 0.1 0.2 0.3 nan nan 0 0\r\n\
                    \r\n\
                    1 1e2 x y z 2 3.5 0 0\r\n\
                    2 -0.001 0 0 0 4e-1 -5 1 1\r\n";
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("written.pcd");
        std::fs::write(&path, text).expect("write");
        let cloud = read_pcd(&path).expect("valid ascii PCD");
        assert_eq!(cloud.points.len(), 4);
        assert_eq!(cloud.points[0], [1.5, -2.25, 3.0]);
        assert!(cloud.points[1].iter().all(|v| v.is_nan()));
        assert_eq!(cloud.points[2], [100.0, 2.0, 3.5]);
        assert_eq!(cloud.points[3], [-0.001, 0.4, -5.0]);
    }

    #[test]
    fn reads_f8_coordinates_binary_and_ascii() {
        let pts: [[f64; 3]; 3] = [[0.1, -20.5, 3.0e1], [1.0 / 3.0, 1e-7, -123.456], [f64::NAN, f64::INFINITY, 0.0]];
        // Binary: x y z F8, then a U1 × 3 field (odd size: no alignment).
        let mut bytes = header("x y z rgb", "8 8 8 1", "F F F U", "1 1 1 3", pts.len(), "binary").into_bytes();
        for p in &pts {
            for v in p {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            bytes.extend_from_slice(&[1, 2, 3]);
        }
        let cloud = parse_pcd(&name(), &bytes).expect("valid");
        assert_eq!(cloud.points.len(), 3);
        for (got, want) in cloud.points.iter().zip(&pts).take(2) {
            assert_eq!(*got, [want[0] as f32, want[1] as f32, want[2] as f32]);
        }
        assert!(cloud.points[2][0].is_nan() && cloud.points[2][1] == f32::INFINITY);

        let mut text = header("z y x", "8 8 8", "F F F", "1 1 1", 2, "ascii");
        text.push_str("0.5 0.25 0.125\n1e300 -1 2\n");
        let cloud = parse_pcd(&name(), text.as_bytes()).expect("valid");
        assert_eq!(cloud.points[0], [0.125, 0.25, 0.5]);
        assert_eq!(cloud.points[1], [2.0, -1.0, f32::INFINITY]);
    }

    #[test]
    fn reads_old_headers_without_count_viewpoint_or_points() {
        let text = "VERSION .6\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 1\nDATA ascii\n1 2 3\n4 5 6\n";
        let cloud = parse_pcd(&name(), text.as_bytes()).expect("valid");
        assert_eq!(cloud.points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        let text = "COLUMNS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2 3\n";
        assert_eq!(parse_pcd(&name(), text.as_bytes()).expect("valid").points, vec![[1.0, 2.0, 3.0]]);
        let empty = header("x y z", "4 4 4", "F F F", "1 1 1", 0, "binary");
        assert!(parse_pcd(&name(), empty.as_bytes()).expect("valid").points.is_empty());
    }

    #[test]
    fn viewpoint_moves_points_into_the_sensor_frame() {
        // Sensor at (1, 2, 3), turned 90° about z: the stored point
        // (1, 3, 3) lies 1 m along the sensor's x axis.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let text = format!(
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nVIEWPOINT 1 2 3 {h} 0 0 {h}\nPOINTS 1\nDATA ascii\n1 3 3\n"
        );
        let p = parse_pcd(&name(), text.as_bytes()).expect("valid").points[0];
        for (got, want) in p.iter().zip([1.0, 0.0, 0.0]) {
            assert!((got - want).abs() < 1e-6, "{p:?}");
        }
    }

    #[test]
    fn errors_name_the_file_and_the_problem() {
        let path = PathBuf::from("/data/scan 7.pcd");
        let check = |bytes: &[u8], want: &[&str]| -> IoError {
            let e = parse_pcd(&path, bytes).expect_err("must fail");
            let m = message(&e);
            assert!(m.contains("/data/scan 7.pcd"), "{m}");
            for w in want {
                assert!(m.contains(w), "{m:?} lacks {w:?}");
            }
            e
        };
        // Missing z.
        let e = check(
            header("x y intensity", "4 4 4", "F F F", "1 1 1", 0, "binary").as_bytes(),
            &["field z", "missing", "x y intensity"],
        );
        assert!(matches!(e, IoError::PcdField { ref field, .. } if field == "z"));
        // Unsupported encodings.
        let e = check(
            header("x y z", "4 4 4", "F F F", "1 1 1", 1, "binary_compressed").as_bytes(),
            &["binary_compressed", "not supported"],
        );
        assert!(matches!(e, IoError::PcdUnsupportedData { .. }));
        check(header("x y z", "4 4 4", "F F F", "1 1 1", 1, "hex").as_bytes(), &["DATA hex"]);
        // Truncated binary data: 3 points of 16 bytes promised, 47 given.
        let mut bytes = binary_xyzi(&[[1.0; 4]; 3]);
        bytes.pop();
        let e = check(&bytes, &["truncated", "48", "47"]);
        assert!(matches!(e, IoError::Truncated { expected: 48, actual: 47, .. }));
        // Inconsistent header lengths.
        for (fields, size, kind, count, what) in [
            ("x y z i", "4 4 4", "F F F F", "1 1 1 1", "SIZE has 3"),
            ("x y z i", "4 4 4 4", "F F F", "1 1 1 1", "TYPE has 3"),
            ("x y z i", "4 4 4 4", "F F F F", "1 1 1 1 1", "COUNT has 5"),
        ] {
            let e = check(header(fields, size, kind, count, 1, "binary").as_bytes(), &[what, "4 fields"]);
            assert!(matches!(e, IoError::PcdHeader { .. }));
        }
        // Bad header values.
        check(header("x y z", "4 4 four", "F F F", "1 1 1", 1, "ascii").as_bytes(), &["SIZE of field z", "four"]);
        check(header("x y z", "4 4 4", "F F D", "1 1 1", 1, "ascii").as_bytes(), &["TYPE of field z", "\"D\""]);
        check(header("x y z", "4 4 4", "F F F", "1 0 1", 1, "ascii").as_bytes(), &["COUNT of field y", "\"0\""]);
        check(header("x y z", "4 2 4", "F I F", "1 1 1", 1, "ascii").as_bytes(), &["field y", "TYPE I SIZE 2"]);
        check(header("x y z", "4 4 4", "F F F", "1 3 1", 1, "ascii").as_bytes(), &["field y", "COUNT 3"]);
        check(header("x y x", "4 4 4", "F F F", "1 1 1", 1, "ascii").as_bytes(), &["field x", "twice"]);
        check(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nPOINTS 2\nDATA ascii\n", &["POINTS 2", "WIDTH 3"]);
        check(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS -1\nDATA ascii\n", &["POINTS", "\"-1\""]);
        check(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nDATA ascii\n", &["neither POINTS nor WIDTH"]);
        check(b"FIELDS x y z\nFIELDS x y z\nDATA ascii\n", &["line 2", "FIELDS given twice"]);
        check(
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nVIEWPOINT 0 0 0 1 0 0\nDATA ascii\n",
            &["VIEWPOINT needs 7"],
        );
        check(
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nVIEWPOINT 0 0 0 0 0 0 0\nDATA ascii\n",
            &["quaternion"],
        );
        check(b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\n", &["no DATA line"]);
        check(b"P6\n640 480\n255\n", &["line 1", "unknown keyword \"P6\""]);
        check(b"\x89PNG\r\n\x1a\n\0\0", &["line 1 is not text"]);
        check(b"", &["no DATA line"]);
        check(b"FIELDS x y z\n\xff\xfe\nDATA ascii\n", &["line 2 is not text"]);
        // Ascii data problems: bad numbers, wrong value counts, too few lines.
        let ascii = header("x y z i", "4 4 4 4", "F F F U", "1 1 1 1", 2, "ascii");
        let e = check(
            format!("{ascii}1 2 3 4\n1 2.5.1 3 junk\n").as_bytes(),
            &["line 13", "field y", "\"2.5.1\"", "not a number"],
        );
        assert!(matches!(e, IoError::PcdAscii { line: 13, .. }));
        check(format!("{ascii}1 2 3 4\n1 2 3\n").as_bytes(), &["line 13", "expected 4 values, found 3"]);
        check(format!("{ascii}1 2 3 4\n").as_bytes(), &["promises 2 points", "has 1"]);
        check(format!("{ascii}1 2 3 4\n\u{e9} 2 3 4\n").as_bytes(), &["field x"]);
    }

    #[test]
    fn read_pcd_reports_missing_files() {
        let e = read_pcd(Path::new("/nonexistent/dir/none.pcd")).expect_err("no such file");
        assert!(matches!(e, IoError::Io { .. }));
        assert!(message(&e).contains("/nonexistent/dir/none.pcd"));
    }

    /// Random bytes, and valid files with random damage, never panic.
    #[test]
    fn never_panics_on_random_or_mutated_input() {
        let mut rng = StdRng::seed_from_u64(0x5eed_0bcd);
        let mut seeds: Vec<Vec<u8>> = vec![
            binary_xyzi(&[[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0], [f32::NAN; 4]]),
            {
                let mut t = header("rgb x y z n", "4 8 4 8 2", "U F F F I", "1 1 1 1 3", 3, "ascii");
                t.push_str("1 2 3 4 5 6 7\n0 nan inf -inf 1 2 3\n9 1e3 2e-3 -0 0 0 0\n");
                t.into_bytes()
            },
            b"VERSION .6\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n1 2 3\n".to_vec(),
        ];
        if let Ok(bytes) = std::fs::read(REAL_SCAN) {
            // The real header, cut down to its first 200 points.
            let text = String::from_utf8_lossy(&bytes[..bytes.len().min(400)]).into_owned();
            if let Some(end) = text.find("DATA binary\n").map(|n| n + "DATA binary\n".len()) {
                let declared = text.lines().find_map(|l| l.strip_prefix("POINTS ")).unwrap_or("0").to_string();
                let head = text[..end].replace(&declared, "200");
                let mut seed = head.into_bytes();
                seed.extend_from_slice(&bytes[end..(end + 200 * 16).min(bytes.len())]);
                seeds.push(seed);
            }
        }
        let nasty: [&[u8]; 14] = [
            b"18446744073709551615",
            b"9223372036854775807",
            b"4294967296",
            b"0",
            b"-1",
            b"nan",
            b"1e309",
            b"\n",
            b"DATA binary\n",
            b"DATA ascii\n",
            b"COUNT 1 1 1 1\n",
            b"\xff",
            b" ",
            b"POINTS 99999999999999\n",
        ];
        let path = name();
        let (mut parsed, mut refused) = (0, 0);
        for i in 0..20_000 {
            let bytes: Vec<u8> = if i % 10 == 0 {
                let n = rng.random_range(0..512);
                (0..n).map(|_| rng.random::<u8>()).collect()
            } else {
                let mut b = seeds[i % seeds.len()].clone();
                for _ in 0..rng.random_range(1..4) {
                    let at = rng.random_range(0..=b.len());
                    match rng.random_range(0..5) {
                        0 if at < b.len() => b[at] = rng.random(),
                        1 => b.truncate(at),
                        2 => {
                            let end = (at + rng.random_range(0..16)).min(b.len());
                            b.drain(at..end);
                        }
                        3 => {
                            let piece = nasty[rng.random_range(0..nasty.len())];
                            b.splice(at..at, piece.iter().copied());
                        }
                        _ => {
                            // Replace a header token by a nasty one.
                            let end = b[at..].iter().position(|c| c.is_ascii_whitespace()).map_or(b.len(), |n| at + n);
                            let piece = nasty[rng.random_range(0..nasty.len())];
                            b.splice(at..end, piece.iter().copied());
                        }
                    }
                }
                b
            };
            // Errors are fine; a panic fails the test.
            match parse_pcd(&path, &bytes) {
                Ok(_) => parsed += 1,
                Err(_) => refused += 1,
            }
        }
        // Both outcomes are reached often: the mutations exercise the
        // data readers, not only the header checks.
        assert!(parsed > 1000 && refused > 1000, "{parsed} parsed, {refused} refused");
    }
}
