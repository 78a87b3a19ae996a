//! Sensor models, measurements and frames.
//!
//! A [`Frame`] is one measurement plus the pose `T_world_sensor` it was
//! taken from. NaN, infinite, zero and out-of-range returns are "no return";
//! whether such a ray clears space up to the maximum range is the caller's
//! choice (`clear_no_return`), as real sensors differ.

mod lidar;
mod pinhole;
mod planar;
mod pose;

pub use lidar::{LidarScan, SpinningLidar, MAX_RINGS};
pub use pinhole::{raw_depth_m, DepthData, DepthImage, PinholeCamera, MAX_IMAGE_PIXELS};
pub use planar::LaserScan;
pub use pose::{
    check_pose, pose_from_matrix, pose_from_matrix_noted, rotation_from_matrix, rotation_from_quaternion,
    PoseAdjustments, ROTATION_NOTED, ROTATION_TOLERANCE,
};

use crate::CoreError;
use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

/// Valid range of a sensor's returns, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RangeLimits {
    /// Shortest valid return.
    pub min_m: f32,
    /// Longest valid return.
    pub max_m: f32,
}

impl RangeLimits {
    /// Whether `d` is a valid return.
    #[inline]
    pub fn accepts(&self, d: f32) -> bool {
        d.is_finite() && d > 0.0 && d >= self.min_m && d <= self.max_m
    }
}

fn check_range(r: &RangeLimits) -> Result<(), CoreError> {
    if r.min_m.is_finite() && r.max_m.is_finite() && r.min_m >= 0.0 && r.max_m > r.min_m {
        Ok(())
    } else {
        Err(CoreError::InvalidParam {
            field: "range",
            value: format!("{}..{} m", r.min_m, r.max_m),
            reason: "need 0 ≤ min < max, finite",
        })
    }
}

/// What produced a measurement and how to interpret it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Sensor {
    /// A pinhole depth camera.
    Depth(PinholeCamera),
    /// A spinning LiDAR delivering range images.
    Lidar(SpinningLidar),
    /// Any source of 3D points (no ring structure): ray casting only.
    Points(RangeLimits),
    /// A planar LiDAR; each [`LaserScan`] carries its own geometry.
    Planar,
}

/// A point cloud in the sensor frame, metres.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// The points; non-finite points are no return.
    pub points: Vec<[f32; 3]>,
}

/// One measurement, in the sensor frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Measurement {
    /// A depth image from a [`Sensor::Depth`].
    Depth(DepthImage),
    /// A range image from a [`Sensor::Lidar`].
    Lidar(LidarScan),
    /// A point cloud from a [`Sensor::Points`] (or any 3D sensor).
    Points(PointCloud),
    /// A planar scan from a [`Sensor::Planar`].
    Scan(LaserScan),
}

/// A measurement and the pose it was taken from.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Time stamp in seconds.
    pub stamp_s: f64,
    /// Pose of the sensor in the world, `T_world_sensor`.
    pub t_world_sensor: Isometry3<f64>,
    /// The measurement.
    pub measurement: Measurement,
}

/// A ray in the sensor frame, for ray casting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorRay {
    /// Unit direction.
    pub dir: [f32; 3],
    /// Length in metres.
    pub range_m: f32,
    /// Whether the ray ends on a return (else it only clears space).
    pub hit: bool,
}

impl SensorRay {
    /// The ray of a beam along `dir` that measured `d`: a return when `d` is
    /// valid, else a clearing ray to the maximum range when
    /// `clear_no_return`, else none.
    #[inline]
    pub fn from_range(dir: [f32; 3], d: f32, range: &RangeLimits, clear_no_return: bool) -> Option<SensorRay> {
        if range.accepts(d) {
            Some(SensorRay { dir, range_m: d, hit: true })
        } else {
            clear_no_return.then_some(SensorRay { dir, range_m: range.max_m, hit: false })
        }
    }
}

/// Where a point falls in a measurement, for volumetric projection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Outside the sensor's field of view.
    Unseen,
    /// In view, but the beam or pixel there had no return.
    NoReturn {
        /// The point's range in the sensor's metric (depth for cameras).
        point_m: f32,
        /// The sensor's maximum range in the same metric.
        max_m: f32,
    },
    /// In view of a beam or pixel with a return.
    Return {
        /// The point's range in the sensor's metric (depth for cameras).
        point_m: f32,
        /// The measured range in the same metric.
        measured_m: f32,
    },
}

impl Sensor {
    /// Checks the sensor's parameters.
    pub fn validate(&self) -> Result<(), CoreError> {
        match self {
            Sensor::Depth(c) => c.validate(),
            Sensor::Lidar(l) => l.validate(),
            Sensor::Points(r) => check_range(r),
            Sensor::Planar => Ok(()),
        }
    }

    /// Checks that `frame` is a valid measurement of this sensor taken from
    /// a valid pose, with at least one ray.
    pub fn check(&self, frame: &Frame) -> Result<(), CoreError> {
        check_pose(&frame.t_world_sensor)?;
        match (self, &frame.measurement) {
            (Sensor::Depth(c), Measurement::Depth(img)) => c.check(img),
            (Sensor::Lidar(l), Measurement::Lidar(scan)) => l.check(scan),
            (Sensor::Points(_) | Sensor::Lidar(_) | Sensor::Depth(_), Measurement::Points(pc)) => {
                match pc.points.is_empty() {
                    true => Err(CoreError::BadMeasurement("point cloud is empty".into())),
                    false => Ok(()),
                }
            }
            (Sensor::Planar, Measurement::Scan(scan)) => scan.validate(),
            (s, m) => Err(CoreError::BadMeasurement(format!("a {} measurement from a {} sensor", m.kind(), s.kind()))),
        }
    }

    /// Short name of the sensor kind.
    pub fn kind(&self) -> &'static str {
        match self {
            Sensor::Depth(_) => "depth camera",
            Sensor::Lidar(_) => "spinning LiDAR",
            Sensor::Points(_) => "point cloud",
            Sensor::Planar => "planar LiDAR",
        }
    }

    /// Whether volumetric projection can interpret this sensor's measurements.
    pub fn supports_projection(&self) -> bool {
        !matches!(self, Sensor::Points(_))
    }

    /// The range of the sensor's valid returns (a planar LiDAR's scans
    /// carry their own: unbounded here).
    pub fn range(&self) -> RangeLimits {
        match self {
            Sensor::Depth(c) => c.range,
            Sensor::Lidar(l) => l.range,
            Sensor::Points(r) => *r,
            Sensor::Planar => RangeLimits { min_m: 0.0, max_m: f32::MAX },
        }
    }

    /// The longest ray this sensor casts, metres (for sizing searches).
    pub fn max_range_m(&self, m: &Measurement) -> f32 {
        match (self, m) {
            (Sensor::Depth(c), _) => c.range.max_m,
            (Sensor::Lidar(l), _) => l.range.max_m,
            (Sensor::Points(r), _) => r.max_m,
            (Sensor::Planar, Measurement::Scan(s)) => s.range.max_m,
            (Sensor::Planar, _) => 0.0,
        }
    }

    /// Every ray of a checked measurement, in the sensor frame. Rays with no
    /// return are included, reaching the maximum range, when `clear_no_return`.
    pub fn rays(&self, m: &Measurement, clear_no_return: bool, out: &mut Vec<SensorRay>) {
        out.clear();
        match (self, m) {
            (Sensor::Depth(c), Measurement::Depth(img)) => c.rays(img, clear_no_return, out),
            (Sensor::Lidar(l), Measurement::Lidar(scan)) => l.rays(scan, clear_no_return, out),
            (s, Measurement::Points(pc)) => points_rays(&pc.points, s.range(), clear_no_return, out),
            (_, Measurement::Scan(scan)) => scan.rays(clear_no_return, out),
            _ => {}
        }
    }

    /// Calls `f` with the point of every return of a checked measurement
    /// (sensor frame, metres), from the host's threads in any order: a
    /// depth image's pixels row by row in parallel, other measurements
    /// through their [`Self::rays`] (kept in `rays`).
    pub fn par_returns(&self, m: &Measurement, rays: &mut Vec<SensorRay>, f: impl Fn([f64; 3]) + Sync) {
        use rayon::prelude::*;
        if let (Sensor::Depth(c), Measurement::Depth(img)) = (self, m) {
            return c.par_returns(img, f);
        }
        self.rays(m, false, rays);
        rays.par_iter()
            .with_min_len(1024)
            .filter(|r| r.hit)
            .for_each(|r| f(r.dir.map(|c| c as f64 * r.range_m as f64)));
    }

    /// Where point `p` (sensor frame) falls in measurement `m`.
    #[inline]
    pub fn project(&self, m: &Measurement, p: [f32; 3]) -> Projection {
        match (self, m) {
            (Sensor::Depth(c), Measurement::Depth(img)) => match c.project(p) {
                None => Projection::Unseen,
                Some(i) => classify(p[2], img.depth_m(i), &c.range),
            },
            (Sensor::Lidar(l), Measurement::Lidar(scan)) => match l.project(p) {
                None => Projection::Unseen,
                Some((r, b)) => classify(norm(p), scan.ranges[r * l.azimuth_bins + b], &l.range),
            },
            (Sensor::Planar, Measurement::Scan(scan)) => match scan.beam(p) {
                None => Projection::Unseen,
                Some(i) => classify((p[0] * p[0] + p[1] * p[1]).sqrt(), scan.ranges[i], &scan.range),
            },
            _ => Projection::Unseen,
        }
    }
}

impl Sensor {
    /// Whether the beam nearest to the direction of `p` passes within
    /// `radius_m` of `p`. A LiDAR's rings are sparse: a voxel between two
    /// rings is crossed by no beam, and the nearest ring says nothing about
    /// it. Pixels and planar beams are dense enough to be taken as passing.
    pub fn beam_passes_within(&self, p: [f32; 3], radius_m: f32) -> bool {
        match self {
            Sensor::Lidar(l) => l.ring_passes_within(p, radius_m),
            _ => true,
        }
    }
}

impl Measurement {
    /// Short name of the measurement kind.
    pub fn kind(&self) -> &'static str {
        match self {
            Measurement::Depth(_) => "depth image",
            Measurement::Lidar(_) => "LiDAR range image",
            Measurement::Points(_) => "point cloud",
            Measurement::Scan(_) => "laser scan",
        }
    }

    /// The measurement's size as the sensor gives it, bytes: its depth
    /// values (4 or 2 bytes each), ranges (4 bytes) or points (12 bytes).
    /// What a backend has to receive at least, to compare its traffic to.
    pub fn bytes(&self) -> usize {
        match self {
            Measurement::Depth(d) => match &d.data {
                DepthData::Metres(v) => 4 * v.len(),
                DepthData::U16 { values, .. } => 2 * values.len(),
            },
            Measurement::Lidar(s) => 4 * s.ranges.len(),
            Measurement::Points(p) => 12 * p.points.len(),
            Measurement::Scan(s) => 4 * s.ranges.len(),
        }
    }
}

#[inline]
pub(crate) fn norm(p: [f32; 3]) -> f32 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

#[inline]
fn classify(point_m: f32, measured_m: f32, range: &RangeLimits) -> Projection {
    if range.accepts(measured_m) {
        Projection::Return { point_m, measured_m }
    } else {
        Projection::NoReturn { point_m, max_m: range.max_m }
    }
}

fn points_rays(points: &[[f32; 3]], limits: RangeLimits, clear_no_return: bool, out: &mut Vec<SensorRay>) {
    for p in points {
        let d = norm(*p);
        if !d.is_finite() || d == 0.0 {
            continue;
        }
        let dir = p.map(|c| c / d);
        if limits.accepts(d) {
            out.push(SensorRay { dir, range_m: d, hit: true });
        } else if clear_no_return && d > limits.max_m {
            // A point past the maximum range still shows free space up to it.
            out.push(SensorRay { dir, range_m: limits.max_m, hit: false });
        }
    }
}
