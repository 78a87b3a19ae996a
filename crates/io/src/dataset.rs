//! Recordings on disk as frames with poses, for `edtmap run --dataset`.
//!
//! A folder is told apart by its files:
//! - a **depth folder** ([`DepthFolder`]): 3DMatch (`camera-intrinsics.txt`,
//!   `frame-XXXXXX.depth.png` + `frame-XXXXXX.pose.txt`) or TUM RGB-D
//!   (`depth.txt` or `depth/<timestamp>.png`, `groundtruth.txt`);
//! - a **folder of point clouds** ([`CloudFolder`]): `*.pcd`, KITTI
//!   Velodyne `*.bin` (float32 x y z reflectance per point, little-endian)
//!   or `*.ply`, one kind per folder, posed by a trajectory, a KITTI
//!   `poses.txt` (the 12 numbers of the row-major 3 × 4 `T_world_sensor`
//!   per cloud) or a `<stem>.pose.txt` beside each cloud.
//!
//! Poses are resolved when the folder is opened: they are just numbers.
//!
//! **What fails where.** Opening fails only for the recording as a whole:
//! the folder is missing or holds no frames, a file that serves every
//! frame (trajectory, `poses.txt`, `times.txt`, `depth.txt`,
//! `camera-intrinsics.txt`) cannot be read or parsed, or no frame has a
//! pose at all. Anything about one frame opens fine and fails on
//! [`Dataset::frame`] for that frame only, naming its file: its image or
//! cloud cannot be read, its pose file is missing or bad
//! ([`IoError::NoPose`] when nothing gives it a pose; the trajectory's
//! span is named when the trajectory does not cover its time). Files that
//! look like frames but do not follow the layout's naming
//! (`frame-abc.depth.png`, `depth/notes.png`) are not frames: they are
//! left out, each with a line in [`Dataset::warnings`].

mod cloud_folder;

pub use crate::depth_folder::DepthFolder;
pub use crate::folder::frames::{parse_kitti_poses, parse_matrix, parse_times, read_matrix_file, FrameFile, FramePose};
pub use crate::folder::DatasetOptions;
pub use cloud_folder::{parse_kitti_bin, read_kitti_bin, CloudFolder, DEFAULT_CLOUD_RATE_HZ};

use crate::folder::frames::{bad, list_dir};
use crate::IoError;
use edtmap_core::sensor::{Frame, RangeLimits};
use std::path::Path;

/// A recording opened for replay.
#[derive(Debug, Clone)]
pub enum Dataset {
    /// Depth images with poses.
    Depth(DepthFolder),
    /// Point clouds with poses.
    Clouds(CloudFolder),
}

impl Dataset {
    /// Opens the recording at `dir` with its own poses and intrinsics;
    /// `depth_scale_m` is the metres per unit of 16-bit depth images and
    /// `range` the depth camera's valid range.
    pub fn open(dir: &Path, depth_scale_m: f32, range: RangeLimits) -> Result<Self, IoError> {
        Self::open_with(dir, &DatasetOptions::new(depth_scale_m, range))
    }

    /// Opens the recording at `dir` as `opts` say.
    ///
    /// ```no_run
    /// use edtmap_core::sensor::RangeLimits;
    /// use edtmap_io::dataset::{Dataset, DatasetOptions};
    /// use edtmap_io::IoError;
    /// use std::path::Path;
    ///
    /// // A TUM RGB-D sequence: 5000 depth units per metre, no intrinsics file.
    /// let mut opts = DatasetOptions::new(0.0002, RangeLimits { min_m: 0.3, max_m: 5.0 });
    /// opts.intrinsics = Some([517.3, 516.5, 318.6, 255.3]);
    /// let set = Dataset::open_with(Path::new("rgbd_dataset_freiburg1_desk"), &opts)?;
    /// for i in 0..set.len() {
    ///     let frame = match set.frame(i) {
    ///         Ok(frame) => frame,
    ///         // Before the ground truth starts: skip the image.
    ///         Err(IoError::NoPose { .. }) => continue,
    ///         Err(e) => return Err(e),
    ///     };
    ///     println!("{:.3} s at {}", frame.stamp_s, frame.t_world_sensor.translation.vector);
    /// }
    /// # Ok::<(), IoError>(())
    /// ```
    pub fn open_with(dir: &Path, opts: &DatasetOptions) -> Result<Self, IoError> {
        if !dir.is_dir() {
            return Err(bad(dir, "not a folder"));
        }
        let entries = list_dir(dir)?;
        if crate::depth_folder::is_depth_folder(dir, &entries) {
            return Ok(Dataset::Depth(DepthFolder::open_with(dir, opts)?));
        }
        if !cloud_folder::cloud_files(&entries).is_empty() {
            return Ok(Dataset::Clouds(CloudFolder::open(dir, opts)?));
        }
        Err(bad(
            dir,
            "neither a depth folder (camera-intrinsics.txt and *.depth.png, or depth.txt or depth/ with TUM images) \
             nor a folder of point clouds (*.pcd, *.bin or *.ply)",
        ))
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames().len()
    }

    /// Whether the recording has no frame.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every frame's file, time and pose.
    pub fn frames(&self) -> &[FrameFile] {
        match self {
            Dataset::Depth(d) => &d.frames,
            Dataset::Clouds(c) => &c.frames,
        }
    }

    /// The sensor the recording holds, named as `Sensor::kind` names it:
    /// `depth camera` or `point cloud`.
    pub fn kind(&self) -> &'static str {
        match self {
            Dataset::Depth(_) => "depth camera",
            Dataset::Clouds(_) => "point cloud",
        }
    }

    /// What opening left out, one line each (files named like frames that
    /// are not frames), for the caller to show.
    pub fn warnings(&self) -> &[String] {
        match self {
            Dataset::Depth(d) => &d.warnings,
            Dataset::Clouds(_) => &[],
        }
    }

    /// The one warning for the poses read so far whose rotations were
    /// orthonormal only within the tolerance and were replaced by the
    /// nearest rotation (`None` when there were none): a reader shows it
    /// once, after the frames it read.
    pub fn pose_warning(&self) -> Option<String> {
        let (dir, noted) = match self {
            Dataset::Depth(d) => (d.frames.first().and_then(|f| f.path.parent()), &d.poses_adjusted),
            Dataset::Clouds(c) => (c.frames.first().and_then(|f| f.path.parent()), &c.poses_adjusted),
        };
        noted.warning(&dir.map_or_else(|| "the recording".to_string(), |d| d.display().to_string()))
    }

    /// Frame `i`, read from disk. [`IoError::NoPose`] when nothing gives
    /// it a pose (its time outside the trajectory, its pose file missing).
    pub fn frame(&self, i: usize) -> Result<Frame, IoError> {
        match self {
            Dataset::Depth(d) => d.frame(i),
            Dataset::Clouds(c) => c.frame(i),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use edtmap_core::sensor::Measurement;
    use std::path::PathBuf;

    /// A folder of `../shared/data`, or `None` (with a note) where it is absent.
    fn data(name: &str) -> Option<PathBuf> {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data").join(name);
        if !dir.exists() {
            eprintln!("skipping: {} is absent", dir.display());
            return None;
        }
        Some(dir)
    }

    #[test]
    fn opens_the_velodyne_pair_with_its_kitti_poses() {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/velodyne-pair");
        let set = Dataset::open(&dir, 0.001, RangeLimits { min_m: 0.1, max_m: 100.0 }).expect("opens");
        assert_eq!((set.kind(), set.len()), ("point cloud", 2));
        let first = set.frame(0).expect("frame 0");
        assert!(first.t_world_sensor.translation.vector.norm() == 0.0 && first.t_world_sensor.rotation.angle() == 0.0);
        let Measurement::Points(cloud) = set.frame(1).expect("frame 1").measurement else { panic!("points") };
        assert!(cloud.points.len() > 60_000, "{} points", cloud.points.len());
    }

    #[test]
    fn opens_the_3dmatch_folder() {
        let Some(dir) = data("3dmatch-seq01") else { return };
        let set = Dataset::open(&dir, 0.001, RangeLimits { min_m: 0.3, max_m: 8.0 }).expect("opens");
        assert_eq!((set.kind(), set.len()), ("depth camera", 5));
    }

    #[test]
    fn reads_kitti_bin_scans_with_their_poses() {
        let dir = std::env::temp_dir().join(format!("edtmap-kitti-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let scan =
            |pts: &[[f32; 4]]| pts.iter().flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes())).collect::<Vec<u8>>();
        std::fs::write(dir.join("000000.bin"), scan(&[[1.0, 2.0, 3.0, 0.5], [-4.0, 0.0, 0.25, 1.0]])).expect("write");
        std::fs::write(dir.join("000001.bin"), scan(&[[5.0, 5.0, 0.0, 0.0]])).expect("write");
        std::fs::write(dir.join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n0 -1 0 10 1 0 0 20 0 0 1 0.5\n")
            .expect("write");
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
