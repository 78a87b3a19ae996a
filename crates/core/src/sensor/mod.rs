//! Sensor models, measurements and frames.
//!
//! A [`Frame`] is one measurement plus the pose `T_world_sensor` it was
//! taken from. NaN, infinite, zero and out-of-range returns are "no return";
//! whether such a ray clears space up to the maximum range is the caller's
//! choice (`clear_no_return`), as real sensors differ.

mod lidar;
mod model;
mod pinhole;
mod planar;
mod points;
mod pose;

pub use lidar::{LidarScan, SpinningLidar, MAX_RINGS};
pub use model::{ReturnBatch, SensorModel, View, RETURN_BATCH};
pub use pinhole::{raw_depth_m, DepthData, DepthImage, PinholeCamera, MAX_IMAGE_PIXELS};
pub use planar::{LaserScan, PlanarLidar};
pub use points::PointSensor;
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

/// What produced a measurement and how to interpret it: the sensor kinds,
/// each a [`SensorModel`] (see [`model`]) whose calls the methods below
/// hand on through [`with_model!`] and [`with_frame_model!`].
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

/// Runs `$body` with `$model` bound to `$sensor`'s [`SensorModel`]: the
/// one place, beside [`with_frame_model!`], that lists the sensor kinds.
macro_rules! with_model {
    ($sensor:expr, |$model:ident| $body:expr) => {
        match $sensor {
            Sensor::Depth($model) => $body,
            Sensor::Lidar($model) => $body,
            Sensor::Points(range) => {
                let $model = &PointSensor(*range);
                $body
            }
            Sensor::Planar => {
                let $model = &PlanarLidar;
                $body
            }
        }
    };
}

/// Runs `$body` with `$model` bound to the [`SensorModel`] that reads
/// measurement `$m` of `$sensor`, and `$data` to the measurement: the
/// sensor's own, or a point cloud, which every 3D sensor may deliver (read
/// with the sensor's range limits); `$other` for any other pairing.
macro_rules! with_frame_model {
    ($sensor:expr, $m:expr, |$model:ident, $data:ident| $body:expr, $other:expr) => {
        match ($sensor, $m) {
            (Sensor::Depth($model), Measurement::Depth($data)) => $body,
            (Sensor::Lidar($model), Measurement::Lidar($data)) => $body,
            (Sensor::Planar, Measurement::Scan($data)) => {
                let $model = &PlanarLidar;
                $body
            }
            (s @ (Sensor::Depth(_) | Sensor::Lidar(_) | Sensor::Points(_)), Measurement::Points($data)) => {
                let $model = &PointSensor(s.range());
                $body
            }
            _ => $other,
        }
    };
}

impl Sensor {
    /// Checks the sensor's parameters.
    pub fn validate(&self) -> Result<(), CoreError> {
        with_model!(self, |model| model.validate())
    }

    /// Checks that `frame` is a valid measurement of this sensor taken from
    /// a valid pose, with at least one ray.
    pub fn check(&self, frame: &Frame) -> Result<(), CoreError> {
        check_pose(&frame.t_world_sensor)?;
        let m = &frame.measurement;
        with_frame_model!(
            self,
            m,
            |model, data| model.check(data),
            Err(CoreError::BadMeasurement(format!("a {} measurement from a {} sensor", m.kind(), self.kind())))
        )
    }

    /// The kind in words.
    pub fn kind(&self) -> &'static str {
        fn kind<M: SensorModel>(_: &M) -> &'static str {
            M::KIND
        }
        with_model!(self, |model| kind(model))
    }

    /// The kind's name as `[sensor] kind` spells it: `depth`, `lidar`,
    /// `points` or `planar`.
    pub fn name(&self) -> &'static str {
        fn name<M: SensorModel>(_: &M) -> &'static str {
            M::NAME
        }
        with_model!(self, |model| name(model))
    }

    /// Whether volumetric projection can interpret this sensor's own
    /// measurements.
    pub fn supports_projection(&self) -> bool {
        fn projects<M: SensorModel>(_: &M) -> bool {
            M::PROJECTS
        }
        with_model!(self, |model| projects(model))
    }

    /// The range of the sensor's valid returns (a planar LiDAR's scans
    /// carry their own: unbounded here).
    pub fn range(&self) -> RangeLimits {
        with_model!(self, |model| model.range())
    }

    /// The longest ray this sensor casts for measurement `m`, metres (for
    /// sizing searches).
    pub fn max_range_m(&self, m: &Measurement) -> f32 {
        with_frame_model!(self, m, |model, data| model.range_of(data).max_m, 0.0)
    }

    /// Every ray of a checked measurement, in the sensor frame. Rays with no
    /// return are included, reaching the maximum range, when `clear_no_return`.
    pub fn rays(&self, m: &Measurement, clear_no_return: bool, out: &mut Vec<SensorRay>) {
        out.clear();
        with_frame_model!(self, m, |model, data| model.rays(data, clear_no_return, out), ())
    }

    /// Calls `f` with the points of every return of a checked measurement
    /// (sensor frame, metres), a [`ReturnBatch`] at a time, from the
    /// host's threads in any order: a depth image's pixels row by row in
    /// parallel, other measurements through their [`Self::rays`] (kept in
    /// `rays`).
    pub fn par_returns(&self, m: &Measurement, rays: &mut Vec<SensorRay>, f: impl Fn(&ReturnBatch) + Sync) {
        with_frame_model!(self, m, |model, data| model.par_returns(data, rays, f), ())
    }

    /// The measurement as volumetric projection sees it; `None` for a
    /// measurement projection cannot interpret (point clouds), or one of
    /// another sensor.
    #[inline]
    pub fn view<'a>(&'a self, m: &'a Measurement) -> Option<View<'a>> {
        match (self, m) {
            (Sensor::Depth(model), Measurement::Depth(data)) => model.view(data),
            (Sensor::Lidar(model), Measurement::Lidar(data)) => model.view(data),
            (Sensor::Planar, Measurement::Scan(data)) => PlanarLidar.view(data),
            _ => None,
        }
    }

    /// Where point `p` (sensor frame) falls in measurement `m`.
    #[inline]
    pub fn project(&self, m: &Measurement, p: [f32; 3]) -> Projection {
        self.view(m).map_or(Projection::Unseen, |v| v.project(p))
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
        self.values()
            * match self {
                Measurement::Depth(d) => match &d.data {
                    DepthData::Metres(_) => 4,
                    DepthData::U16 { .. } => 2,
                },
                Measurement::Points(_) => 12,
                Measurement::Lidar(_) | Measurement::Scan(_) => 4,
            }
    }

    /// The measurement's values: pixels, ranges or points, each at most
    /// one return.
    pub fn values(&self) -> usize {
        match self {
            Measurement::Depth(d) => match &d.data {
                DepthData::Metres(v) => v.len(),
                DepthData::U16 { values, .. } => values.len(),
            },
            Measurement::Lidar(s) => s.ranges.len(),
            Measurement::Points(p) => p.points.len(),
            Measurement::Scan(s) => s.ranges.len(),
        }
    }
}

#[inline]
pub(crate) fn norm(p: [f32; 3]) -> f32 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

#[inline]
pub(crate) fn classify(point_m: f32, measured_m: f32, range: &RangeLimits) -> Projection {
    if range.accepts(measured_m) {
        Projection::Return { point_m, measured_m }
    } else {
        Projection::NoReturn { point_m, max_m: range.max_m }
    }
}
