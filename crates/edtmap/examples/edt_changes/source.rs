//! Where `export` takes its frames from: a built-in scene, simulated, or a
//! recording (a folder of 3DMatch or TUM depth images or PCD/PLY/KITTI
//! clouds, a ROS bag or MCAP file), opened as `edtmap run --dataset` opens
//! it.

use crate::common::Error;
use edtmap::config::Config;
use edtmap::sensor::{Frame, Sensor};
use edtmap_ros::config::DatasetSection;
use edtmap_ros::recording::Recording;
use edtmap_sim::{Scene, SceneName, SceneOptions, SceneSection};
use serde::Deserialize;
use std::path::Path;

/// The sections of the config the CLI reads and `export` follows.
#[derive(Deserialize)]
pub(crate) struct Sections {
    /// The built-in scene.
    pub(crate) scene: Option<SceneSection>,
    /// How to read a folder recording.
    #[serde(default)]
    pub(crate) dataset: DatasetSection,
}

/// The frames of a run, all read before the first is integrated so that
/// no repeat times the disk or the simulator.
pub(crate) struct Frames {
    /// The scene's name or the recording's folder name.
    pub(crate) name: String,
    /// The frames, in order.
    pub(crate) frames: Vec<Frame>,
}

/// The first `limit` frames of the scene `name` (default: the config's
/// `[scene] frames`, else the scene's length), with `[scene]`'s seed and
/// noise.
pub(crate) fn scene(
    name: &str,
    section: Option<&SceneSection>,
    sensor: &Sensor,
    limit: Option<usize>,
) -> Result<Frames, Error> {
    let scene_name: SceneName = name.parse().map_err(|e| format!("{e}"))?;
    let options = section.map_or_else(|| Ok(SceneOptions::default()), SceneSection::options)?;
    let scene = Scene::new(scene_name, &options)?;
    let n = limit.or(section.and_then(|s| s.frames)).unwrap_or_else(|| scene.default_frames());
    let frames = (0..n)
        .map(|i| scene.frame(sensor, i).map_err(|e| format!("simulating frame {i}: {e}")))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Frames { name: name.to_owned(), frames })
}

/// The first `limit` frames (default: all) of the recording at `path`,
/// opened as `edtmap run --dataset` opens it ([`Recording::open`]: a
/// depth camera's calibration in the recording replaces `[sensor]`'s
/// unless `[dataset] intrinsics = "config"`, and `config` is updated so
/// that the mapper sees that camera). A frame that cannot be read fails
/// the run, as the comparison needs them all.
pub(crate) fn recording(
    path: &Path,
    config: &mut Config,
    dataset: &DatasetSection,
    origin: &str,
    limit: Option<usize>,
) -> Result<Frames, Error> {
    let recording = Recording::open(path, config, dataset, origin)?;
    let (sensor, _) = config.mapper_params()?;
    if recording.kind() != sensor.kind() {
        return Err(format!(
            "{} holds {} frames but the config's [sensor] is a {}",
            path.display(),
            recording.kind(),
            sensor.kind()
        )
        .into());
    }
    let n = limit.unwrap_or(recording.len()).min(recording.len());
    let name = path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned());
    let frames = recording.frames(n, &name).map(|(_, _, r)| r.map_err(|f| f.message)).collect::<Result<Vec<_>, _>>()?;
    Ok(Frames { name, frames })
}
