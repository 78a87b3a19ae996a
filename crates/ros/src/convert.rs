//! Sensor messages as edtmap measurements, with every length and offset
//! checked against the message's own bytes.

use super::msg::{Image, LaserScanMsg, PointCloud2, PointField};
use edtmap_core::sensor::{DepthData, DepthImage, LaserScan, PointCloud, RangeLimits};

/// Bytes of a `PointField` datatype, or `None` for an unknown code.
fn datatype_size(code: u8) -> Option<usize> {
    match code {
        1 | 2 => Some(1),
        3 | 4 => Some(2),
        5..=7 => Some(4),
        8 => Some(8),
        _ => None,
    }
}

/// Reads one value of `code` from `b` (exactly its size) as f64.
fn read_value(code: u8, b: &[u8], big_endian: bool) -> f64 {
    let mut buf = [0u8; 8];
    buf[..b.len()].copy_from_slice(b);
    if big_endian {
        buf[..b.len()].reverse();
    }
    let arr4 = [buf[0], buf[1], buf[2], buf[3]];
    match code {
        1 => f64::from(buf[0] as i8),
        2 => f64::from(buf[0]),
        3 => f64::from(i16::from_le_bytes([buf[0], buf[1]])),
        4 => f64::from(u16::from_le_bytes([buf[0], buf[1]])),
        5 => f64::from(i32::from_le_bytes(arr4)),
        6 => f64::from(u32::from_le_bytes(arr4)),
        7 => f64::from(f32::from_le_bytes(arr4)),
        _ => f64::from_le_bytes(buf),
    }
}

impl PointCloud2 {
    /// An unordered cloud of `x y z` float32 points, as drivers publish
    /// them (non-finite points: no return).
    pub fn from_points(header: super::msg::Header, points: &[[f32; 3]]) -> Self {
        PointCloud2::from_f32_fields(header, &["x", "y", "z"], points.as_flattened())
    }

    /// An unordered little-endian cloud of float32 fields named `names`,
    /// one point per `names.len()` entries of `values` (a trailing partial
    /// point is left out); dense when every value is finite.
    pub fn from_f32_fields(header: super::msg::Header, names: &[&str], values: &[f32]) -> Self {
        let n = names.len().max(1);
        let fields = names
            .iter()
            .zip(0..)
            .map(|(name, i)| PointField { name: (*name).into(), offset: 4 * i, datatype: 7, count: 1 })
            .collect();
        let values = &values[..values.len() / n * n];
        let width = u32::try_from(values.len() / n).unwrap_or(u32::MAX);
        let point_step = u32::try_from(4 * n).unwrap_or(u32::MAX);
        PointCloud2 {
            header,
            height: 1,
            width,
            fields,
            is_bigendian: false,
            point_step,
            row_step: width.saturating_mul(point_step),
            data: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
            is_dense: values.iter().all(|v| v.is_finite()),
        }
    }

    fn field(&self, name: &str) -> Result<(&PointField, usize), String> {
        let f = self.fields.iter().find(|f| f.name == name).ok_or_else(|| {
            let names: Vec<&str> = self.fields.iter().map(|f| f.name.as_str()).collect();
            format!("PointCloud2 has no field {name} (fields: {})", names.join(", "))
        })?;
        let size = datatype_size(f.datatype)
            .ok_or_else(|| format!("PointCloud2 field {name}: unknown datatype {}", f.datatype))?;
        if f.offset as usize + size > self.point_step as usize {
            return Err(format!(
                "PointCloud2 field {name}: offset {} + {size} bytes exceeds point_step {}",
                f.offset, self.point_step
            ));
        }
        Ok((f, size))
    }

    /// The cloud's x, y, z in metres; non-finite points (no return) kept as
    /// they are.
    pub fn xyz(&self) -> Result<PointCloud, String> {
        let fields = [self.field("x")?, self.field("y")?, self.field("z")?];
        if self.width == 0 || self.height == 0 {
            return Ok(PointCloud { points: Vec::new() });
        }
        let (h, w, step, row) = (self.height as u64, self.width as u64, self.point_step as u64, self.row_step as u64);
        if w > 0 && row < w * step {
            return Err(format!("PointCloud2 row_step {row} is shorter than width {w} × point_step {step}"));
        }
        let need = if h == 0 || w == 0 { 0 } else { ((h - 1).saturating_mul(row)).saturating_add(w * step) };
        if need > self.data.len() as u64 {
            return Err(format!("PointCloud2 of {h} × {w} points needs {need} bytes of data, has {}", self.data.len()));
        }
        let mut points = Vec::with_capacity((h * w) as usize);
        for r in 0..h as usize {
            for c in 0..w as usize {
                let base = r * row as usize + c * step as usize;
                points.push(fields.map(|(f, size)| {
                    let at = base + f.offset as usize;
                    read_value(f.datatype, &self.data[at..at + size], self.is_bigendian) as f32
                }));
            }
        }
        Ok(PointCloud { points })
    }
}

impl Image {
    /// The image as depths: `16UC1` and `mono16` are raw units of
    /// `metres_per_unit` (0 = no return), `32FC1` is metres (0 or
    /// non-finite = no return).
    pub fn depth(&self, metres_per_unit: f32) -> Result<DepthImage, String> {
        let bytes = match self.encoding.as_str() {
            "16UC1" | "mono16" => 2,
            "32FC1" => 4,
            other => return Err(format!("Image encoding {other:?} is not a depth image (16UC1, mono16 or 32FC1)")),
        };
        let (w, h, step) = (self.width as usize, self.height as usize, self.step as usize);
        if w == 0 || h == 0 {
            return Err(format!("Image of {w} × {h} pixels is empty"));
        }
        if step < w * bytes {
            return Err(format!("Image step {step} is shorter than width {w} × {bytes} bytes"));
        }
        if (step as u64) * (h as u64) > self.data.len() as u64 {
            return Err(format!("Image of {h} rows × {step} bytes needs {} bytes, has {}", step * h, self.data.len()));
        }
        let pixel = |r: usize, c: usize| {
            let at = r * step + c * bytes;
            let mut b = [0u8; 4];
            b[..bytes].copy_from_slice(&self.data[at..at + bytes]);
            if self.is_bigendian {
                b[..bytes].reverse();
            }
            b
        };
        let data = if bytes == 2 {
            let values = (0..h).flat_map(|r| (0..w).map(move |c| (r, c))).map(|(r, c)| {
                let b = pixel(r, c);
                u16::from_le_bytes([b[0], b[1]])
            });
            DepthData::U16 { values: values.collect(), metres_per_unit }
        } else {
            let values = (0..h).flat_map(|r| (0..w).map(move |c| (r, c))).map(|(r, c)| {
                let d = f32::from_le_bytes(pixel(r, c));
                if d > 0.0 && d.is_finite() {
                    d
                } else {
                    f32::NAN
                }
            });
            DepthData::Metres(values.collect())
        };
        Ok(DepthImage { width: self.width, height: self.height, data })
    }
}

impl LaserScanMsg {
    /// The scan with the message's own angles and valid range.
    pub fn scan(&self) -> Result<LaserScan, String> {
        let scan = LaserScan {
            angle_min_rad: f64::from(self.angle_min),
            angle_increment_rad: f64::from(self.angle_increment),
            ranges: self.ranges.clone(),
            range: RangeLimits { min_m: self.range_min, max_m: self.range_max },
        };
        scan.validate().map_err(|e| format!("LaserScan: {e}"))?;
        Ok(scan)
    }
}
