//! Opening any recording edtmap reads (a ROS 1 bag, a ROS 2 MCAP file, a
//! folder of depth images or point clouds) with a configuration, for
//! `edtmap run --dataset` and the Python package's `read_recording`.

use std::path::Path;

use edtmap::config::{Config, SensorKind};
use edtmap::sensor::Frame;
use edtmap::MapError;
use edtmap_io::dataset::Dataset;

use crate::config::{DatasetSection, IntrinsicsSource};
use crate::{is_recording, RosOptions, RosReplay};

/// The frames of a recording.
#[derive(Debug)]
pub enum Recording {
    /// A folder of depth images or point clouds.
    Folder(Dataset),
    /// A ROS 1 bag or ROS 2 MCAP file.
    Ros(Box<RosReplay>),
}

/// A frame of a recording that did not come out.
#[derive(Debug, Clone)]
pub struct RecordingFailure {
    /// The frame's position in the recording.
    pub index: usize,
    /// File, topic, stamp and reason.
    pub message: String,
    /// Whether the recording is damaged here, so nothing after it can be
    /// read (otherwise only this frame is lost).
    pub damage: bool,
}

impl Recording {
    /// Opens the recording at `path` as `dataset` says, with `config`'s
    /// sensor (`origin` names the config in errors). For a depth camera, the
    /// recording's calibration (a folder's `camera-intrinsics.txt` with its
    /// first image's size, a ROS camera info) replaces `[sensor]`'s, with a
    /// warning where they differ, unless `[dataset] intrinsics = "config"`.
    pub fn open(
        path: &Path,
        config: &mut Config,
        dataset: &DatasetSection,
        origin: &str,
    ) -> Result<Recording, MapError> {
        let in_dataset = |e| MapError::Config { section: "dataset", source: e };
        if !config.other_sensors.is_empty() {
            return Err(MapError::ConfigFile {
                path: origin.to_string(),
                message: format!(
                    "lists {} [[sensors]]; a recording ({}) is replayed with one sensor: give it a config with one [sensor] section",
                    config.other_sensors.len() + 1,
                    path.display()
                ),
            });
        }
        if is_recording(path) {
            let opts = ros_options(dataset).map_err(|e| MapError::ConfigFile {
                path: format!("{origin}: replaying {}", path.display()),
                message: in_dataset(e).to_string(),
            })?;
            let replay = RosReplay::open(path, &opts)?;
            for w in replay.warnings() {
                tracing::warn!("{w}");
            }
            if let (SensorKind::Depth, Some(info)) = (config.sensor.kind, replay.camera_info()) {
                let k = info.k;
                let from = format!("the camera info of {} says", path.display());
                use_calibration(
                    config,
                    dataset.intrinsics,
                    &Calibration { k: [k[0], k[4], k[2], k[5]], width: info.width, height: info.height, from },
                    origin,
                );
            }
            tracing::info!(
                "{}: {} messages of {} on {}",
                path.display(),
                replay.len(),
                replay.sensor_type(),
                opts.sensor_topic
            );
            return Ok(Recording::Ros(Box::new(replay)));
        }
        dataset.validate().map_err(in_dataset)?;
        let opts = dataset.folder_options(config, path)?;
        let set = Dataset::open_with(path, &opts)?;
        for w in set.warnings() {
            tracing::warn!("{w}");
        }
        if let (SensorKind::Depth, Dataset::Depth(folder)) = (config.sensor.kind, &set) {
            if let Some(file) = &folder.intrinsics_file {
                let c = &folder.camera;
                let from = format!("{} and the first image say", file.display());
                use_calibration(
                    config,
                    dataset.intrinsics,
                    &Calibration { k: [c.fx, c.fy, c.cx, c.cy], width: c.width, height: c.height, from },
                    origin,
                );
            }
        }
        tracing::info!("{}: {} frames of {}", path.display(), set.len(), set.kind());
        Ok(Recording::Folder(set))
    }

    /// The one warning for the poses read so far that were replaced by the
    /// nearest rotation (a folder's pose files; see
    /// [`Dataset::pose_warning`]); `None` when there were none.
    pub fn pose_warning(&self) -> Option<String> {
        match self {
            Recording::Folder(d) => d.pose_warning(),
            Recording::Ros(_) => None,
        }
    }

    /// Frames the recording's index holds.
    pub fn len(&self) -> usize {
        match self {
            Recording::Folder(d) => d.len(),
            Recording::Ros(r) => r.len(),
        }
    }

    /// Whether the recording holds no frame.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The sensor kind the recording holds, as `Sensor::kind` names it.
    pub fn kind(&self) -> &'static str {
        match self {
            Recording::Folder(d) => d.kind(),
            Recording::Ros(r) => r.kind(),
        }
    }

    /// The first `n` frames, or failures in their place; `name` names the
    /// recording in a folder's messages.
    pub fn frames<'a>(
        &'a self,
        n: usize,
        name: &'a str,
    ) -> Box<dyn Iterator<Item = Result<Frame, RecordingFailure>> + 'a> {
        match self {
            Recording::Folder(set) => Box::new((0..n).map(move |i| {
                set.frame(i).map_err(|e| RecordingFailure {
                    index: i,
                    message: format!("frame {i} of {name}: {e}"),
                    damage: false,
                })
            })),
            // The index counts only what precedes damage: when every indexed
            // frame is asked for, still report the damage that ends the file.
            Recording::Ros(replay) => {
                let all = n >= replay.len();
                Box::new(
                    replay
                        .frames()
                        .enumerate()
                        .take_while(move |(i, r)| *i < n || (all && r.as_ref().is_err_and(|e| e.fatal)))
                        .map(|(i, r)| {
                            r.map_err(|e| RecordingFailure { index: i, message: e.to_string(), damage: e.fatal })
                        }),
                )
            }
        }
    }
}

/// A depth camera's calibration as a recording gives it.
struct Calibration {
    /// `[fx, fy, cx, cy]`, pixels.
    k: [f64; 4],
    /// Image width, pixels.
    width: u32,
    /// Image height, pixels.
    height: u32,
    /// Where it comes from, as the subject of `says`: `the camera info
    /// of drive.bag says`.
    from: String,
}

/// The camera `[sensor]` describes, in the words of the messages.
fn describe(k: [Option<f64>; 4], width: Option<u32>, height: Option<u32>) -> String {
    let show = |v: Option<f64>| v.map_or_else(|| "unset".to_string(), |v| v.to_string());
    let size = |v: Option<u32>| v.map_or_else(|| "unset".to_string(), |v| v.to_string());
    format!(
        "fx {}, fy {}, cx {}, cy {}, {} x {} pixels",
        show(k[0]),
        show(k[1]),
        show(k[2]),
        show(k[3]),
        size(width),
        size(height)
    )
}

/// Applies a recording's calibration to `[sensor]` as `[dataset]
/// intrinsics` says: the recording's wins (default) or `[sensor]`'s, its
/// unset fields filled from the recording's. Where both give a value and
/// they differ, a warning names both and the one used.
fn use_calibration(config: &mut Config, policy: IntrinsicsSource, cal: &Calibration, origin: &str) {
    let s = &mut config.sensor.camera;
    let theirs = describe(cal.k.map(Some), Some(cal.width), Some(cal.height));
    let ours = describe([s.fx, s.fy, s.cx, s.cy], s.width, s.height);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
    let mut differ = false;
    for (field, value) in [(&mut s.fx, cal.k[0]), (&mut s.fy, cal.k[1]), (&mut s.cx, cal.k[2]), (&mut s.cy, cal.k[3])] {
        differ |= field.is_some_and(|v| !close(v, value));
        if policy == IntrinsicsSource::Recording || field.is_none() {
            *field = Some(value);
        }
    }
    for (field, value) in [(&mut s.width, cal.width), (&mut s.height, cal.height)] {
        differ |= field.is_some_and(|v| v != value);
        if policy == IntrinsicsSource::Recording || field.is_none() {
            *field = Some(value);
        }
    }
    if differ {
        match policy {
            IntrinsicsSource::Recording => tracing::warn!(
                "depth camera: {origin} [sensor] says {ours} but {} {theirs}: using the recording's; set [dataset] intrinsics = \"config\" to use [sensor]'s",
                cal.from
            ),
            IntrinsicsSource::Config => tracing::warn!(
                "depth camera: {origin} [sensor] says {ours} but {} {theirs}: using [sensor]'s, as [dataset] intrinsics = \"config\" asks",
                cal.from
            ),
        }
    }
    let used = describe([s.fx, s.fy, s.cx, s.cy], s.width, s.height);
    tracing::info!("depth camera: {used} ({} {theirs})", cal.from);
}

/// The options of a ROS replay from `[dataset]`; `sensor_topic` and
/// `pose_topic` are needed.
pub fn ros_options(d: &DatasetSection) -> Result<RosOptions, edtmap::CoreError> {
    d.validate()?;
    let missing = |field: &'static str| edtmap::CoreError::InvalidParam {
        field,
        value: "missing".into(),
        reason: "required to replay a ROS bag or MCAP file",
    };
    Ok(RosOptions {
        sensor_topic: d.sensor_topic.clone().ok_or_else(|| missing("sensor_topic"))?,
        camera_info_topic: d.camera_info_topic.clone(),
        pose_topic: d.pose_topic.clone().ok_or_else(|| missing("pose_topic"))?,
        static_tf_topic: d.static_tf_topic.clone(),
        world_frame: d.world_frame.clone(),
        body_frame: d.body_frame.clone(),
        t_body_sensor: d.t_body_sensor()?,
        max_pose_gap_s: d.max_pose_gap_s,
        depth_scale_m: d.depth_scale_m,
    })
}
