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

mod limits;
mod memory;
mod sensor;

pub(crate) use limits::check_ogm;
pub use limits::{Limit, DEPTH_SCALE_M, OFFSET_M, POSE_GAP_S, WORLD_M};
pub use memory::MemorySection;
pub use sensor::{CameraFields, ConstructionName, LidarFields, SensorKind, SensorSection};

use crate::{MapError, MapperParams};
use edtmap_core::sensor::Sensor;
use edtmap_core::{EdtParams, GlobalParams, OccupancyParams, VolumeParams};
use serde::de::{DeserializeOwned, IgnoredAny};
use serde::Deserialize;
use std::path::Path;

/// A whole configuration file, as the library reads it: the mapper's
/// sections. The sections the applications read from the same file
/// (`[scene]`: the built-in scenes, `[output]`: the CLI's pictures,
/// `[dataset]`: recordings, `[ros]`: the live node) are accepted here and
/// left to them; each parses its own with [`sections`].
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
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
    /// The memory budget.
    #[serde(default)]
    pub memory: MemorySection,
    #[serde(default)]
    scene: IgnoredAny,
    #[serde(default)]
    output: IgnoredAny,
    #[serde(default)]
    dataset: IgnoredAny,
    #[serde(default)]
    ros: IgnoredAny,
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

/// The text of the configuration file `path` (UTF-8, of a sane size).
pub fn read(path: &Path) -> Result<String, MapError> {
    Ok(edtmap_io::files::read_text(path)?)
}

/// The sections of a configuration's `text` that an application reads, as
/// the struct `A` lists them (each with `deny_unknown_fields`; `A` itself
/// without, as the file holds the mapper's and other applications'
/// sections too). `origin` names the text in errors, which give the line.
pub fn sections<A: DeserializeOwned>(text: &str, origin: &str) -> Result<A, MapError> {
    toml::from_str(text).map_err(|e| MapError::ConfigFile { path: origin.to_string(), message: e.to_string() })
}

impl Config {
    /// Parses a configuration from TOML text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Config, MapError> {
        let config: Config = toml::from_str(text)
            .map_err(|e| MapError::ConfigFile { path: origin.to_string(), message: e.to_string() })?;
        config.mapper_params()?;
        Ok(config)
    }

    /// Reads and parses a configuration file (an application reads its own
    /// sections from the same [`read`] text with [`sections`]).
    pub fn load(path: &Path) -> Result<Config, MapError> {
        Config::parse(&read(path)?, &path.display().to_string())
    }

    /// The sensor and mapper parameters, validated: every number in its
    /// range, then the stages' own checks ([`MapperParams::validate`]).
    pub fn mapper_params(&self) -> Result<(Sensor, MapperParams), MapError> {
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
}
