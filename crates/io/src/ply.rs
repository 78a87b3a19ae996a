//! PLY point clouds (binary little-endian, `float x y z` and `uchar red
//! green blue` per vertex), readable by MeshLab, CloudCompare, Open3D and
//! Blender: occupied voxels, and EDT voxels coloured by distance.

use crate::picture::Rgb;
use crate::IoError;
use std::io::Write;
use std::path::Path;

/// One coloured point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColouredPoint {
    /// Position, metres.
    pub xyz: [f32; 3],
    /// Colour.
    pub rgb: Rgb,
}

/// Writes `points` to `path` as a binary PLY; `comment` goes into the
/// header. The file is written next to `path` and renamed into place, so
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
    let tmp = path.with_extension("ply.part");
    std::fs::write(&tmp, &bytes).map_err(|e| IoError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| IoError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_and_body_round_trip() {
        let dir = std::env::temp_dir().join(format!("edtmap-ply-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("p.ply");
        let points = [ColouredPoint { xyz: [1.5, -2.0, 0.25], rgb: [10, 20, 30] }, ColouredPoint { xyz: [0.0, 0.0, 1e6], rgb: [255, 0, 7] }];
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
