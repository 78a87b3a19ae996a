//! Where `edtmap run` takes its frames from: a built-in scene, a folder
//! recording, or a ROS bag / MCAP file; and what to do with a frame that
//! cannot be used.

use std::path::Path;

use anyhow::{bail, Context, Result};
use edtmap::config::Config;
use edtmap::sensor::{Frame, Sensor};
use edtmap::MapperSensor;
use edtmap_ros::config::DatasetSection;
use edtmap_ros::recording::Recording;
use edtmap_sim::{Scene, SceneName, SceneSection};
use nalgebra::Isometry3;

/// A frame that did not come out, with where it was and why.
#[derive(Debug, Clone)]
pub(crate) struct Failure {
    /// The frame's position in the recording.
    pub(crate) index: usize,
    /// File, topic, stamp and reason.
    pub(crate) message: String,
    /// What it means for the run.
    pub(crate) kind: FailureKind,
}

/// How a failure weighs on the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FailureKind {
    /// This frame only: skipped or stopping, per `[dataset] on_error`.
    Frame,
    /// The recording is damaged here: nothing after it can be read. The run
    /// ends; an error only with `on_error = "stop"`.
    Damage,
    /// The pipeline itself failed (a simulated scene, a lost device): the run
    /// ends with an error.
    Fatal,
}

/// The frames of a run.
pub(crate) enum Source {
    /// A built-in scene, simulated.
    Scene(Box<Scene>),
    /// A recording: a folder, a ROS 1 bag or a ROS 2 MCAP file.
    Recording(Recording),
}

impl Source {
    /// Opens the recording at `path` (see [`Recording::open`]).
    pub(crate) fn open_recording(
        path: &Path,
        config: &mut Config,
        dataset: &DatasetSection,
        origin: &str,
    ) -> Result<Source> {
        Ok(Source::Recording(Recording::open(path, config, dataset, origin)?))
    }

    /// A scene by name, with the config's `[scene]` settings.
    pub(crate) fn scene(name: &str, section: Option<&SceneSection>) -> Result<(Source, usize)> {
        let (scene, n) = build_scene(name, section)?;
        Ok((Source::Scene(Box::new(scene)), n))
    }

    /// Frames the source holds (a recording's index; a scene's length).
    pub(crate) fn len(&self) -> Option<usize> {
        match self {
            Source::Scene(_) => None,
            Source::Recording(r) => Some(r.len()),
        }
    }

    /// The sensor kind a recording holds, as `Sensor::kind` names it.
    pub(crate) fn kind(&self) -> Option<&'static str> {
        match self {
            Source::Scene(_) => None,
            Source::Recording(r) => Some(r.kind()),
        }
    }

    /// The one warning for the recording's poses that were replaced by the
    /// nearest rotation, if any were.
    pub(crate) fn pose_warning(&self) -> Option<String> {
        match self {
            Source::Scene(_) => None,
            Source::Recording(r) => r.pose_warning(),
        }
    }

    /// The first `n` frames, or failures in their place, each with its
    /// index and its sensor's position in `sensors`: a scene's time steps
    /// each give one frame of every sensor, in `sensors`' order, from its
    /// mount, indexed by the time step; a recording's frames come in the
    /// order it holds them, indexed among their sensor's frames.
    pub(crate) fn frames<'a>(
        &'a self,
        sensors: &'a [(MapperSensor, Isometry3<f64>)],
        n: usize,
        name: &'a str,
    ) -> Box<dyn Iterator<Item = (usize, usize, Result<Frame, Failure>)> + 'a> {
        match self {
            Source::Scene(scene) => Box::new((0..n).flat_map(move |i| {
                sensors.iter().enumerate().map(move |(s, (sensor, mount))| {
                    let frame = scene.mounted_frame(&sensor.sensor, mount, i).map_err(|e| Failure {
                        index: i,
                        message: format!("simulating frame {i} of {}: {e}", sensor.name),
                        kind: FailureKind::Fatal,
                    });
                    (i, s, frame)
                })
            })),
            Source::Recording(r) => Box::new(r.frames(n, name).map(|(index, s, r)| {
                let frame = r.map_err(|e| {
                    let kind = if e.damage { FailureKind::Damage } else { FailureKind::Frame };
                    Failure { index: e.index, message: e.message, kind }
                });
                (index, s, frame)
            })),
        }
    }
}

/// A built-in scene by name, with the config's `[scene]` settings, and its
/// number of frames.
pub(crate) fn build_scene(name: &str, section: Option<&SceneSection>) -> Result<(Scene, usize)> {
    let scene_name: SceneName = name.parse().map_err(|e| anyhow::anyhow!("{e}"))?;
    let section = section.cloned().unwrap_or_else(|| SceneSection::named(name));
    if section.frames == Some(0) {
        bail!("[scene] frames = 0: a scene needs at least 1 frame (leave frames out for the scene's own length)");
    }
    let scene = Scene::new(scene_name, &section.options().context("[scene]")?).context("[scene]")?;
    let n = section.frames.unwrap_or_else(|| scene.default_frames());
    Ok((scene, n))
}

/// Refuses a recording whose sensor is not the config's lone sensor's
/// (several sensors' topics are checked as the recording opens).
pub(crate) fn check_kind(source: &Source, sensor: &Sensor, path: &Path, origin: &str) -> Result<()> {
    match source.kind() {
        Some(kind) if kind != sensor.kind() => {
            bail!("{} holds {kind} frames but {origin}'s [sensor] is a {}", path.display(), sensor.kind())
        }
        _ => Ok(()),
    }
}
