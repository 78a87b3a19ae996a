//! What the folder readers share: [`DatasetOptions`] and the frame list
//! ([`frames`]). The depth folder reader (`crate::depth_folder`) and the
//! point cloud folders of `crate::dataset` both build on this, and
//! `crate::dataset` tells the folder kinds apart on top of them, so no
//! reader needs the module that dispatches to it.

pub(crate) mod frames;

use crate::trajectory::GROUND_TRUTH_MAX_POSE_GAP_S;
use edtmap_core::sensor::RangeLimits;
use std::path::PathBuf;

/// How to read a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetOptions {
    /// Metres per unit of 16-bit depth images (0.001 for 3DMatch's
    /// millimetres, 0.0002 for TUM's 5000 units per metre).
    pub depth_scale_m: f32,
    /// The depth camera's valid range.
    pub range: RangeLimits,
    /// The depth camera's `[fx, fy, cx, cy]`, pixels, for folders without
    /// `camera-intrinsics.txt` (or all folders when `folder_intrinsics` is
    /// false).
    pub intrinsics: Option<[f64; 4]>,
    /// Whether a folder's own `camera-intrinsics.txt` gives the camera
    /// (the default). When false the file is not read and `intrinsics` is
    /// used.
    pub folder_intrinsics: bool,
    /// A TUM trajectory file giving the poses, interpolated at each frame's
    /// time; it overrides the folder's own poses.
    pub trajectory: Option<PathBuf>,
    /// Largest gap between trajectory samples to interpolate across,
    /// seconds.
    pub max_pose_gap_s: f64,
}

impl DatasetOptions {
    /// Options with the folder's own poses and intrinsics and
    /// [`GROUND_TRUTH_MAX_POSE_GAP_S`].
    pub fn new(depth_scale_m: f32, range: RangeLimits) -> Self {
        DatasetOptions {
            depth_scale_m,
            range,
            intrinsics: None,
            folder_intrinsics: true,
            trajectory: None,
            max_pose_gap_s: GROUND_TRUTH_MAX_POSE_GAP_S,
        }
    }
}
