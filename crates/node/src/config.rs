//! `[ros]`: what `edtmap node` subscribes to and publishes, in the
//! vocabulary of `[dataset]` (the replay of a recording). The section sits
//! in the configuration file beside the mapper's; [`RosSection::parse`]
//! reads it from the file's text.

use edtmap::config::{sections, Limit, DEPTH_SCALE_M, OFFSET_M, POSE_GAP_S, WORLD_M};
use edtmap::{CoreError, MapError};
use edtmap_ros::config::{sensor_in_body, RECORDING_MAX_POSE_GAP_S};
use nalgebra::Isometry3;
use serde::Deserialize;
use std::path::PathBuf;

/// How long a sensor message may wait for its pose, seconds.
const POSE_WAIT_S: Limit =
    Limit { lo: 0.0, lo_open: false, hi: 60.0, hi_open: false, accepted: "must be finite, in [0, 60] seconds" };
/// Output rates, hertz (0: never).
const RATE_HZ: Limit = Limit {
    lo: 0.0,
    lo_open: false,
    hi: 1000.0,
    hi_open: false,
    accepted: "must be finite, in [0, 1000] Hz (0: never)",
};
/// Map clearing radius, metres (0: never).
const CLEARING_M: Limit = Limit {
    lo: 0.0,
    lo_open: false,
    hi: 1e5,
    hi_open: false,
    accepted: "must be finite, in [0, 1e5] metres (0: never)",
};
/// Map clearing period, seconds.
const CLEARING_S: Limit =
    Limit { lo: 0.01, lo_open: false, hi: 3600.0, hi_open: false, accepted: "must be finite, in [0.01, 3600] seconds" };
/// How much transform history a node keeps, seconds.
const TF_HISTORY_S: Limit =
    Limit { lo: 0.1, lo_open: false, hi: 3600.0, hi_open: false, accepted: "must be finite, in [0.1, 3600] seconds" };

/// Which message type carries the poses when `pose_topic` is not `/tf`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseType {
    /// `nav_msgs/Odometry`.
    #[default]
    Odometry,
    /// `geometry_msgs/PoseStamped`.
    PoseStamped,
    /// `geometry_msgs/TransformStamped`.
    TransformStamped,
    /// `tf2_msgs/TFMessage`: the transform tree (with `static_tf_topic`).
    Tf,
}

/// Which request/reply layout services use. ROS 2's two usual RMW
/// implementations put the request id in different places
/// (`rmw_cyclonedds_cpp` in a 16-byte header of the sample,
/// `rmw_fastrtps_cpp` in the RTPS inline QoS); the node tells them apart
/// per request and answers both whatever this says, so only `auto` is
/// needed; the others are accepted so older configs load.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ServiceMapping {
    /// Each request answered in the layout it came in.
    #[default]
    Auto,
    /// Formerly: only `rmw_cyclonedds_cpp` clients; now as `auto`.
    Cyclone,
    /// Formerly: only `rmw_fastrtps_cpp` clients; now as `auto`.
    Enhanced,
}

/// Whose intrinsics a depth camera is mapped with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Intrinsics {
    /// The camera info's (as `[dataset] intrinsics = "recording"`): images
    /// wait for the first camera info; it replaces `[sensor]`'s before the
    /// first frame.
    #[default]
    CameraInfo,
    /// `[sensor]`'s, always.
    Config,
}

/// What `/edtmap/occupied_pointcloud` covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OccupiedScope {
    /// The current local volume.
    #[default]
    Window,
    /// The whole map.
    Map,
}

/// `[ros]`: the live node's topics, frames and outputs.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RosSection {
    /// Node namespace (`/` or `/robot1`); outputs go to
    /// `NAMESPACE/edtmap/...`.
    pub namespace: String,
    /// A lone `[sensor]`'s topic (default `/points`): `PointCloud2` for
    /// `kind = "points"`, `Image` (`16UC1` or `32FC1`) for `"depth"`,
    /// `LaserScan` for `"planar"`. Several sensors are `[[sensors]]`
    /// entries, each with its own `topic`.
    pub sensor_topic: Option<String>,
    /// A lone depth camera's intrinsics (default: the image topic's
    /// sibling `camera_info`); `[[sensors]]` entries give their own.
    pub camera_info_topic: Option<String>,
    /// Where poses come from: `/tf` (the default), or a topic of
    /// `pose_type`.
    pub pose_topic: String,
    /// The message type on `pose_topic` when it is not `/tf`.
    pub pose_type: Option<PoseType>,
    /// With `/tf`: the static transforms' topic.
    pub static_tf_topic: String,
    /// The fixed frame; outputs are published in it. With `/tf` the
    /// default is the root of the tree, with a pose topic the poses' frame.
    pub world_frame: Option<String>,
    /// With `/tf`: the robot frame the extrinsics are from (default: the
    /// sensor message's own frame, so the tree supplies the extrinsics).
    pub body_frame: Option<String>,
    /// A lone sensor's pose on the robot, `T_body_sensor`, as `[x, y, z,
    /// qx, qy, qz, qw]`; identity by default. `[[sensors]]` entries give
    /// their own.
    pub sensor_in_body: Option<[f64; 7]>,
    /// Largest time between two poses a frame is interpolated across, seconds.
    pub max_pose_gap_s: f64,
    /// How long a sensor message waits for a pose at its stamp, seconds;
    /// then it is dropped and counted (`missing transform`).
    pub pose_wait_s: f64,
    /// For this long after the node starts, while discovery settles, a
    /// sensor message whose transform has not come keeps waiting (the
    /// newest few) until this much time has passed since the start,
    /// seconds; then `pose_wait_s` alone applies.
    pub startup_pose_wait_s: f64,
    /// Transform history kept, seconds.
    pub tf_history_s: f64,
    /// Metres per unit of 16-bit depth images.
    pub depth_scale_m: f32,
    /// Depth cameras: `camera_info` (the default: the camera's own
    /// intrinsics) or `config` (`[sensor]`'s).
    pub intrinsics: Intrinsics,
    /// `/edtmap/esdf_pointcloud` rate, Hz (0: never).
    pub esdf_pointcloud_hz: f64,
    /// Heights of the voxels `/edtmap/esdf_pointcloud` holds, `[lowest,
    /// highest]`, metres, world frame: by default a ground robot's 0 to
    /// 2 m, so the cloud stays small enough for a default-QoS subscriber.
    pub esdf_pointcloud_z_m: [f64; 2],
    /// `/edtmap/occupied_pointcloud` rate, Hz (0: never).
    pub occupied_pointcloud_hz: f64,
    /// What the occupied cloud covers: `window` or `map`.
    pub occupied_scope: OccupiedScope,
    /// `/edtmap/distance_slice` and `/edtmap/occupancy_grid` rate, Hz (0: never).
    pub slice_hz: f64,
    /// Height of the slice, metres, world frame.
    pub slice_height_m: f64,
    /// Service request layout: `auto` (the default; every value answers
    /// `rmw_fastrtps_cpp` and `rmw_cyclonedds_cpp` clients alike).
    pub service_mapping: ServiceMapping,
    /// Forget the map farther than this from the sensor (metres; 0: keep
    /// everything), so a node that runs for hours holds a bounded map.
    /// Needs `[global] mode = "exact"`.
    pub map_clearing_radius_m: f64,
    /// How often the map is cleared, seconds.
    pub map_clearing_period_s: f64,
    /// Where to save the whole map before each clearing that drops
    /// something (replaced atomically each time), so what is forgotten is
    /// kept on disk; nothing by default.
    pub map_clearing_save: Option<PathBuf>,
    /// Where to save the map when the node stops (SIGINT); nothing by default.
    pub save_on_exit: Option<PathBuf>,
    /// Only talk over loopback (127.0.0.1), with unicast discovery: for
    /// tests and machines without multicast.
    pub localhost_only: bool,
}

impl Default for RosSection {
    fn default() -> Self {
        RosSection {
            namespace: "/".into(),
            sensor_topic: None,
            camera_info_topic: None,
            pose_topic: "/tf".into(),
            pose_type: None,
            static_tf_topic: "/tf_static".into(),
            world_frame: None,
            body_frame: None,
            sensor_in_body: None,
            max_pose_gap_s: RECORDING_MAX_POSE_GAP_S,
            pose_wait_s: 0.5,
            startup_pose_wait_s: 2.0,
            tf_history_s: 10.0,
            depth_scale_m: 0.001,
            intrinsics: Intrinsics::CameraInfo,
            esdf_pointcloud_hz: 2.0,
            esdf_pointcloud_z_m: [0.0, 2.0],
            occupied_pointcloud_hz: 1.0,
            occupied_scope: OccupiedScope::Window,
            slice_hz: 2.0,
            slice_height_m: 1.0,
            service_mapping: ServiceMapping::Auto,
            map_clearing_radius_m: 0.0,
            map_clearing_period_s: 1.0,
            map_clearing_save: None,
            save_on_exit: None,
            localhost_only: false,
        }
    }
}

fn invalid(field: &'static str, value: String, reason: &'static str) -> CoreError {
    CoreError::InvalidParam { field, value, reason }
}

/// A ROS name: `/` or `/a/b` style, letters, digits and underscores.
fn check_name(field: &'static str, name: &str, absolute: bool) -> Result<(), CoreError> {
    let body = name.strip_prefix('/').unwrap_or(name);
    let word = |p: &str| {
        !p.is_empty()
            && !p.starts_with(|c: char| c.is_ascii_digit())
            && p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    let ok = (absolute && name == "/") || ((!absolute || name.starts_with('/')) && body.split('/').all(word));
    if ok {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("{name:?}"),
            "must be a ROS name: '/'-separated words of letters, digits and underscores, not starting with a digit",
        ))
    }
}

/// The file as `[ros]` sees it.
#[derive(Deserialize)]
struct File {
    #[serde(default)]
    ros: RosSection,
}

impl RosSection {
    /// `[ros]` of a configuration's text (defaults when absent), checked;
    /// `origin` names the text in errors.
    pub fn parse(text: &str, origin: &str) -> Result<RosSection, MapError> {
        let ros = sections::<File>(text, origin)?.ros;
        ros.validate().map_err(|source| MapError::Config { section: "ros", source })?;
        Ok(ros)
    }

    /// Checks every value.
    pub fn validate(&self) -> Result<(), CoreError> {
        check_name("namespace", &self.namespace, true)?;
        if let Some(t) = &self.sensor_topic {
            check_name("sensor_topic", t, false)?;
        }
        check_name("pose_topic", &self.pose_topic, false)?;
        check_name("static_tf_topic", &self.static_tf_topic, false)?;
        if let Some(t) = &self.camera_info_topic {
            check_name("camera_info_topic", t, false)?;
        }
        POSE_GAP_S.f64("max_pose_gap_s", self.max_pose_gap_s)?;
        POSE_WAIT_S.f64("pose_wait_s", self.pose_wait_s)?;
        POSE_WAIT_S.f64("startup_pose_wait_s", self.startup_pose_wait_s)?;
        TF_HISTORY_S.f64("tf_history_s", self.tf_history_s)?;
        DEPTH_SCALE_M.f32("depth_scale_m", self.depth_scale_m)?;
        RATE_HZ.f64("esdf_pointcloud_hz", self.esdf_pointcloud_hz)?;
        WORLD_M.all("esdf_pointcloud_z_m", &self.esdf_pointcloud_z_m)?;
        if self.esdf_pointcloud_z_m[0] > self.esdf_pointcloud_z_m[1] {
            return Err(invalid(
                "esdf_pointcloud_z_m",
                format!("{:?}", self.esdf_pointcloud_z_m),
                "must be [lowest, highest] with lowest <= highest",
            ));
        }
        RATE_HZ.f64("occupied_pointcloud_hz", self.occupied_pointcloud_hz)?;
        RATE_HZ.f64("slice_hz", self.slice_hz)?;
        WORLD_M.f64("slice_height_m", self.slice_height_m)?;
        CLEARING_M.f64("map_clearing_radius_m", self.map_clearing_radius_m)?;
        CLEARING_S.f64("map_clearing_period_s", self.map_clearing_period_s)?;
        if let Some(pose) = &self.sensor_in_body {
            OFFSET_M.all("sensor_in_body", &pose[..3])?;
        }
        if self.pose_type.is_some_and(|t| t != PoseType::Tf) && self.pose_topic.trim_start_matches('/') == "tf" {
            return Err(invalid(
                "pose_type",
                format!("{:?}", self.pose_type),
                "must be \"tf\" (or left out) when pose_topic is /tf",
            ));
        }
        self.t_body_sensor()?;
        Ok(())
    }

    /// The message type on `pose_topic`.
    pub fn pose_type(&self) -> PoseType {
        match self.pose_type {
            Some(t) => t,
            None if self.pose_topic.trim_start_matches('/') == "tf" => PoseType::Tf,
            None => PoseType::Odometry,
        }
    }

    /// `T_body_sensor` from `sensor_in_body`.
    pub fn t_body_sensor(&self) -> Result<Isometry3<f64>, CoreError> {
        sensor_in_body("sensor_in_body", self.sensor_in_body)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_numbers_are_checked_by_field() {
        assert!(RosSection::default().validate().is_ok());
        let ns = |n: &str| RosSection { namespace: n.into(), ..Default::default() }.validate();
        assert!(ns("/robot_1").is_ok() && ns("/a/b").is_ok());
        for bad in ["robot", "/a//b", "/a/", "/1a", "/a-b"] {
            assert!(ns(bad).expect_err(bad).to_string().contains("namespace"), "{bad}");
        }
        let topic = RosSection { sensor_topic: Some("/points 2".into()), ..Default::default() }.validate();
        assert!(topic.expect_err("space").to_string().contains("sensor_topic"));
        let wait = RosSection { pose_wait_s: -1.0, ..Default::default() }.validate();
        assert!(wait.expect_err("negative").to_string().contains("pose_wait_s"));
        let startup = RosSection { startup_pose_wait_s: f64::NAN, ..Default::default() }.validate();
        assert!(startup.expect_err("NaN").to_string().contains("startup_pose_wait_s"));
        let band = RosSection { esdf_pointcloud_z_m: [2.0, 0.0], ..Default::default() }.validate();
        assert!(band.expect_err("upside down").to_string().contains("esdf_pointcloud_z_m"));
        let odom_on_tf = RosSection { pose_type: Some(PoseType::Odometry), ..Default::default() }.validate();
        assert!(odom_on_tf.expect_err("odometry on /tf").to_string().contains("pose_type"));
        let odom = RosSection { pose_topic: "/odom".into(), ..Default::default() };
        assert_eq!(odom.pose_type(), PoseType::Odometry);
        assert_eq!(RosSection::default().pose_type(), PoseType::Tf);
    }
}
