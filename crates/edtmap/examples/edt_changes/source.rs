//! Where `export` takes its frames from: a built-in scene, simulated, or a
//! folder recording (3DMatch or TUM depth images, PCD/PLY/KITTI clouds),
//! opened as `edtmap run --dataset` opens it.

use crate::common::Error;
use edtmap::config::{Config, SensorKind};
use edtmap::sensor::{Frame, Sensor};
use edtmap_io::dataset::Dataset;
use edtmap_ros::config::{DatasetSection, IntrinsicsSource};
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

/// Opens the folder recording `dir` with `config`'s `[dataset]` options.
/// A depth folder's `camera-intrinsics.txt` and image size replace
/// `[sensor]`'s camera unless `[dataset] intrinsics = "config"`, as in
/// `edtmap run`; `config` is updated so that the mapper sees that camera.
pub(crate) fn open_recording(dir: &Path, config: &mut Config, dataset: &DatasetSection) -> Result<Dataset, Error> {
    dataset.validate().map_err(|e| format!("[dataset]: {e}"))?;
    let opts = dataset.folder_options(config, dir)?;
    let set = Dataset::open_with(dir, &opts)?;
    for w in set.warnings() {
        eprintln!("edt_changes: {}: {w}", dir.display());
    }
    if let (SensorKind::Depth, Dataset::Depth(folder), IntrinsicsSource::Recording) =
        (config.sensor.kind, &set, dataset.intrinsics)
    {
        if folder.intrinsics_file.is_some() {
            let (c, s) = (&folder.camera, &mut config.sensor.camera);
            (s.fx, s.fy, s.cx, s.cy, s.width, s.height) =
                (Some(c.fx), Some(c.fy), Some(c.cx), Some(c.cy), Some(c.width), Some(c.height));
        }
    }
    Ok(set)
}

/// The first `limit` frames of `set` (default: all), read from `dir`; a
/// frame that cannot be read fails the run, as the comparison needs them
/// all.
pub(crate) fn recording(dir: &Path, set: &Dataset, sensor: &Sensor, limit: Option<usize>) -> Result<Frames, Error> {
    if set.kind() != sensor.kind() {
        return Err(format!(
            "{} holds {} frames but the config's [sensor] is a {}",
            dir.display(),
            set.kind(),
            sensor.kind()
        )
        .into());
    }
    let n = limit.unwrap_or(set.len()).min(set.len());
    let frames = (0..n)
        .map(|i| set.frame(i).map_err(|e| format!("frame {i} of {}: {e}", dir.display())))
        .collect::<Result<Vec<_>, _>>()?;
    let name = dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned());
    Ok(Frames { name, frames })
}
