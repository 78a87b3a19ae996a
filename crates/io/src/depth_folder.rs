//! Depth-image folders in the 3DMatch style: `frame-XXXXXX.depth.png`
//! (16-bit depth, 0 = no return), `frame-XXXXXX.pose.txt` (4 × 4 row-major
//! `T_world_camera`, metres, optical axes) and `camera-intrinsics.txt`
//! (3 × 3 K).

use crate::IoError;
use edtmap_core::sensor::{pose_from_matrix, DepthData, DepthImage, Frame, Measurement, PinholeCamera, RangeLimits};
use std::path::{Path, PathBuf};

/// A depth-image folder: its camera and its frames, in file-name order.
#[derive(Debug, Clone)]
pub struct DepthFolder {
    /// The camera: intrinsics from the folder, size from the first image.
    pub camera: PinholeCamera,
    /// `(depth PNG, pose file)` of every frame, sorted.
    pub frames: Vec<(PathBuf, PathBuf)>,
    /// Metres per depth unit (0.001 for millimetres).
    pub metres_per_unit: f32,
}

fn bad(path: &Path, reason: impl Into<String>) -> IoError {
    IoError::Dataset { path: path.to_path_buf(), reason: reason.into() }
}

impl DepthFolder {
    /// Opens `dir`, reading the intrinsics and the first image's size;
    /// `range` bounds the valid depths.
    pub fn open(dir: &Path, metres_per_unit: f32, range: RangeLimits) -> Result<Self, IoError> {
        let entries = std::fs::read_dir(dir).map_err(|e| IoError::io(dir, e))?;
        let mut frames = Vec::new();
        for entry in entries {
            let path = entry.map_err(|e| IoError::io(dir, e))?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if let Some(stem) = name.strip_suffix(".depth.png") {
                let pose = dir.join(format!("{stem}.pose.txt"));
                if !pose.exists() {
                    return Err(bad(&pose, format!("missing: {name} has no pose file")));
                }
                frames.push((path, pose));
            }
        }
        if frames.is_empty() {
            return Err(bad(dir, "no *.depth.png frames"));
        }
        frames.sort();
        let k_path = dir.join("camera-intrinsics.txt");
        let k = read_numbers(&k_path, 9)?;
        let (width, height, _) = read_depth_png(&frames[0].0)?;
        let camera = PinholeCamera { fx: k[0], fy: k[4], cx: k[2], cy: k[5], width, height, range };
        Ok(DepthFolder { camera, frames, metres_per_unit })
    }

    /// Frame `i`: its depth image and pose; the stamp is the frame's index
    /// at 30 Hz, as 3DMatch folders carry no times.
    pub fn frame(&self, i: usize) -> Result<Frame, IoError> {
        let (png, pose_path) = self.frames.get(i).ok_or_else(|| bad(Path::new("."), format!("frame {i} of {}", self.frames.len())))?;
        let (width, height, values) = read_depth_png(png)?;
        if (width, height) != (self.camera.width, self.camera.height) {
            return Err(bad(png, format!("{width} x {height} pixels, the folder's first frame has {} x {}", self.camera.width, self.camera.height)));
        }
        let m = read_numbers(pose_path, 16)?;
        let matrix: [[f64; 4]; 4] = std::array::from_fn(|r| std::array::from_fn(|c| m[4 * r + c]));
        let pose = pose_from_matrix(&matrix).map_err(|e| bad(pose_path, e.to_string()))?;
        let image = DepthImage { width, height, data: DepthData::U16 { values, metres_per_unit: self.metres_per_unit } };
        Ok(Frame { stamp_s: i as f64 / 30.0, t_world_sensor: pose, measurement: Measurement::Depth(image) })
    }
}

/// Exactly `count` whitespace-separated numbers from `path`.
fn read_numbers(path: &Path, count: usize) -> Result<Vec<f64>, IoError> {
    let text = std::fs::read_to_string(path).map_err(|e| IoError::io(path, e))?;
    let mut out = Vec::with_capacity(count);
    for token in text.split_whitespace() {
        out.push(token.parse::<f64>().map_err(|_| bad(path, format!("{token:?} is not a number")))?);
    }
    if out.len() != count {
        return Err(bad(path, format!("expected {count} numbers, found {}", out.len())));
    }
    Ok(out)
}

/// Width, height and values of a 16-bit greyscale PNG.
fn read_depth_png(path: &Path) -> Result<(u32, u32, Vec<u16>), IoError> {
    let file = std::fs::File::open(path).map_err(|e| IoError::io(path, e))?;
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().map_err(|e| bad(path, format!("not a PNG: {e}")))?;
    let info = reader.info();
    let (width, height) = (info.width, info.height);
    if info.color_type != png::ColorType::Grayscale || info.bit_depth != png::BitDepth::Sixteen {
        return Err(bad(path, format!("depth must be 16-bit greyscale, found {:?} {:?}", info.color_type, info.bit_depth)));
    }
    let mut buf = vec![0; reader.output_buffer_size().ok_or_else(|| bad(path, "image too large"))?];
    let frame = reader.next_frame(&mut buf).map_err(|e| bad(path, format!("corrupt PNG data: {e}")))?;
    let values = buf[..frame.buffer_size()].chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
    Ok((width, height, values))
}
