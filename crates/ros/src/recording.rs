//! Opening any recording edtmap reads (a ROS 1 bag, a ROS 2 MCAP file, a
//! folder of depth images or point clouds) with a configuration, for
//! `edtmap run --dataset` and the Python package's `read_recording`.

use std::path::Path;

use edtmap::config::{CameraFields, Config, SensorKind};
use edtmap::sensor::Frame;
use edtmap::MapError;
use edtmap_io::dataset::Dataset;

use crate::config::{sensor_topics, LoneSensor};
use crate::config::{DatasetSection, IntrinsicsSource};
use crate::poses::SensorMessage;
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
    /// The frame's position in the recording: among its sensor's frames.
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
        if is_recording(path) {
            let opts = ros_options(dataset, config).map_err(|message| MapError::ConfigFile {
                path: format!("{origin}: replaying {}", path.display()),
                message,
            })?;
            let replay = RosReplay::open(path, &opts)?;
            for w in replay.warnings() {
                tracing::warn!("{w}");
            }
            let several = !config.other_sensors.is_empty();
            for (i, section) in config.sensors_mut().enumerate() {
                if let (SensorKind::Depth, Some(info)) = (section.kind, replay.camera_info_of(i)) {
                    let k = info.k;
                    let from = format!("the camera info of {} says", path.display());
                    let which = if several { format!("[[sensors]] {:?}", section.name()) } else { "[sensor]".into() };
                    use_calibration(
                        &mut section.camera,
                        &which,
                        dataset.intrinsics,
                        &Calibration { k: [k[0], k[4], k[2], k[5]], width: info.width, height: info.height, from },
                        origin,
                    );
                }
                if !several {
                    continue;
                }
                let Some(message) = SensorMessage::of(section.kind) else {
                    return Err(MapError::ConfigFile {
                        path: origin.to_string(),
                        message: format!(
                            "[[sensors]] {:?}: kind = \"lidar\" takes range images, which no ROS message carries; \
                             a recording's sensor_msgs/PointCloud2 needs kind = \"points\"",
                            section.name()
                        ),
                    });
                };
                if let Some(got) = replay.sensor_type_of(i) {
                    let wanted = message.ros_type();
                    if got != wanted {
                        return Err(MapError::ConfigFile {
                            path: origin.to_string(),
                            message: format!(
                                "[[sensors]] {:?}: topic {} of {} carries {got}, but kind = {:?} takes {wanted}",
                                section.name(),
                                opts.sensors[i].topic,
                                path.display(),
                                format!("{:?}", section.kind).to_lowercase()
                            ),
                        });
                    }
                }
            }
            for (i, s) in opts.sensors.iter().enumerate() {
                tracing::info!(
                    "{}: {} messages of {} on {}",
                    path.display(),
                    replay.len_of(i),
                    replay.sensor_type_of(i).unwrap_or("nothing"),
                    s.topic
                );
            }
            return Ok(Recording::Ros(Box::new(replay)));
        }
        if !config.other_sensors.is_empty() {
            return Err(MapError::ConfigFile {
                path: origin.to_string(),
                message: format!(
                    "lists {} [[sensors]], but {} is a folder, which holds one sensor's frames: several sensors \
                     replay from a ROS bag or MCAP file, each [[sensors]] entry naming its topic",
                    config.other_sensors.len() + 1,
                    path.display()
                ),
            });
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
                    &mut config.sensor.camera,
                    "[sensor]",
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
    /// recording in a folder's messages. Each comes with its position among
    /// its sensor's frames and its sensor's position in the config's
    /// sensors: a ROS recording with several sensor topics gives them in the
    /// order it holds them, and its `n` counts the messages of every sensor
    /// topic together.
    pub fn frames<'a>(
        &'a self,
        n: usize,
        name: &'a str,
    ) -> Box<dyn Iterator<Item = (usize, usize, Result<Frame, RecordingFailure>)> + 'a> {
        match self {
            Recording::Folder(set) => Box::new((0..n).map(move |i| {
                let frame = set.frame(i).map_err(|e| RecordingFailure {
                    index: i,
                    message: format!("frame {i} of {name}: {e}"),
                    damage: false,
                });
                (i, 0, frame)
            })),
            // The index counts only what precedes damage: when every indexed
            // frame is asked for, still report the damage that ends the file.
            Recording::Ros(replay) => {
                let all = n >= replay.len();
                Box::new(
                    replay
                        .sensor_frames()
                        .enumerate()
                        .take_while(move |(i, f)| *i < n || (all && f.frame.as_ref().is_err_and(|e| e.fatal)))
                        .map(|(_, f)| {
                            let frame = f.frame.map_err(|e| RecordingFailure {
                                index: e.index,
                                message: e.to_string(),
                                damage: e.fatal,
                            });
                            (f.index, f.sensor, frame)
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
fn use_calibration(s: &mut CameraFields, which: &str, policy: IntrinsicsSource, cal: &Calibration, origin: &str) {
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
                "depth camera: {origin} {which} says {ours} but {} {theirs}: using the recording's; set [dataset] intrinsics = \"config\" to use {which}'s",
                cal.from
            ),
            IntrinsicsSource::Config => tracing::warn!(
                "depth camera: {origin} {which} says {ours} but {} {theirs}: using {which}'s, as [dataset] intrinsics = \"config\" asks",
                cal.from
            ),
        }
    }
    let used = describe([s.fx, s.fy, s.cx, s.cy], s.width, s.height);
    tracing::info!("depth camera {which}: {used} ({} {theirs})", cal.from);
}

/// The options of a ROS replay from `[dataset]` and the config's
/// sensors (see [`sensor_topics`]); `pose_topic` and every sensor's topic
/// are needed. The error says what to set.
pub fn ros_options(d: &DatasetSection, config: &Config) -> Result<RosOptions, String> {
    d.validate().map_err(|e| format!("[dataset] {e}"))?;
    let lone = LoneSensor {
        section: "[dataset]",
        topic: d.sensor_topic.as_deref(),
        camera_info_topic: d.camera_info_topic.as_deref(),
        sensor_in_body: d.sensor_in_body,
        needed: "to replay a ROS bag or MCAP file",
    };
    Ok(RosOptions {
        sensors: sensor_topics(config, &lone)?,
        pose_topic: d.pose_topic.clone().ok_or_else(|| {
            "invalid [dataset] pose_topic = missing: required to replay a ROS bag or MCAP file".to_string()
        })?,
        static_tf_topic: d.static_tf_topic.clone(),
        world_frame: d.world_frame.clone(),
        body_frame: d.body_frame.clone(),
        max_pose_gap_s: d.max_pose_gap_s,
        depth_scale_m: d.depth_scale_m,
    })
}
