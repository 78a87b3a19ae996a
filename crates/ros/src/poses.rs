//! Where a sensor message's pose comes from, for a recording and a live
//! node alike: a pose topic (odometry, stamped poses or transforms) or the
//! `/tf` tree, then the sensor's extrinsics; and a sensor message's
//! measurement.

use super::msg::{Message, StampedTransform};
use super::tf::TfBuffer;
use super::RosOptions;
use edtmap::config::SensorKind;
use edtmap_core::sensor::Measurement;
use edtmap_io::trajectory::Trajectory;
use nalgebra::Isometry3;

/// The robot's poses so far.
#[derive(Debug, Clone)]
pub enum Poses {
    /// `T_world_body` samples of one topic.
    Topic(Trajectory),
    /// The transform tree, with the fixed frame.
    Tf(TfBuffer, Option<String>),
}

impl Poses {
    /// Empty poses of the kind `is_tf` says.
    pub fn new(is_tf: bool, opts: &RosOptions) -> Self {
        if is_tf {
            Poses::Tf(TfBuffer::default(), opts.world_frame.clone())
        } else {
            Poses::Topic(Trajectory::default())
        }
    }

    /// Whether no pose has come yet.
    pub fn is_empty(&self) -> bool {
        match self {
            Poses::Topic(t) => t.is_empty(),
            Poses::Tf(tf, _) => tf.edges() == 0,
        }
    }

    /// Adds the poses of `msg`; `is_static` for `/tf_static`. A pose in
    /// another frame than the configured world frame is an error.
    pub fn add(&mut self, msg: &Message, is_static: bool, opts: &RosOptions) -> Result<(), String> {
        let one = |t: &StampedTransform| -> Result<(), String> {
            if let Some(world) = &opts.world_frame {
                let world = world.trim_start_matches('/');
                if t.header.frame_id.trim_start_matches('/') != world {
                    return Err(format!(
                        "pose topic {} gives poses in frame {}, the config's world_frame is {world}",
                        opts.pose_topic, t.header.frame_id
                    ));
                }
            }
            Ok(())
        };
        match (self, msg) {
            (Poses::Tf(tf, _), Message::Tf(ts)) => ts.iter().for_each(|t| tf.insert(t, is_static)),
            (Poses::Topic(traj), Message::Odometry(t) | Message::PoseStamped(t) | Message::TransformStamped(t)) => {
                one(t)?;
                traj.push(t.header.stamp_s(), t.transform);
            }
            (_, other) => return Err(format!("a {} is not a pose here", other.type_name())),
        }
        Ok(())
    }

    /// Drops poses older than `t` (one before it kept), bounding a live
    /// node's history.
    pub fn forget_before(&mut self, t: f64) {
        match self {
            Poses::Topic(traj) => traj.forget_before(t),
            Poses::Tf(tf, _) => tf.forget_before(t),
        }
    }

    /// The body frame and the fixed frame a message in `frame_id` is
    /// looked up between (`/tf` only).
    fn tf_frames(
        tf: &TfBuffer,
        world: &Option<String>,
        frame_id: &str,
        opts: &RosOptions,
    ) -> Result<(String, String), String> {
        let body = opts.body_frame.as_deref().unwrap_or(frame_id).to_string();
        let world = match world {
            Some(w) => w.clone(),
            None => tf.root_of(&body).ok_or_else(|| {
                format!("frame {body:?} is not in the transform tree (frames known: {})", tf.frames().join(", "))
            })?,
        };
        Ok((world, body))
    }

    /// The latest time a message in `frame_id` has a pose at, if any: a
    /// live node waits for it to pass a message's stamp.
    pub fn latest(&self, frame_id: &str, opts: &RosOptions) -> Option<f64> {
        match self {
            Poses::Topic(traj) => traj.span().map(|s| s.1),
            Poses::Tf(tf, world) => {
                let (world, body) = Self::tf_frames(tf, world, frame_id, opts).ok()?;
                tf.latest_common(&world, &body)
            }
        }
    }

    /// `T_world_sensor` at `stamp_s` for a message in `frame_id` of a
    /// sensor mounted at `t_body_sensor`.
    pub fn sensor_pose(
        &self,
        stamp_s: f64,
        frame_id: &str,
        t_body_sensor: &Isometry3<f64>,
        opts: &RosOptions,
    ) -> Result<Isometry3<f64>, String> {
        let gap = opts.max_pose_gap_s;
        let t_world_body = match self {
            Poses::Topic(traj) => {
                traj.pose_at(stamp_s, gap).map_err(|e| format!("pose topic {}: {e}", opts.pose_topic))?
            }
            Poses::Tf(tf, world) => {
                let (world, body) = Self::tf_frames(tf, world, frame_id, opts)?;
                tf.lookup(&world, &body, stamp_s, gap)?
            }
        };
        Ok(t_world_body * t_body_sensor)
    }
}

/// The measurement of a decoded sensor message, with its stamp and frame.
pub fn measurement(msg: Message, depth_scale_m: f32) -> Result<(Measurement, i64, String), String> {
    match msg {
        Message::PointCloud2(m) => Ok((Measurement::Points(m.xyz()?), m.header.stamp_ns, m.header.frame_id)),
        Message::Image(m) => Ok((Measurement::Depth(m.depth(depth_scale_m)?), m.header.stamp_ns, m.header.frame_id)),
        Message::LaserScan(m) => Ok((Measurement::Scan(m.scan()?), m.header.stamp_ns, m.header.frame_id)),
        other => Err(format!("{} is not a sensor message", other.type_name())),
    }
}

/// The ROS message that carries a sensor kind's measurements, live and
/// recorded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorMessage {
    /// `sensor_msgs/PointCloud2`: point clouds (`kind = "points"`).
    PointCloud2,
    /// `sensor_msgs/Image`, with its `sensor_msgs/CameraInfo`: depth
    /// images (`kind = "depth"`).
    Image,
    /// `sensor_msgs/LaserScan`: planar scans (`kind = "planar"`).
    LaserScan,
}

impl SensorMessage {
    /// The message carrying measurements of `kind`; `None` for a spinning
    /// LiDAR's range images, which no ROS message carries (its drivers
    /// publish point clouds: `kind = "points"`).
    pub fn of(kind: SensorKind) -> Option<Self> {
        match kind {
            SensorKind::Points => Some(SensorMessage::PointCloud2),
            SensorKind::Depth => Some(SensorMessage::Image),
            SensorKind::Planar => Some(SensorMessage::LaserScan),
            SensorKind::Lidar => None,
        }
    }

    /// The type's name within `sensor_msgs` (`Image`).
    pub fn name(self) -> &'static str {
        match self {
            SensorMessage::PointCloud2 => "PointCloud2",
            SensorMessage::Image => "Image",
            SensorMessage::LaserScan => "LaserScan",
        }
    }

    /// The type as `package/Type` (`sensor_msgs/Image`).
    pub fn ros_type(self) -> String {
        format!("sensor_msgs/{}", self.name())
    }
}
