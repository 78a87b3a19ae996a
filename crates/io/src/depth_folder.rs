//! Depth-image folders: 16-bit greyscale PNGs (0 = no return) with poses,
//! in two layouts.
//!
//! * **3DMatch**: `frame-XXXXXX.depth.png` with a `frame-XXXXXX.pose.txt`
//!   each (4 × 4 row-major `T_world_camera`, metres, optical axes), or
//!   poses from a trajectory file at each frame's time. 3DMatch carries no
//!   times: frame `XXXXXX` is at `XXXXXX / 30` s (the sequences are 30 Hz).
//! * **TUM RGB-D**: `depth.txt` (`timestamp depth/<name>.png` per line,
//!   `#` comments) or else a `depth/` folder of `<timestamp>.png`; poses
//!   interpolated at each image's time in a TUM trajectory: the one given,
//!   or the folder's `groundtruth.txt`.
//!
//! Intrinsics come from `camera-intrinsics.txt` (3 × 3 K) when the folder
//! has one (unless [`DatasetOptions::folder_intrinsics`] is false), else
//! from [`DatasetOptions::intrinsics`]. Depth units are the caller's:
//! millimetres in 3DMatch, 1/5000 m in TUM.
//!
//! A frame whose image or pose file is missing or unreadable fails on
//! [`DepthFolder::frame`] alone; only problems of the whole folder fail
//! [`DepthFolder::open_with`] (see [`crate::dataset`]).
//!
//! The first image with a readable header gives the folder its size; every other image's
//! header must give the same before it is decoded ([`read_depth_png`]), so
//! a file claiming a huge image is refused without allocating it.

mod depth_png;

pub use depth_png::{read_depth_png, ExpectedSize, MAX_DEPTH_IMAGE_BYTES};

use crate::folder::frames::{bad, file_name, list_dir, read_text, FrameFile, FramePose, TrajectoryFile};
use crate::folder::DatasetOptions;
use crate::IoError;
use depth_png::DepthPng;
use edtmap_core::sensor::{DepthData, DepthImage, Frame, Measurement, PinholeCamera, PoseAdjustments, RangeLimits};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Frame rate of 3DMatch sequences, Hz: the time of frame `XXXXXX`.
pub const THREEDMATCH_RATE_HZ: f64 = 30.0;

/// A depth-image folder: its camera and its frames.
#[derive(Debug, Clone)]
pub struct DepthFolder {
    /// The camera: intrinsics from the folder or the options, size from the
    /// first image.
    pub camera: PinholeCamera,
    /// Every frame's image, time and pose, in file-name order (3DMatch) or
    /// in the order `depth.txt` lists them (TUM).
    pub frames: Vec<FrameFile>,
    /// Metres per depth unit (0.001 for millimetres).
    pub metres_per_unit: f32,
    /// The `camera-intrinsics.txt` that gave the camera's intrinsics;
    /// `None` when they came from [`DatasetOptions::intrinsics`].
    pub intrinsics_file: Option<PathBuf>,
    /// Files left out at open (named like frames but not frames), one
    /// line each.
    pub warnings: Vec<String>,
    /// The rotations read so far that were replaced by the nearest
    /// rotation (see [`Dataset::pose_warning`](crate::dataset::Dataset::pose_warning)).
    pub poses_adjusted: Arc<PoseAdjustments>,
}

impl DepthFolder {
    /// Opens `dir` with its own poses and intrinsics; `range` bounds the
    /// valid depths.
    pub fn open(dir: &Path, metres_per_unit: f32, range: RangeLimits) -> Result<Self, IoError> {
        Self::open_with(dir, &DatasetOptions::new(metres_per_unit, range))
    }

    /// Opens `dir` (either layout), resolving every frame's time and pose
    /// and reading the intrinsics and the first image's size (from its
    /// header: the image is decoded with its frame).
    pub fn open_with(dir: &Path, opts: &DatasetOptions) -> Result<Self, IoError> {
        let entries = list_dir(dir)?;
        let mut warnings = Vec::new();
        let frames = if is_tum(dir) {
            tum_frames(dir, opts, &mut warnings)?
        } else {
            threedmatch_frames(dir, &entries, opts, &mut warnings)?
        };
        if frames.is_empty() {
            let layout = if is_tum(dir) {
                "listed in depth.txt or named depth/<timestamp>.png"
            } else {
                "named frame-XXXXXX.depth.png (XXXXXX the frame number)"
            };
            let left_out = if warnings.is_empty() {
                String::new()
            } else {
                format!(" ({} files left out: {})", warnings.len(), warnings.join("; "))
            };
            return Err(bad(dir, format!("no depth images {layout}{left_out}")));
        }
        let ([fx, fy, cx, cy], intrinsics_file) = intrinsics(dir, opts)?;
        let (width, height) = first_image_size(dir, &frames)?;
        let camera = PinholeCamera { fx, fy, cx, cy, width, height, range: opts.range };
        Ok(DepthFolder {
            camera,
            frames,
            metres_per_unit: opts.depth_scale_m,
            intrinsics_file,
            warnings,
            poses_adjusted: Arc::default(),
        })
    }

    /// Frame `i`: its depth image, time and pose. A frame whose time the
    /// trajectory does not cover is [`IoError::NoPose`]; an image whose
    /// header gives another size than the camera's is refused before it is
    /// decoded.
    pub fn frame(&self, i: usize) -> Result<Frame, IoError> {
        let file =
            self.frames.get(i).ok_or_else(|| bad(Path::new("."), format!("frame {i} of {}", self.frames.len())))?;
        let pose = file.pose_noted(Some(&self.poses_adjusted))?;
        let (width, height) = (self.camera.width, self.camera.height);
        let expected = ExpectedSize { width, height, source: "the folder's first image" };
        let (width, height, values) = read_depth_png(&file.path, Some(expected))?;
        let image =
            DepthImage { width, height, data: DepthData::U16 { values, metres_per_unit: self.metres_per_unit } };
        Ok(Frame { stamp_s: file.stamp_s, t_world_sensor: pose, measurement: Measurement::Depth(image) })
    }
}

/// Whether `dir`'s entries make it a depth folder of either layout.
pub(crate) fn is_depth_folder(dir: &Path, entries: &[PathBuf]) -> bool {
    is_tum(dir)
        || dir.join("camera-intrinsics.txt").exists()
        || entries.iter().any(|p| file_name(p).ends_with(".depth.png"))
}

fn is_tum(dir: &Path) -> bool {
    dir.join("depth.txt").is_file() || dir.join("depth").is_dir()
}

/// The frame number of a 3DMatch image name, `frame-XXXXXX.depth.png`.
fn threedmatch_number(name: &str) -> Option<u32> {
    let digits = name.strip_prefix("frame-")?.strip_suffix(".depth.png")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

/// The 3DMatch frames: `frame-XXXXXX.depth.png`, posed by their
/// `.pose.txt` files or by the trajectory at `XXXXXX / 30` s. Other
/// `*.depth.png` names are left out with a warning; a frame without its
/// pose file fails alone, but a folder where no frame has one is refused.
fn threedmatch_frames(
    dir: &Path,
    entries: &[PathBuf],
    opts: &DatasetOptions,
    warnings: &mut Vec<String>,
) -> Result<Vec<FrameFile>, IoError> {
    let traj = opts.trajectory.as_deref().map(|p| TrajectoryFile::read(p, opts.max_pose_gap_s)).transpose()?;
    let mut frames = Vec::new();
    for path in entries {
        let name = file_name(path);
        let Some(stem) = name.strip_suffix(".depth.png") else { continue };
        let Some(number) = threedmatch_number(name) else {
            warnings.push(format!(
                "{}: not a frame, left out: 3DMatch frames are named frame-XXXXXX.depth.png (XXXXXX the frame number)",
                path.display()
            ));
            continue;
        };
        let stamp_s = f64::from(number) / THREEDMATCH_RATE_HZ;
        let pose = match &traj {
            Some(traj) => traj.pose_at(stamp_s),
            None => {
                let pose = dir.join(format!("{stem}.pose.txt"));
                if pose.exists() {
                    FramePose::File(pose)
                } else {
                    FramePose::Missing(format!(
                        "its pose file {} is missing (or set [dataset] trajectory)",
                        file_name(&pose)
                    ))
                }
            }
        };
        frames.push(FrameFile { path: path.clone(), stamp_s, pose });
    }
    if traj.is_none() && !frames.is_empty() && frames.iter().all(|f| matches!(f.pose, FramePose::Missing(_))) {
        return Err(bad(
            dir,
            format!("no poses: none of the {} frames has its pose file (frame-XXXXXX.pose.txt, 4 × 4 T_world_camera; {} is missing): add them or set [dataset] trajectory", frames.len(), file_name(&frames[0].path).replace(".depth.png", ".pose.txt")),
        ));
    }
    Ok(frames)
}

/// The TUM frames, posed by the trajectory at each image's time.
fn tum_frames(dir: &Path, opts: &DatasetOptions, warnings: &mut Vec<String>) -> Result<Vec<FrameFile>, IoError> {
    let images = tum_images(dir, warnings)?;
    let traj_path = match &opts.trajectory {
        Some(p) => p.clone(),
        None => dir.join("groundtruth.txt"),
    };
    if opts.trajectory.is_none() && !traj_path.exists() {
        return Err(bad(
            dir,
            "no poses: the folder has no groundtruth.txt (TUM trajectory) and no trajectory file was given",
        ));
    }
    let traj = TrajectoryFile::read(&traj_path, opts.max_pose_gap_s)?;
    Ok(images.into_iter().map(|(stamp_s, path)| FrameFile { pose: traj.pose_at(stamp_s), path, stamp_s }).collect())
}

/// `(time, image)` of every TUM depth image: as `depth.txt` lists them,
/// else the `depth/` folder's `<timestamp>.png` in time order (other
/// names left out with a warning).
fn tum_images(dir: &Path, warnings: &mut Vec<String>) -> Result<Vec<(f64, PathBuf)>, IoError> {
    let list = dir.join("depth.txt");
    if list.is_file() {
        return parse_depth_list(dir, &list, &read_text(&list)?);
    }
    let folder = dir.join("depth");
    let mut images = Vec::new();
    for path in list_dir(&folder)? {
        if path.extension().is_some_and(|e| e == "png") {
            let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
            match stem.parse::<f64>().ok().filter(|t| t.is_finite()) {
                Some(t) => images.push((t, path)),
                None => warnings.push(format!(
                    "{}: not a frame, left out: the name is not a time (depth/ holds <timestamp>.png images)",
                    path.display()
                )),
            }
        }
    }
    images.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(images)
}

/// Parses a TUM `depth.txt`: `timestamp path` per line, the path relative
/// to `dir`. A listed image that is missing or not a regular file fails as
/// its frame, when it is read.
fn parse_depth_list(dir: &Path, list: &Path, text: &str) -> Result<Vec<(f64, PathBuf)>, IoError> {
    let mut images = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let at = |reason: String| bad(list, format!("line {}: {reason}", k + 1));
        let mut tokens = line.split_whitespace();
        let (Some(stamp), Some(name), None) = (tokens.next(), tokens.next(), tokens.next()) else {
            return Err(at("expected `timestamp depth/<name>.png`".into()));
        };
        let shown: String = stamp.chars().take(40).collect();
        let t = stamp
            .parse::<f64>()
            .ok()
            .filter(|t| t.is_finite())
            .ok_or_else(|| at(format!("{shown:?} is not a time")))?;
        images.push((t, dir.join(name)));
    }
    Ok(images)
}

/// `[fx, fy, cx, cy]` and the file they came from: `camera-intrinsics.txt`
/// when the folder has one and the options allow, else the options.
fn intrinsics(dir: &Path, opts: &DatasetOptions) -> Result<([f64; 4], Option<PathBuf>), IoError> {
    let path = dir.join("camera-intrinsics.txt");
    if opts.folder_intrinsics && path.exists() {
        return Ok((parse_intrinsics(&path, &read_text(&path)?)?, Some(path)));
    }
    let Some(k) = opts.intrinsics else {
        return Err(bad(dir, "no camera-intrinsics.txt: set the depth camera's intrinsics [sensor] fx, fy, cx, cy (pixels) in the config"));
    };
    check_intrinsics(k).map_err(|reason| bad(dir, format!("[sensor] fx, fy, cx, cy: {reason}")))?;
    Ok((k, None))
}

/// The size of the first depth image whose header reads (a frame whose
/// header does not fails later, alone); an error when none does.
fn first_image_size(dir: &Path, frames: &[FrameFile]) -> Result<(u32, u32), IoError> {
    let mut first_error = None;
    for frame in frames {
        match DepthPng::open(&frame.path, None) {
            Ok(png) => return Ok((png.width, png.height)),
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    let first = first_error.map_or_else(String::new, |e| format!(", the first: {e}"));
    Err(bad(dir, format!("none of the {} depth images can be read{first}", frames.len())))
}

/// Parses a `camera-intrinsics.txt`: the 9 numbers of the 3 × 3 K,
/// row-major; returns `[fx, fy, cx, cy]`. `path` names the file in errors.
pub fn parse_intrinsics(path: &Path, text: &str) -> Result<[f64; 4], IoError> {
    let mut k = Vec::with_capacity(9);
    for (n, line) in text.lines().enumerate() {
        for token in line.split_whitespace() {
            let shown: String = token.chars().take(40).collect();
            k.push(token.parse::<f64>().map_err(|_| bad(path, format!("line {}: {shown:?} is not a number", n + 1)))?);
            if k.len() > 9 {
                return Err(bad(path, format!("line {}: more than 9 numbers, K is 3 × 3", n + 1)));
            }
        }
    }
    if k.len() != 9 {
        return Err(bad(path, format!("expected 9 numbers (3 × 3 K), found {}", k.len())));
    }
    let fxfycxcy = [k[0], k[4], k[2], k[5]];
    check_intrinsics(fxfycxcy).map_err(|reason| bad(path, reason))?;
    Ok(fxfycxcy)
}

fn check_intrinsics([fx, fy, cx, cy]: [f64; 4]) -> Result<(), String> {
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
        return Err(format!("focal lengths fx = {fx}, fy = {fy} must be positive"));
    }
    if !(cx.is_finite() && cy.is_finite()) {
        return Err(format!("principal point cx = {cx}, cy = {cy} must be finite"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intrinsics_name_the_problem() {
        let p = Path::new("camera-intrinsics.txt");
        assert_eq!(parse_intrinsics(p, "570 0 320\n0 571 240\n0 0 1\n").expect("K"), [570.0, 571.0, 320.0, 240.0]);
        let err = parse_intrinsics(p, "570 0 320\n0 x 240\n0 0 1\n").expect_err("x").to_string();
        assert!(err.contains("line 2") && err.contains("\"x\""), "{err}");
        let err = parse_intrinsics(p, "570 0 320\n0 570 240\n").expect_err("6").to_string();
        assert!(err.contains("found 6"), "{err}");
        let err = parse_intrinsics(p, "-570 0 320\n0 570 240\n0 0 1").expect_err("negative").to_string();
        assert!(err.contains("positive"), "{err}");
    }

    #[test]
    fn depth_lists_name_the_line() {
        let dir = tempfile::tempdir().expect("temp dir");
        std::fs::create_dir(dir.path().join("depth")).expect("mkdir");
        std::fs::write(dir.path().join("depth/1.5.png"), b"").expect("write");
        let list = dir.path().join("depth.txt");
        let got = parse_depth_list(dir.path(), &list, "# c\n1.5 depth/1.5.png\n").expect("one");
        assert_eq!(got, vec![(1.5, dir.path().join("depth/1.5.png"))]);
        for (text, want) in [
            ("x depth/1.5.png\n", "line 1: \"x\" is not a time"),
            ("1.5\n", "line 1: expected"),
            ("# c\n2 depth/2.png extra\n", "line 2:"),
        ] {
            let err = parse_depth_list(dir.path(), &list, text).expect_err(want).to_string();
            assert!(err.contains("depth.txt") && err.contains(want), "{err}");
        }
    }
}
