//! The TOML configuration: one section per stage, validated into typed
//! parameters with errors that name the section and field.
//!
//! ```toml
//! [sensor]                 # what produced the frames
//! kind = "lidar"           # depth | lidar | points | planar
//! construction = "auto"    # auto | projection | raycast
//! min_range_m = 0.2
//! max_range_m = 20.0
//! rings = 32
//! elevation_min_deg = -15.0
//! elevation_max_deg = 15.0
//! azimuth_bins = 900
//!
//! [occupancy]
//! voxel_size_m = 0.2
//! local_size_m = [10.0, 10.0, 3.0]
//! ```
//! The files under `configs/` document every field.

mod dataset;
mod limits;
mod memory;
mod ros;
mod sensor;

pub use dataset::{DatasetSection, IntrinsicsSource, OnError, RECORDING_MAX_POSE_GAP_S};

pub use memory::MemorySection;
pub use ros::{Intrinsics, OccupiedScope, PoseType, RosSection, ServiceMapping};
pub use sensor::{CameraFields, ConstructionName, LidarFields, SensorKind, SensorSection};

use crate::{MapError, MapperParams};
use edtmap_core::sensor::Sensor;
use edtmap_core::{EdtParams, GlobalParams, OccupancyParams, VolumeParams};
use serde::Deserialize;
use std::path::Path;

/// A whole configuration file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// The built-in scene to replay, for `edtmap run --scene`.
    #[serde(default)]
    pub scene: Option<SceneSection>,
    /// The sensor.
    pub sensor: SensorSection,
    /// Voxels, local volume and log-odds fusion.
    pub occupancy: OccupancySection,
    /// Batch EDT.
    #[serde(default)]
    pub edt: EdtParams,
    /// Global EDT: cutoff, connectivity, integration mode, forbidden zones.
    #[serde(default)]
    pub global: GlobalParams,
    /// Pictures and reports.
    #[serde(default)]
    pub output: OutputSection,
    /// Recordings replayed with `edtmap run --dataset`.
    #[serde(default)]
    pub dataset: DatasetSection,
    /// The memory budget.
    #[serde(default)]
    pub memory: MemorySection,
    /// The live ROS 2 node (`edtmap node`).
    #[serde(default)]
    pub ros: RosSection,
}

/// `[scene]`: which built-in scene and how to simulate it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSection {
    /// Scene name (`uav_pillars`, `ugv_corridor`, `room`, `planar`).
    pub name: String,
    /// Frames to replay; the scene's own length when absent.
    #[serde(default)]
    pub frames: Option<usize>,
    /// Seed of the layout and the noise.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Standard deviation of Gaussian range noise, metres.
    #[serde(default)]
    pub range_noise_m: f64,
    /// Probability that a return is dropped.
    #[serde(default)]
    pub dropout: f64,
}

fn default_seed() -> u64 {
    7
}

/// `[occupancy]`: voxels, the local volume and log-odds fusion.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OccupancySection {
    /// Voxel edge length, metres.
    pub voxel_size_m: f64,
    /// Local volume edge lengths, metres.
    #[serde(default = "default_local_size")]
    pub local_size_m: [f64; 3],
    /// Height of the local volume's centre for ground robots, metres.
    #[serde(default)]
    pub fixed_height_m: Option<f64>,
    /// Log-odds probabilities (OctoMap's defaults).
    #[serde(flatten)]
    pub probabilities: OccupancyParams,
}

fn default_local_size() -> [f64; 3] {
    VolumeParams::default().size_m
}

/// `[output]`: pictures.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    /// Height of the pictured horizontal slices, metres (default: the
    /// layer of the last local volume with the most observed voxels).
    #[serde(default)]
    pub slice_height_m: Option<f64>,
}

impl Config {
    /// Parses a configuration from TOML text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Config, MapError> {
        let config: Config = toml::from_str(text)
            .map_err(|e| MapError::ConfigFile { path: origin.to_string(), message: e.to_string() })?;
        config.mapper_params()?;
        Ok(config)
    }

    /// Reads and parses a configuration file.
    pub fn load(path: &Path) -> Result<Config, MapError> {
        let text = edtmap_io::files::read_text(path)?;
        Config::parse(&text, &path.display().to_string())
    }

    /// The sensor and mapper parameters, validated: every number in its
    /// range, then the stages' own checks ([`MapperParams::validate`]).
    pub fn mapper_params(&self) -> Result<(Sensor, MapperParams), MapError> {
        self.check_limits()?;
        let occ = &self.occupancy;
        let (sensor, ogm) = self.sensor.checked().map_err(|source| MapError::Config { section: "sensor", source })?;
        let params = MapperParams {
            voxel_size_m: occ.voxel_size_m,
            volume: VolumeParams { size_m: occ.local_size_m, fixed_height_m: occ.fixed_height_m },
            occupancy: occ.probabilities.clone(),
            ogm,
            edt: self.edt,
            global: self.global.clone(),
            max_memory_bytes: self.memory.max_bytes()?,
        };
        params.validate()?;
        Ok((sensor, params))
    }

    /// How to open the folder recording `dir` (depth scale, the sensor's
    /// range, the camera and whose intrinsics win, the trajectory relative
    /// to `dir`, the pose gap), from `[dataset]` and `[sensor]`.
    pub fn dataset_options(&self, dir: &Path) -> Result<edtmap_io::dataset::DatasetOptions, MapError> {
        let (sensor, _) = self.mapper_params()?;
        let range = match sensor {
            Sensor::Depth(c) => c.range,
            Sensor::Lidar(l) => l.range,
            Sensor::Points(r) => r,
            Sensor::Planar => edtmap_core::sensor::RangeLimits { min_m: 0.0, max_m: f32::MAX },
        };
        Ok(edtmap_io::dataset::DatasetOptions {
            depth_scale_m: self.dataset.depth_scale_m,
            range,
            intrinsics: self.sensor.camera.intrinsics(),
            folder_intrinsics: self.dataset.intrinsics == IntrinsicsSource::Recording,
            trajectory: self.dataset.trajectory.as_ref().map(|t| dir.join(t)),
            max_pose_gap_s: self.dataset.max_pose_gap_s,
        })
    }
}
