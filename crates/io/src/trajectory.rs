//! Timestamped trajectories and the pose at any time between their samples.
//!
//! [`Trajectory::pose_at`] interpolates linearly in translation and
//! spherically (slerp) in rotation between the two samples around the
//! asked time. It refuses a time outside the samples (beyond a small
//! tolerance) and a time between two samples further apart than the gap
//! the caller allows: a robot's pose is not guessed across a hole in its
//! odometry.

use crate::IoError;
use edtmap_core::sensor::{check_pose, rotation_from_quaternion};
use nalgebra::{Isometry3, Quaternion, Translation3};
use std::path::Path;

/// Largest time between two trajectory samples that a frame's pose is
/// interpolated across by default when a folder is opened from code
/// (`DatasetOptions::new`, `DepthFolder::open`), seconds. Such folders are
/// posed by ground truth (TUM's 100 Hz motion capture, 3DMatch's per-frame
/// poses), which has no longer gaps, and a pose is not guessed over a hole.
pub const GROUND_TRUTH_MAX_POSE_GAP_S: f64 = 0.1;

/// Default of `[dataset] max_pose_gap_s` in a config file, seconds: the
/// gap `edtmap run` allows unless told otherwise. Its recordings include
/// ROS bags posed by odometry or `/tf` at 10 Hz, whose samples are a
/// jittered 0.1 s apart and may miss one; so the run is more lenient than
/// [`GROUND_TRUTH_MAX_POSE_GAP_S`] (TUM configs set 0.1 themselves).
pub const RECORDING_MAX_POSE_GAP_S: f64 = 0.25;

/// Poses `T_world_body` at increasing times.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    stamps: Vec<f64>,
    poses: Vec<Isometry3<f64>>,
}

/// Why a trajectory has no pose at a time.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseLookupError {
    /// The trajectory has no sample.
    #[error("the trajectory is empty")]
    Empty,
    /// The time is before the first sample.
    #[error("time {t:.6} s is before the first pose at {first:.6} s")]
    Before {
        /// Asked time, seconds.
        t: f64,
        /// First sample, seconds.
        first: f64,
    },
    /// The time is after the last sample.
    #[error("time {t:.6} s is after the last pose at {last:.6} s")]
    After {
        /// Asked time, seconds.
        t: f64,
        /// Last sample, seconds.
        last: f64,
    },
    /// The samples around the time are too far apart.
    #[error("time {t:.6} s falls in a {gap:.3} s gap between poses (at most {max_gap:.3} s allowed)")]
    Gap {
        /// Asked time, seconds.
        t: f64,
        /// Time between the samples around it, seconds.
        gap: f64,
        /// Largest gap allowed, seconds.
        max_gap: f64,
    },
}

/// Times within this of the first or last sample take that sample's pose.
pub const END_TOLERANCE_S: f64 = 1e-6;

impl Trajectory {
    /// A trajectory from samples in any order; of samples with equal times
    /// the last given is kept.
    pub fn new(mut samples: Vec<(f64, Isometry3<f64>)>) -> Self {
        samples.retain(|(t, _)| t.is_finite());
        // Stable sort keeps the given order among equal stamps.
        samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut stamps: Vec<f64> = Vec::with_capacity(samples.len());
        let mut poses: Vec<Isometry3<f64>> = Vec::with_capacity(samples.len());
        for (t, pose) in samples {
            if stamps.last() == Some(&t) {
                if let Some(last) = poses.last_mut() {
                    *last = pose;
                }
            } else {
                stamps.push(t);
                poses.push(pose);
            }
        }
        Trajectory { stamps, poses }
    }

    /// Adds one sample, as a live stream does: appended when newest (the
    /// usual case), put in its place otherwise; a sample at an existing
    /// time replaces it. A non-finite time is ignored.
    pub fn push(&mut self, t: f64, pose: Isometry3<f64>) {
        if !t.is_finite() {
            return;
        }
        let at = self.stamps.partition_point(|&s| s < t);
        if self.stamps.get(at) == Some(&t) {
            self.poses[at] = pose;
        } else {
            self.stamps.insert(at, t);
            self.poses.insert(at, pose);
        }
    }

    /// Drops the samples before `t` but the last of them, so a pose at `t`
    /// or later can still be interpolated: bounds a live stream's history.
    pub fn forget_before(&mut self, t: f64) {
        let keep_from = self.stamps.partition_point(|&s| s < t).saturating_sub(1);
        self.stamps.drain(..keep_from);
        self.poses.drain(..keep_from);
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.stamps.len()
    }

    /// Whether there is no sample.
    pub fn is_empty(&self) -> bool {
        self.stamps.is_empty()
    }

    /// First and last sample times, seconds.
    pub fn span(&self) -> Option<(f64, f64)> {
        Some((*self.stamps.first()?, *self.stamps.last()?))
    }

    /// The samples, in time order.
    pub fn samples(&self) -> impl Iterator<Item = (f64, &Isometry3<f64>)> {
        self.stamps.iter().copied().zip(&self.poses)
    }

    /// The pose at time `t`, interpolated between the samples around it,
    /// which must be at most `max_gap_s` apart.
    pub fn pose_at(&self, t: f64, max_gap_s: f64) -> Result<Isometry3<f64>, PoseLookupError> {
        let (first, last) = self.span().ok_or(PoseLookupError::Empty)?;
        if t.is_nan() || t < first - END_TOLERANCE_S {
            return Err(PoseLookupError::Before { t, first });
        }
        if t > last + END_TOLERANCE_S {
            return Err(PoseLookupError::After { t, last });
        }
        // Index of the first sample at or after t.
        let hi = self.stamps.partition_point(|&s| s < t);
        if hi == 0 {
            return Ok(self.poses[0]);
        }
        if hi == self.stamps.len() {
            return Ok(self.poses[hi - 1]);
        }
        if (self.stamps[hi] - t).abs() <= END_TOLERANCE_S {
            return Ok(self.poses[hi]);
        }
        if t - self.stamps[hi - 1] <= END_TOLERANCE_S {
            return Ok(self.poses[hi - 1]);
        }
        let (t0, t1) = (self.stamps[hi - 1], self.stamps[hi]);
        let gap = t1 - t0;
        if gap > max_gap_s {
            return Err(PoseLookupError::Gap { t, gap, max_gap: max_gap_s });
        }
        let s = (t - t0) / gap;
        let (a, b) = (&self.poses[hi - 1], &self.poses[hi]);
        let translation = a.translation.vector.lerp(&b.translation.vector, s);
        // slerp takes the short way; nearly equal rotations fall back to nlerp.
        let rotation = a.rotation.try_slerp(&b.rotation, s, 1e-9).unwrap_or_else(|| a.rotation.nlerp(&b.rotation, s));
        Ok(Isometry3::from_parts(Translation3::from(translation), rotation))
    }

    /// Reads a TUM trajectory: one `timestamp tx ty tz qx qy qz qw` line per
    /// pose (seconds, metres, unit quaternion), `#` comments and blank lines
    /// ignored; commas may separate the numbers.
    pub fn read_tum(path: &Path) -> Result<Self, IoError> {
        let text = crate::files::read_text(path)?;
        Self::parse_tum(&text).map_err(|reason| IoError::Dataset { path: path.to_path_buf(), reason })
    }

    /// Parses TUM trajectory text; the error names the line.
    pub fn parse_tum(text: &str) -> Result<Self, String> {
        let mut samples = Vec::new();
        for (k, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let at = |reason: String| format!("line {}: {reason}", k + 1);
            let numbers = line
                .split(|c: char| c.is_whitespace() || c == ',')
                .filter(|t| !t.is_empty())
                .map(|t| t.parse::<f64>().map_err(|_| at(format!("{t:?} is not a number"))))
                .collect::<Result<Vec<f64>, String>>()?;
            let [t, x, y, z, qx, qy, qz, qw] = numbers[..] else {
                return Err(at(format!("{} numbers, a TUM pose has 8: timestamp tx ty tz qx qy qz qw", numbers.len())));
            };
            let (rotation, _) =
                rotation_from_quaternion(Quaternion::new(qw, qx, qy, qz)).map_err(|e| at(e.to_string()))?;
            let pose = Isometry3::from_parts(Translation3::new(x, y, z), rotation);
            check_pose(&pose).map_err(|e| at(e.to_string()))?;
            if !t.is_finite() {
                return Err(at(format!("timestamp {t} is not finite")));
            }
            samples.push((t, pose));
        }
        if samples.is_empty() {
            return Err("no pose".into());
        }
        Ok(Trajectory::new(samples))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn pose(x: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::new(Vector3::new(x, 0.0, 0.0), Vector3::new(0.0, 0.0, yaw))
    }

    #[test]
    fn interpolates_translation_and_rotation() {
        let traj = Trajectory::new(vec![(2.0, pose(1.0, 0.5)), (1.0, pose(0.0, 0.0))]);
        let p = traj.pose_at(1.25, 1.0).expect("inside");
        assert!((p.translation.x - 0.25).abs() < 1e-12);
        assert!((p.rotation.angle() - 0.125).abs() < 1e-12);
        assert_eq!(traj.pose_at(2.0, 1.0), Ok(pose(1.0, 0.5)));
        assert_eq!(traj.pose_at(1.0, 1.0), Ok(pose(0.0, 0.0)));
    }

    #[test]
    fn refuses_times_outside_and_gaps() {
        let traj = Trajectory::new(vec![(0.0, pose(0.0, 0.0)), (1.0, pose(1.0, 0.0)), (5.0, pose(2.0, 0.0))]);
        assert!(matches!(traj.pose_at(-0.1, 1.0), Err(PoseLookupError::Before { .. })));
        assert!(matches!(traj.pose_at(5.1, 1.0), Err(PoseLookupError::After { .. })));
        assert!(matches!(traj.pose_at(3.0, 1.0), Err(PoseLookupError::Gap { .. })));
        assert!(traj.pose_at(3.0, 4.0).is_ok());
        // On a sample, up to the tolerance, whatever the gap after it.
        assert_eq!(traj.pose_at(1.0 + 1e-7, 1.0), Ok(pose(1.0, 0.0)));
        assert_eq!(Trajectory::default().pose_at(0.0, 1.0), Err(PoseLookupError::Empty));
    }

    #[test]
    fn parses_tum_and_names_bad_lines() {
        let traj =
            Trajectory::parse_tum("# tum\n1.0 1 2 3 0 0 0 1\n\n2.0,4,5,6,0,0,0.7071068,0.7071068\n").expect("valid");
        assert_eq!(traj.len(), 2);
        let p = traj.pose_at(2.0, 2.0).expect("end");
        assert!((p.rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
        let err = Trajectory::parse_tum("1 2 3\n").expect_err("short");
        assert!(err.contains("line 1") && err.contains("8"), "{err}");
        let err = Trajectory::parse_tum("1.0 1 2 3 0 0 0 1\n2.0 1 2 x 0 0 0 1\n").expect_err("bad number");
        assert!(err.contains("line 2") && err.contains("\"x\""), "{err}");
        let err = Trajectory::parse_tum("1.0 1 2 3 0 0 0 2\n").expect_err("norm");
        assert!(err.contains("norm"), "{err}");
    }
}
