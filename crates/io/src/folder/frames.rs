//! The frame list both folder kinds share: one file per frame with its
//! time and where its pose comes from, and the small text files that give
//! times and poses (`times.txt`, KITTI `poses.txt`, per-file 4 × 4
//! matrices, TUM trajectories).

use crate::trajectory::Trajectory;
use crate::IoError;
use edtmap_core::sensor::{pose_from_matrix_noted, PoseAdjustments};
use nalgebra::Isometry3;
use std::path::{Path, PathBuf};

/// One frame of a folder: the file holding its measurement, its time and
/// its pose.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameFile {
    /// The depth image or point cloud.
    pub path: PathBuf,
    /// Time stamp, seconds (the file's own time when the layout has one).
    pub stamp_s: f64,
    /// Where the pose `T_world_sensor` comes from.
    pub pose: FramePose,
}

/// Where a frame's pose comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum FramePose {
    /// Known at open time (a trajectory or a KITTI `poses.txt`).
    Known(Isometry3<f64>),
    /// A 4 × 4 row-major matrix file beside the frame, read with the frame.
    File(PathBuf),
    /// The trajectory has no pose at the frame's time; the reason names the
    /// trajectory and its span. Reading the frame returns
    /// [`IoError::NoPose`].
    Missing(String),
}

impl FrameFile {
    /// The frame's pose, reading its matrix file if it has one.
    pub fn pose(&self) -> Result<Isometry3<f64>, IoError> {
        self.pose_noted(None)
    }

    /// [`FrameFile::pose`], counting an adjusted rotation in `noted`.
    pub fn pose_noted(&self, noted: Option<&PoseAdjustments>) -> Result<Isometry3<f64>, IoError> {
        match &self.pose {
            FramePose::Known(pose) => Ok(*pose),
            FramePose::File(path) => parse_matrix_noted(path, &read_text(path)?, noted),
            FramePose::Missing(reason) => {
                Err(IoError::NoPose { path: self.path.clone(), stamp_s: self.stamp_s, reason: reason.clone() })
            }
        }
    }
}

pub(crate) fn bad(path: &Path, reason: impl Into<String>) -> IoError {
    IoError::Dataset { path: path.to_path_buf(), reason: reason.into() }
}

/// The entries of `dir`, sorted by name.
pub(crate) fn list_dir(dir: &Path) -> Result<Vec<PathBuf>, IoError> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| IoError::io(dir, e))? {
        out.push(entry.map_err(|e| IoError::io(dir, e))?.path());
    }
    out.sort();
    Ok(out)
}

/// The file name of `path` as text (empty when it is not UTF-8).
pub(crate) fn file_name(path: &Path) -> &str {
    path.file_name().and_then(|n| n.to_str()).unwrap_or_default()
}

/// The time a file's name gives, as in `1311868164.363181.pcd`: its name
/// without the final extension, when that is a finite number of seconds
/// with a decimal point. Integer names such as KITTI's `000042.bin` are
/// frame numbers, not times.
pub(crate) fn stem_time(path: &Path) -> Option<f64> {
    let stem = path.file_stem()?.to_str()?;
    if !stem.contains('.') {
        return None;
    }
    stem.parse::<f64>().ok().filter(|t| t.is_finite())
}

/// A TUM trajectory file, read once, and the pose it gives a frame.
pub(crate) struct TrajectoryFile {
    pub(crate) path: PathBuf,
    pub(crate) trajectory: Trajectory,
    pub(crate) max_gap_s: f64,
}

impl TrajectoryFile {
    /// Reads the TUM file at `path`.
    pub(crate) fn read(path: &Path, max_gap_s: f64) -> Result<Self, IoError> {
        Ok(TrajectoryFile { path: path.to_path_buf(), trajectory: Trajectory::read_tum(path)?, max_gap_s })
    }

    /// The pose at `t`, or why there is none (naming the trajectory file
    /// and its span, for the frame's error).
    pub(crate) fn pose_at(&self, t: f64) -> FramePose {
        match self.trajectory.pose_at(t, self.max_gap_s) {
            Ok(pose) => FramePose::Known(pose),
            Err(e) => {
                let (first, last) = self.trajectory.span().unwrap_or((f64::NAN, f64::NAN));
                FramePose::Missing(format!("{e} ({} spans {first:.6} s to {last:.6} s)", self.path.display()))
            }
        }
    }
}

/// The numbers of one line, or an error naming the file and line `k + 1`.
fn line_numbers(path: &Path, k: usize, line: &str) -> Result<Vec<f64>, IoError> {
    line.split(|c: char| c.is_whitespace() || c == ',')
        .filter(|t| !t.is_empty())
        .map(|t| {
            let shown: String = t.chars().take(40).collect();
            t.parse::<f64>().map_err(|_| bad(path, format!("line {}: {shown:?} is not a number", k + 1)))
        })
        .collect()
}

/// The non-blank, non-`#` lines of `text` with their 0-based line index.
fn content_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().map(|(k, l)| (k, l.trim())).filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// Parses a KITTI odometry trajectory: one line per frame, the 12 numbers
/// of the row-major 3 × 4 `T_world_sensor`. `path` names the file in
/// errors.
pub fn parse_kitti_poses(path: &Path, text: &str) -> Result<Vec<Isometry3<f64>>, IoError> {
    parse_kitti_poses_noted(path, text, None)
}

/// [`parse_kitti_poses`], counting adjusted rotations in `noted`.
pub(crate) fn parse_kitti_poses_noted(
    path: &Path,
    text: &str,
    noted: Option<&PoseAdjustments>,
) -> Result<Vec<Isometry3<f64>>, IoError> {
    let mut poses = Vec::new();
    for (k, line) in content_lines(text) {
        let numbers = line_numbers(path, k, line)?;
        if numbers.len() != 12 {
            return Err(bad(path, format!("line {}: {} numbers, a KITTI pose has 12", k + 1, numbers.len())));
        }
        poses.push(matrix_pose(&numbers, noted).map_err(|e| bad(path, format!("line {}: {e}", k + 1)))?);
    }
    Ok(poses)
}

/// Parses a `times.txt` (KITTI odometry): one time in seconds per line.
pub fn parse_times(path: &Path, text: &str) -> Result<Vec<f64>, IoError> {
    let mut times = Vec::new();
    for (k, line) in content_lines(text) {
        match line_numbers(path, k, line)?[..] {
            [t] if t.is_finite() => times.push(t),
            [t] => return Err(bad(path, format!("line {}: time {t} is not finite", k + 1))),
            ref other => return Err(bad(path, format!("line {}: {} numbers, expected one time", k + 1, other.len()))),
        }
    }
    Ok(times)
}

/// Reads `path`'s text: a regular file of at most
/// [`crate::files::MAX_TEXT_BYTES`], UTF-8.
pub(crate) fn read_text(path: &Path) -> Result<String, IoError> {
    crate::files::read_text(path)
}

/// Reads a pose matrix file: 16 numbers (4 × 4 row-major) or 12 (the top
/// 3 × 4 rows), whitespace-separated over any number of lines.
pub fn read_matrix_file(path: &Path) -> Result<Isometry3<f64>, IoError> {
    parse_matrix(path, &read_text(path)?)
}

/// Parses the text of a pose matrix file (see [`read_matrix_file`]).
pub fn parse_matrix(path: &Path, text: &str) -> Result<Isometry3<f64>, IoError> {
    parse_matrix_noted(path, text, None)
}

/// [`parse_matrix`], counting an adjusted rotation in `noted`.
fn parse_matrix_noted(path: &Path, text: &str, noted: Option<&PoseAdjustments>) -> Result<Isometry3<f64>, IoError> {
    let mut numbers = Vec::with_capacity(16);
    for (k, line) in content_lines(text) {
        numbers.extend(line_numbers(path, k, line)?);
        if numbers.len() > 16 {
            return Err(bad(
                path,
                format!("line {}: more than 16 numbers, a pose matrix has 16 (4 × 4) or 12 (3 × 4)", k + 1),
            ));
        }
    }
    if numbers.len() != 16 && numbers.len() != 12 {
        return Err(bad(path, format!("{} numbers, a pose matrix has 16 (4 × 4) or 12 (3 × 4)", numbers.len())));
    }
    matrix_pose(&numbers, noted).map_err(|e| bad(path, e))
}

/// The pose of 12 or 16 row-major numbers.
fn matrix_pose(n: &[f64], noted: Option<&PoseAdjustments>) -> Result<Isometry3<f64>, String> {
    let m: [[f64; 4]; 4] = std::array::from_fn(|r| {
        std::array::from_fn(|c| match n.get(4 * r + c) {
            Some(&v) => v,
            None => f64::from(u8::from(c == 3)),
        })
    });
    pose_from_matrix_noted(&m, noted).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kitti_poses_name_the_line() {
        let p = Path::new("poses.txt");
        let poses = parse_kitti_poses(p, "# c\n1 0 0 1 0 1 0 2 0 0 1 3\n\n").expect("one pose");
        assert_eq!(poses.len(), 1);
        assert_eq!(poses[0].translation.vector.as_slice(), &[1.0, 2.0, 3.0]);
        let err = parse_kitti_poses(p, "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0\n").expect_err("short").to_string();
        assert!(err.contains("poses.txt: line 2: 3 numbers"), "{err}");
    }

    #[test]
    fn times_and_matrices() {
        let p = Path::new("times.txt");
        assert_eq!(parse_times(p, "0.0\n0.1\n 0.25 \n").expect("times"), vec![0.0, 0.1, 0.25]);
        let err = parse_times(p, "0\n1 2\n").expect_err("two").to_string();
        assert!(err.contains("line 2"), "{err}");
        let m = Path::new("a.pose.txt");
        let pose = parse_matrix(m, "1 0 0 5\n0 1 0 6\n0 0 1 7\n0 0 0 1\n").expect("4x4");
        assert_eq!(pose.translation.vector.as_slice(), &[5.0, 6.0, 7.0]);
        assert!(parse_matrix(m, "1 0 0 5\n0 1 0 6\n0 0 1 7\n").is_ok());
        let err = parse_matrix(m, "1 0 0 5\n0 1 0 6\n0 0 1 7\n0 0 0 1\n1\n").expect_err("17").to_string();
        assert!(err.contains("line 5"), "{err}");
    }

    #[test]
    fn stem_times() {
        assert_eq!(stem_time(Path::new("d/1311868164.363181.pcd")), Some(1311868164.363181));
        assert_eq!(stem_time(Path::new("d/scan.pcd")), None);
        assert_eq!(stem_time(Path::new("d/inf.pcd")), None);
        assert_eq!(stem_time(Path::new("d/000042.bin")), None);
    }
}
