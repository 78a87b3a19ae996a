//! Folders of point clouds, one file per frame: `*.pcd`, KITTI Velodyne
//! `*.bin` or `*.ply`, one kind per folder.

use crate::files::{self, MAX_CLOUD_BYTES};
use crate::folder::frames::{
    bad, file_name, list_dir, parse_kitti_poses_noted, parse_times, read_text, stem_time, FrameFile, FramePose,
    TrajectoryFile,
};
use crate::folder::DatasetOptions;
use crate::ply::read_ply;
use crate::{read_pcd, IoError};
use edtmap_core::sensor::{Frame, Measurement, PointCloud, PoseAdjustments};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Frame rate assumed for clouds without times (KITTI's Velodyne), Hz.
pub const DEFAULT_CLOUD_RATE_HZ: f64 = 10.0;

/// The cloud file kinds, by extension.
const CLOUD_KINDS: [&str; 3] = ["pcd", "bin", "ply"];

/// A folder of point clouds with their times and poses.
#[derive(Debug, Clone)]
pub struct CloudFolder {
    /// The clouds in order (file-name order; time order when every name is
    /// a time), with their times and poses.
    pub frames: Vec<FrameFile>,
    /// The rotations read so far that were replaced by the nearest
    /// rotation (see [`Dataset::pose_warning`](crate::dataset::Dataset::pose_warning)).
    pub poses_adjusted: Arc<PoseAdjustments>,
}

/// The point-cloud files of a folder's entries.
pub(crate) fn cloud_files(entries: &[PathBuf]) -> Vec<PathBuf> {
    let is_cloud = |p: &&PathBuf| p.extension().and_then(|e| e.to_str()).is_some_and(|e| CLOUD_KINDS.contains(&e));
    entries.iter().filter(is_cloud).cloned().collect()
}

impl CloudFolder {
    /// Lists `dir`'s clouds and finds each one's time and pose. Poses come
    /// from, in this order: `opts.trajectory` (at each cloud's time from
    /// `times.txt`, or else from its file name), `poses.txt` (KITTI, one
    /// line per cloud), or a `<stem>.pose.txt` matrix beside every cloud.
    /// Times come from `times.txt`, else from numeric file names, else the
    /// index at [`DEFAULT_CLOUD_RATE_HZ`].
    pub fn open(dir: &Path, opts: &DatasetOptions) -> Result<Self, IoError> {
        let clouds = sorted_clouds(dir)?;
        let times_path = dir.join("times.txt");
        let file_times: Option<Vec<f64>> = if times_path.exists() {
            let times = parse_times(&times_path, &read_text(&times_path)?)?;
            if times.len() != clouds.len() {
                return Err(bad(&times_path, format!("{} times for {} point clouds", times.len(), clouds.len())));
            }
            Some(times)
        } else {
            clouds.iter().map(|c| stem_time(c)).collect()
        };
        let stamps =
            file_times.clone().unwrap_or_else(|| (0..clouds.len()).map(|i| i as f64 / DEFAULT_CLOUD_RATE_HZ).collect());
        let poses_adjusted = Arc::new(PoseAdjustments::default());
        let poses = if let Some(traj_path) = &opts.trajectory {
            let Some(times) = file_times else {
                return Err(bad(dir, format!("a trajectory ({}) needs each cloud's time: add times.txt (one time per cloud) or name the clouds by their time, as 1311868164.363181.pcd", traj_path.display())));
            };
            let traj = TrajectoryFile::read(traj_path, opts.max_pose_gap_s)?;
            times.iter().map(|&t| traj.pose_at(t)).collect()
        } else if dir.join("poses.txt").exists() {
            let poses_path = dir.join("poses.txt");
            let poses = parse_kitti_poses_noted(&poses_path, &read_text(&poses_path)?, Some(&poses_adjusted))?;
            if poses.len() != clouds.len() {
                return Err(bad(&poses_path, format!("{} poses for {} point clouds", poses.len(), clouds.len())));
            }
            poses.into_iter().map(FramePose::Known).collect()
        } else {
            per_file_poses(dir, &clouds)?
        };
        let frames = clouds
            .into_iter()
            .zip(stamps)
            .zip(poses)
            .map(|((path, stamp_s), pose)| FrameFile { path, stamp_s, pose })
            .collect();
        Ok(CloudFolder { frames, poses_adjusted })
    }

    /// Cloud `i`, read from disk, with its time and pose.
    pub fn frame(&self, i: usize) -> Result<Frame, IoError> {
        let file =
            self.frames.get(i).ok_or_else(|| bad(Path::new("."), format!("frame {i} of {}", self.frames.len())))?;
        let pose = file.pose_noted(Some(&self.poses_adjusted))?;
        let cloud = match file.path.extension().and_then(|e| e.to_str()) {
            Some("bin") => read_kitti_bin(&file.path)?,
            Some("ply") => read_ply(&file.path)?,
            _ => read_pcd(&file.path)?,
        };
        Ok(Frame { stamp_s: file.stamp_s, t_world_sensor: pose, measurement: Measurement::Points(cloud) })
    }
}

/// The folder's clouds, all of one kind, in file-name order, or in time
/// order when every name is a time.
fn sorted_clouds(dir: &Path) -> Result<Vec<PathBuf>, IoError> {
    let mut clouds = cloud_files(&list_dir(dir)?);
    let Some(first) = clouds.first() else {
        return Err(bad(dir, "no *.pcd, *.bin or *.ply point clouds"));
    };
    let kind = first.extension().map(|e| e.to_os_string());
    if let Some(other) = clouds.iter().find(|c| c.extension().map(|e| e.to_os_string()) != kind) {
        return Err(bad(
            dir,
            format!("both {} and {}: keep one kind of cloud per folder", file_name(first), file_name(other)),
        ));
    }
    let times: Option<Vec<f64>> = clouds.iter().map(|c| stem_time(c)).collect();
    if let Some(times) = times {
        let mut keyed: Vec<(f64, PathBuf)> = times.into_iter().zip(clouds).collect();
        keyed.sort_by(|a, b| a.0.total_cmp(&b.0));
        clouds = keyed.into_iter().map(|(_, c)| c).collect();
    }
    Ok(clouds)
}

/// A `<stem>.pose.txt` beside each cloud: a cloud without one fails as
/// its frame; a folder where no cloud has one is refused, naming the
/// first.
fn per_file_poses(dir: &Path, clouds: &[PathBuf]) -> Result<Vec<FramePose>, IoError> {
    let poses: Vec<FramePose> = clouds
        .iter()
        .map(|cloud| {
            let stem = cloud.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
            let pose = dir.join(format!("{stem}.pose.txt"));
            if pose.exists() {
                FramePose::File(pose)
            } else {
                FramePose::Missing(format!(
                    "its pose file {stem}.pose.txt is missing (4 × 4 row-major, beside the cloud)"
                ))
            }
        })
        .collect();
    if let (Some(first), true) = (clouds.first(), poses.iter().all(|p| matches!(p, FramePose::Missing(_)))) {
        let stem = first.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
        return Err(bad(first, format!("no pose: give a trajectory, a poses.txt (KITTI) in the folder, or a {stem}.pose.txt (4 × 4 row-major) beside each cloud")));
    }
    Ok(poses)
}

/// A KITTI Velodyne scan: little-endian float32 `x y z reflectance` per
/// point (reflectance unused); a regular file of at most
/// [`MAX_CLOUD_BYTES`].
pub fn read_kitti_bin(path: &Path) -> Result<PointCloud, IoError> {
    let bytes = files::read_input(path, MAX_CLOUD_BYTES)?;
    parse_kitti_bin(path, &bytes)
}

/// Parses the bytes of a KITTI Velodyne scan; `path` only names it in
/// errors.
pub fn parse_kitti_bin(path: &Path, bytes: &[u8]) -> Result<PointCloud, IoError> {
    if !bytes.len().is_multiple_of(16) {
        return Err(bad(
            path,
            format!("{} bytes is not a whole number of 16-byte points (x y z reflectance)", bytes.len()),
        ));
    }
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let points = bytes.chunks_exact(16).map(|p| [f(&p[0..4]), f(&p[4..8]), f(&p[8..12])]).collect();
    Ok(PointCloud { points })
}
