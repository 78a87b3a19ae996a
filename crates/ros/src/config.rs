//! `[dataset]`: how a recording becomes frames (`edtmap run --dataset`,
//! the Python package's `read_recording`). The section sits in the
//! configuration file beside the mapper's; [`DatasetSection::parse`]
//! reads it from the file's text.

use crate::SensorTopic;
pub use edtmap::config::sensor_in_body;
use edtmap::config::{sections, Config, DEPTH_SCALE_M, OFFSET_M, POSE_GAP_S};
use edtmap::{CoreError, MapError};
use edtmap_io::dataset::DatasetOptions;
use nalgebra::Isometry3;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// What a replay does with a frame it cannot use.
///
/// The same rule holds for every kind of recording (3DMatch and TUM
/// folders, PCD/PLY/KITTI cloud folders, ROS bags, MCAP files). A problem
/// of the recording as a whole refuses the run before anything is mapped,
/// whatever this says: the folder or file is missing or holds no frames,
/// a file serving every frame (trajectory, `poses.txt`, `times.txt`,
/// `depth.txt`, `camera-intrinsics.txt`) cannot be read, no frame has a
/// pose, a topic is absent, the config does not fit. A problem of one
/// frame is this setting's: its image, cloud or message cannot be read or
/// decoded, its pose file is missing or bad, no pose covers its stamp, the
/// mapper refuses it. Files named like frames that are not frames
/// (`frame-abc.depth.png`) are left out with a warning.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnError {
    /// Report the frame (a warning, `skipped` in `report.json`), leave it
    /// out, go on.
    #[default]
    Skip,
    /// Stop at the frame: keep and write what was integrated, then fail.
    Stop,
}

/// Where a depth camera's intrinsics and image size come from when both
/// the recording and `[sensor]` give them (`[dataset] intrinsics`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IntrinsicsSource {
    /// The recording's own calibration: a folder's `camera-intrinsics.txt`
    /// with its first image's size, a ROS camera info. `[sensor] fx, fy,
    /// cx, cy, width, height` serve recordings without one (TUM); where
    /// they differ from the recording's, a warning names both.
    #[default]
    Recording,
    /// `[sensor]`'s, always: the recording's calibration is not used.
    Config,
}

/// Default of `[dataset] max_pose_gap_s`, seconds: defined beside the
/// interpolation, and more lenient than the library's default for folders
/// opened from code (see both there).
pub use edtmap_io::trajectory::RECORDING_MAX_POSE_GAP_S;

/// `[dataset]`: how to read a recording (`edtmap run --dataset PATH`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DatasetSection {
    /// Metres per unit of 16-bit depth images (0.001: millimetres; TUM: 0.0002).
    pub depth_scale_m: f32,
    /// `skip` (default) or `stop` at a frame that cannot be used; see
    /// [`OnError`] for what is a frame's problem and what the recording's.
    pub on_error: OnError,
    /// Depth cameras: `recording` (default: the recording's calibration
    /// wins over `[sensor]`'s, with a warning where they differ) or
    /// `config` (`[sensor]`'s always).
    pub intrinsics: IntrinsicsSource,
    /// Largest time between two poses a frame is interpolated across, seconds.
    pub max_pose_gap_s: f64,
    /// Folders: a TUM trajectory (`t tx ty tz qx qy qz qw`) giving the
    /// poses; relative to the recording's folder.
    pub trajectory: Option<PathBuf>,
    /// ROS: the sensor topic (`PointCloud2`, `Image` or `LaserScan`).
    pub sensor_topic: Option<String>,
    /// ROS: camera intrinsics for depth images (default: the image topic's sibling `camera_info`).
    pub camera_info_topic: Option<String>,
    /// ROS: the poses (`Odometry`, `PoseStamped`, `TransformStamped`, or `/tf`).
    pub pose_topic: Option<String>,
    /// ROS with `/tf`: the static transforms' topic.
    pub static_tf_topic: String,
    /// ROS: the fixed frame (default with `/tf`: the root of the tree).
    pub world_frame: Option<String>,
    /// ROS with `/tf`: the robot frame the extrinsics are from (default: the sensor's own frame).
    pub body_frame: Option<String>,
    /// ROS: the sensor's pose on the robot, `T_body_sensor`, as
    /// `[x, y, z, qx, qy, qz, qw]` (metres, unit quaternion); identity by default.
    pub sensor_in_body: Option<[f64; 7]>,
}

impl Default for DatasetSection {
    fn default() -> Self {
        DatasetSection {
            depth_scale_m: 0.001,
            on_error: OnError::Skip,
            intrinsics: IntrinsicsSource::Recording,
            max_pose_gap_s: RECORDING_MAX_POSE_GAP_S,
            trajectory: None,
            sensor_topic: None,
            camera_info_topic: None,
            pose_topic: None,
            static_tf_topic: "/tf_static".into(),
            world_frame: None,
            body_frame: None,
            sensor_in_body: None,
        }
    }
}

/// The file as `[dataset]` sees it.
#[derive(Deserialize)]
struct File {
    #[serde(default)]
    dataset: DatasetSection,
}

impl DatasetSection {
    /// `[dataset]` of a configuration's text (defaults when absent),
    /// checked; `origin` names the text in errors.
    pub fn parse(text: &str, origin: &str) -> Result<DatasetSection, MapError> {
        let dataset = sections::<File>(text, origin)?.dataset;
        dataset.validate().map_err(|source| MapError::Config { section: "dataset", source })?;
        Ok(dataset)
    }

    /// How to open the folder recording `dir` (depth scale, the sensor's
    /// range, the camera and whose intrinsics win, the trajectory relative
    /// to `dir`, the pose gap), from this section and `config`'s `[sensor]`.
    pub fn folder_options(&self, config: &Config, dir: &Path) -> Result<DatasetOptions, MapError> {
        let (sensor, _) = config.mapper_params()?;
        Ok(DatasetOptions {
            depth_scale_m: self.depth_scale_m,
            range: sensor.range(),
            intrinsics: config.sensor.camera.intrinsics(),
            folder_intrinsics: self.intrinsics == IntrinsicsSource::Recording,
            trajectory: self.trajectory.as_ref().map(|t| dir.join(t)),
            max_pose_gap_s: self.max_pose_gap_s,
        })
    }

    /// Checks the values that need no recording.
    pub fn validate(&self) -> Result<(), CoreError> {
        DEPTH_SCALE_M.f32("depth_scale_m", self.depth_scale_m)?;
        POSE_GAP_S.f64("max_pose_gap_s", self.max_pose_gap_s)?;
        if let Some(pose) = &self.sensor_in_body {
            OFFSET_M.all("sensor_in_body", &pose[..3])?;
        }
        self.t_body_sensor()?;
        Ok(())
    }

    /// `T_body_sensor` from `sensor_in_body`.
    pub fn t_body_sensor(&self) -> Result<Isometry3<f64>, CoreError> {
        sensor_in_body("sensor_in_body", self.sensor_in_body)
    }
}

/// What a section (`[dataset]`, `[ros]`) says of a config's lone sensor:
/// its topic, camera info topic and mount.
#[derive(Debug, Clone, Copy)]
pub struct LoneSensor<'a> {
    /// The section's name in messages (`[dataset]`).
    pub section: &'static str,
    /// Its `sensor_topic`.
    pub topic: Option<&'a str>,
    /// Its `camera_info_topic`.
    pub camera_info_topic: Option<&'a str>,
    /// Its `sensor_in_body`.
    pub sensor_in_body: Option<[f64; 7]>,
    /// What the topic is needed for, in messages (`to replay a ROS bag`).
    pub needed: &'static str,
}

/// Each of `config`'s sensors with its topic, camera info topic and mount,
/// for a recording's replay and the live node alike. A `[[sensors]]` entry
/// gives its own (`topic`, `camera_info_topic`, `sensor_in_body`); a lone
/// sensor may take them from `lone`'s section instead, not from both.
/// With several sensors, the section's are refused: they would be
/// ambiguous. The error says what to set.
pub fn sensor_topics(config: &Config, lone: &LoneSensor<'_>) -> Result<Vec<SensorTopic>, String> {
    let section = lone.section;
    let alone = config.other_sensors.is_empty();
    if !alone {
        let set = [
            ("sensor_topic", lone.topic.is_some()),
            ("camera_info_topic", lone.camera_info_topic.is_some()),
            ("sensor_in_body", lone.sensor_in_body.is_some()),
        ];
        if let Some((field, _)) = set.iter().find(|(_, set)| *set) {
            return Err(format!(
                "{section} {field} is for a lone [sensor]: with [[sensors]], each entry gives its own (topic, \
                 camera_info_topic, sensor_in_body)"
            ));
        }
    }
    let mut out = Vec::new();
    for s in config.sensors() {
        let which = format!("[[sensors]] {:?}", s.name());
        let both = |field: &str| format!("{field} is set in both {which} and {section}: set it in one place");
        let topic = match (&s.topic, lone.topic) {
            (Some(_), Some(_)) => return Err(both("the sensor topic")),
            (Some(t), None) => t.clone(),
            (None, Some(t)) => t.to_string(),
            (None, None) if alone => {
                return Err(format!("invalid {section} sensor_topic = missing: required {}", lone.needed))
            }
            (None, None) => return Err(format!("{which} has no topic: each sensor needs one {}", lone.needed)),
        };
        let camera_info_topic = match (&s.camera_info_topic, lone.camera_info_topic) {
            (Some(_), Some(_)) => return Err(both("camera_info_topic")),
            (Some(t), _) => Some(t.clone()),
            (None, t) => t.map(str::to_string),
        };
        let t_body_sensor = match (s.sensor_in_body, lone.sensor_in_body) {
            (Some(_), Some(_)) => return Err(both("sensor_in_body")),
            (Some(_), None) => s.t_body_sensor().map_err(|e| format!("{which} {e}"))?,
            (None, pose) => sensor_in_body("sensor_in_body", pose).map_err(|e| format!("{section} {e}"))?,
        };
        out.push(SensorTopic { topic, camera_info_topic, t_body_sensor });
    }
    Ok(out)
}
