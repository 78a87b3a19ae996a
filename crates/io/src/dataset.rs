//! Recordings on disk as frames with poses, for `edtmap run --dataset`.
//!
//! Two layouts so far, told apart by their files:
//! - a 3DMatch-style depth folder (`camera-intrinsics.txt`,
//!   `frame-XXXXXX.depth.png` + `frame-XXXXXX.pose.txt`), read by
//!   [`DepthFolder`];
//! - a folder of point clouds (`*.pcd`, or KITTI Velodyne `*.bin`: float32
//!   x y z reflectance per point, little-endian; in file-name order) with a
//!   `poses.txt` trajectory in the KITTI odometry format: one line per
//!   cloud, the 12 numbers of the row-major 3 × 4 `T_world_sensor`.

use crate::depth_folder::DepthFolder;
use crate::{read_pcd, IoError};
use edtmap_core::sensor::{pose_from_matrix, Frame, Measurement, PointCloud, RangeLimits};
use std::path::{Path, PathBuf};

/// A recording opened for replay.
#[derive(Debug, Clone)]
pub enum Dataset {
    /// Depth images with per-frame poses.
    Depth(DepthFolder),
    /// Point clouds with a KITTI-format trajectory.
    Clouds(CloudFolder),
}

/// Point clouds (`*.pcd` or KITTI `*.bin`) with one pose each from
/// `poses.txt`.
#[derive(Debug, Clone)]
pub struct CloudFolder {
    /// The clouds, in file-name order, with their poses.
    pub frames: Vec<(PathBuf, [[f64; 4]; 4])>,
}

fn bad(path: &Path, reason: impl Into<String>) -> IoError {
    IoError::Dataset { path: path.to_path_buf(), reason: reason.into() }
}

impl Dataset {
    /// Opens the recording at `dir`; `depth_scale_m` is the metres per unit
    /// of 16-bit depth images and `range` the depth camera's valid range.
    pub fn open(dir: &Path, depth_scale_m: f32, range: RangeLimits) -> Result<Self, IoError> {
        if !dir.is_dir() {
            return Err(bad(dir, "not a folder"));
        }
        if dir.join("camera-intrinsics.txt").exists() {
            return Ok(Dataset::Depth(DepthFolder::open(dir, depth_scale_m, range)?));
        }
        if dir.join("poses.txt").exists() {
            return Ok(Dataset::Clouds(CloudFolder::open(dir)?));
        }
        Err(bad(dir, "neither a depth folder (camera-intrinsics.txt) nor point clouds with poses.txt"))
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        match self {
            Dataset::Depth(d) => d.frames.len(),
            Dataset::Clouds(c) => c.frames.len(),
        }
    }

    /// Whether the recording has no frame.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The sensor the recording holds, named as `Sensor::kind` names it:
    /// `depth camera` or `point cloud`.
    pub fn kind(&self) -> &'static str {
        match self {
            Dataset::Depth(_) => "depth camera",
            Dataset::Clouds(_) => "point cloud",
        }
    }

    /// Frame `i`, read from disk.
    pub fn frame(&self, i: usize) -> Result<Frame, IoError> {
        match self {
            Dataset::Depth(d) => d.frame(i),
            Dataset::Clouds(c) => c.frame(i),
        }
    }
}

impl CloudFolder {
    /// Lists `dir`'s `*.pcd` files and reads `dir/poses.txt`, which must
    /// hold one pose per cloud.
    pub fn open(dir: &Path) -> Result<Self, IoError> {
        let mut clouds = Vec::new();
        for entry in std::fs::read_dir(dir).map_err(|e| IoError::io(dir, e))? {
            let path = entry.map_err(|e| IoError::io(dir, e))?.path();
            if path.extension().is_some_and(|e| e == "pcd" || e == "bin") {
                clouds.push(path);
            }
        }
        if clouds.is_empty() {
            return Err(bad(dir, "no *.pcd or *.bin point clouds"));
        }
        let kinds = clouds.iter().filter(|p| p.extension().is_some_and(|e| e == "pcd")).count();
        if kinds != 0 && kinds != clouds.len() {
            return Err(bad(dir, "both *.pcd and *.bin clouds: keep one kind per folder"));
        }
        clouds.sort();
        let poses_path = dir.join("poses.txt");
        let text = std::fs::read_to_string(&poses_path).map_err(|e| IoError::io(&poses_path, e))?;
        let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
        if lines.len() != clouds.len() {
            return Err(bad(&poses_path, format!("{} poses for {} point clouds", lines.len(), clouds.len())));
        }
        let mut frames = Vec::with_capacity(clouds.len());
        for (k, (cloud, line)) in clouds.into_iter().zip(lines).enumerate() {
            let at = |reason: String| bad(&poses_path, format!("line {}: {reason}", k + 1));
            let numbers = line
                .split_whitespace()
                .map(|t| t.parse::<f64>().map_err(|_| at(format!("{t:?} is not a number"))))
                .collect::<Result<Vec<f64>, IoError>>()?;
            if numbers.len() != 12 {
                return Err(at(format!("{} numbers, a KITTI pose has 12", numbers.len())));
            }
            let m: [[f64; 4]; 4] = std::array::from_fn(|r| std::array::from_fn(|c| if r < 3 { numbers[4 * r + c] } else if c == 3 { 1.0 } else { 0.0 }));
            pose_from_matrix(&m).map_err(|e| at(e.to_string()))?;
            frames.push((cloud, m));
        }
        Ok(CloudFolder { frames })
    }

    /// Cloud `i` with its pose; its stamp is its index (the clouds carry
    /// none).
    pub fn frame(&self, i: usize) -> Result<Frame, IoError> {
        let (path, m) = self.frames.get(i).ok_or_else(|| bad(Path::new("."), format!("frame {i} of {}", self.frames.len())))?;
        let cloud = if path.extension().is_some_and(|e| e == "bin") { read_kitti_bin(path)? } else { read_pcd(path)? };
        let pose = pose_from_matrix(m).map_err(|e| bad(path, e.to_string()))?;
        Ok(Frame { stamp_s: i as f64, t_world_sensor: pose, measurement: Measurement::Points(cloud) })
    }
}

/// A KITTI Velodyne scan: little-endian float32 `x y z reflectance` per
/// point (reflectance unused).
pub fn read_kitti_bin(path: &Path) -> Result<PointCloud, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::io(path, e))?;
    if bytes.len() % 16 != 0 {
        return Err(bad(path, format!("{} bytes is not a whole number of 16-byte points (x y z reflectance)", bytes.len())));
    }
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let points = bytes.chunks_exact(16).map(|p| [f(&p[0..4]), f(&p[4..8]), f(&p[8..12])]).collect();
    Ok(PointCloud { points })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data").join(name)
    }

    #[test]
    fn opens_the_velodyne_pair_with_its_kitti_poses() {
        let dir = data("velodyne-pair");
        if !dir.exists() {
            eprintln!("skipping: {} is absent", dir.display());
            return;
        }
        let set = Dataset::open(&dir, 0.001, RangeLimits { min_m: 0.1, max_m: 100.0 }).expect("opens");
        assert_eq!((set.kind(), set.len()), ("point cloud", 2));
        let first = set.frame(0).expect("frame 0");
        assert!(first.t_world_sensor.translation.vector.norm() == 0.0 && first.t_world_sensor.rotation.angle() == 0.0);
        let Measurement::Points(cloud) = set.frame(1).expect("frame 1").measurement else { panic!("points") };
        assert!(cloud.points.len() > 60_000, "{} points", cloud.points.len());
    }

    #[test]
    fn opens_the_3dmatch_folder() {
        let dir = data("3dmatch-seq01");
        if !dir.exists() {
            eprintln!("skipping: {} is absent", dir.display());
            return;
        }
        let set = Dataset::open(&dir, 0.001, RangeLimits { min_m: 0.3, max_m: 8.0 }).expect("opens");
        assert_eq!((set.kind(), set.len()), ("depth camera", 5));
    }

    #[test]
    fn reads_kitti_bin_scans_with_their_poses() {
        let dir = std::env::temp_dir().join(format!("edtmap-kitti-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let scan = |pts: &[[f32; 4]]| pts.iter().flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes())).collect::<Vec<u8>>();
        std::fs::write(dir.join("000000.bin"), scan(&[[1.0, 2.0, 3.0, 0.5], [-4.0, 0.0, 0.25, 1.0]])).expect("write");
        std::fs::write(dir.join("000001.bin"), scan(&[[5.0, 5.0, 0.0, 0.0]])).expect("write");
        std::fs::write(dir.join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n0 -1 0 10 1 0 0 20 0 0 1 0.5\n").expect("write");
        let set = Dataset::open(&dir, 0.001, RangeLimits { min_m: 0.1, max_m: 50.0 }).expect("opens");
        assert_eq!((set.kind(), set.len()), ("point cloud", 2));
        let Measurement::Points(first) = set.frame(0).expect("frame 0").measurement else { panic!("points") };
        assert_eq!(first.points, vec![[1.0, 2.0, 3.0], [-4.0, 0.0, 0.25]]);
        let second = set.frame(1).expect("frame 1");
        // x of the scan maps to y of the world (90° about z), then the offset.
        let p = second.t_world_sensor.transform_point(&[1.0, 0.0, 0.0].into());
        assert!((p.x - 10.0).abs() < 1e-12 && (p.y - 21.0).abs() < 1e-12 && (p.z - 0.5).abs() < 1e-12, "{p:?}");
        std::fs::write(dir.join("000001.bin"), [0u8; 15]).expect("write");
        let err = set.frame(1).expect_err("15 bytes").to_string();
        assert!(err.contains("000001.bin") && err.contains("16-byte points"), "{err}");
        std::fs::write(dir.join("000002.pcd"), b"x").expect("write");
        let err = Dataset::open(&dir, 0.001, RangeLimits { min_m: 0.1, max_m: 50.0 }).expect_err("mixed").to_string();
        assert!(err.contains("keep one kind"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn bad_trajectories_name_the_file_and_line() {
        let dir = std::env::temp_dir().join(format!("edtmap-dataset-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        std::fs::write(dir.join("a.pcd"), b"not read here").expect("write");
        std::fs::write(dir.join("b.pcd"), b"not read here").expect("write");
        for (poses, want) in [
            ("1 0 0 0 0 1 0 0 0 0 1 0\n", "1 poses for 2 point clouds"),
            ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n", "line 2: 11 numbers"),
            ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 x 0\n", "line 2: \"x\" is not a number"),
            ("1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n", "line 2:"),
        ] {
            std::fs::write(dir.join("poses.txt"), poses).expect("write");
            let err = Dataset::open(&dir, 0.001, RangeLimits { min_m: 0.1, max_m: 10.0 }).expect_err(want).to_string();
            assert!(err.contains("poses.txt") && err.contains(want), "{err}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
