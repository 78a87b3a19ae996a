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

pub use dataset::{DatasetSection, IntrinsicsSource, OnError, RECORDING_MAX_POSE_GAP_S};

pub use memory::MemorySection;

use crate::{MapError, MapperParams};
use edtmap_core::sensor::{PinholeCamera, RangeLimits, Sensor, SpinningLidar};
use edtmap_core::{CoreError, EdtParams, GlobalParams, OccupancyParams, VolumeParams};
use edtmap_cpu::occupancy::{Construction, OgmOptions};
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

/// `[sensor]`: the sensor model, and how its frames become occupancy.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSection {
    /// `depth`, `lidar`, `points` or `planar`.
    pub kind: SensorKind,
    /// `auto` (projection when the model allows), `projection` or `raycast`.
    #[serde(default)]
    pub construction: ConstructionName,
    /// Whether rays with no return clear space up to `max_range_m`.
    #[serde(default)]
    pub clear_no_return: bool,
    /// Shortest valid return, metres.
    pub min_range_m: f32,
    /// Longest valid return, metres.
    pub max_range_m: f32,
    /// Both constructions: a voxel is free only when it lies more than this in front of the return, metres (default half a voxel diagonal).
    pub free_margin_m: Option<f32>,
    /// Planar projection: half thickness of the observed slab, metres (default half a voxel).
    pub planar_half_thickness_m: Option<f32>,
    /// LiDAR: number of evenly spread rings.
    pub rings: Option<usize>,
    /// LiDAR: elevation of the lowest ring, degrees.
    pub elevation_min_deg: Option<f64>,
    /// LiDAR: elevation of the highest ring, degrees.
    pub elevation_max_deg: Option<f64>,
    /// LiDAR: explicit ring elevations in degrees (instead of `rings`).
    pub ring_elevations_deg: Option<Vec<f64>>,
    /// LiDAR: azimuth bins per turn.
    pub azimuth_bins: Option<usize>,
    /// Depth camera: focal length x, pixels.
    pub fx: Option<f64>,
    /// Depth camera: focal length y, pixels.
    pub fy: Option<f64>,
    /// Depth camera: principal point x, pixels.
    pub cx: Option<f64>,
    /// Depth camera: principal point y, pixels.
    pub cy: Option<f64>,
    /// Depth camera: image width, pixels.
    pub width: Option<u32>,
    /// Depth camera: image height, pixels.
    pub height: Option<u32>,
}

/// Sensor kinds of `[sensor] kind`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorKind {
    /// Pinhole depth camera.
    Depth,
    /// Spinning LiDAR with rings.
    Lidar,
    /// Plain point clouds.
    Points,
    /// Planar 2D LiDAR.
    Planar,
}

/// Values of `[sensor] construction`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConstructionName {
    /// Projection where possible, else ray casting.
    #[default]
    Auto,
    /// Volumetric projection.
    Projection,
    /// Ray casting.
    Raycast,
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
        let config: Config = toml::from_str(text).map_err(|e| MapError::ConfigFile { path: origin.to_string(), message: e.to_string() })?;
        config.mapper_params()?;
        Ok(config)
    }

    /// Reads and parses a configuration file.
    pub fn load(path: &Path) -> Result<Config, MapError> {
        let text = edtmap_io::files::read_text(path)?;
        Config::parse(&text, &path.display().to_string())
    }

    /// The sensor and mapper parameters, validated: every number in its
    /// range, then the stages' own checks.
    pub fn mapper_params(&self) -> Result<(Sensor, MapperParams), MapError> {
        self.check_limits()?;
        let occ = &self.occupancy;
        let in_occ = |source| MapError::Config { section: "occupancy", source };
        edtmap_core::check_voxel_size(occ.voxel_size_m).map_err(in_occ)?;
        occ.probabilities.log_odds().map_err(in_occ)?;
        let volume = VolumeParams { size_m: occ.local_size_m, fixed_height_m: occ.fixed_height_m };
        edtmap_core::LocalVolume::centred(&volume, occ.voxel_size_m, [0.0; 3]).map_err(in_occ)?;
        let sensor = self.sensor.model().map_err(|source| MapError::Config { section: "sensor", source })?;
        let ogm = self.sensor.ogm_options(occ.voxel_size_m, &sensor).map_err(|source| MapError::Config { section: "sensor", source })?;
        let in_global = |source| MapError::Config { section: "global", source };
        self.global.cutoff(occ.voxel_size_m).map_err(in_global)?;
        self.global.check_forbidden().map_err(in_global)?;
        let global = self.global.clone();
        let params = MapperParams { voxel_size_m: occ.voxel_size_m, volume, occupancy: occ.probabilities.clone(), ogm, edt: self.edt, global, max_memory_bytes: self.memory.max_bytes()? };
        Ok((sensor, params))
    }
}

fn need<T: Copy>(v: Option<T>, field: &'static str, kind: &'static str) -> Result<T, CoreError> {
    v.ok_or(CoreError::InvalidParam { field, value: "missing".into(), reason: kind })
}

impl SensorSection {
    /// The sensor model this section describes.
    pub fn model(&self) -> Result<Sensor, CoreError> {
        let range = RangeLimits { min_m: self.min_range_m, max_m: self.max_range_m };
        let sensor = match self.kind {
            SensorKind::Depth => {
                let why = "required for kind = \"depth\"";
                Sensor::Depth(PinholeCamera {
                    fx: need(self.fx, "fx", why)?,
                    fy: need(self.fy, "fy", why)?,
                    cx: need(self.cx, "cx", why)?,
                    cy: need(self.cy, "cy", why)?,
                    width: need(self.width, "width", why)?,
                    height: need(self.height, "height", why)?,
                    range,
                })
            }
            SensorKind::Lidar => Sensor::Lidar(self.lidar(range)?),
            SensorKind::Points => Sensor::Points(range),
            SensorKind::Planar => Sensor::Planar,
        };
        if self.kind == SensorKind::Planar && !(range.min_m >= 0.0 && range.max_m > range.min_m) {
            return Err(CoreError::InvalidParam { field: "min_range_m/max_range_m", value: format!("{}..{}", range.min_m, range.max_m), reason: "need 0 ≤ min < max" });
        }
        sensor.validate()?;
        Ok(sensor)
    }

    fn lidar(&self, range: RangeLimits) -> Result<SpinningLidar, CoreError> {
        let why = "required for kind = \"lidar\"";
        let bins = need(self.azimuth_bins, "azimuth_bins", why)?;
        if let Some(table) = &self.ring_elevations_deg {
            let ring_elevations_rad = table.iter().map(|d| d.to_radians()).collect();
            return Ok(SpinningLidar { ring_elevations_rad, azimuth_bins: bins, range });
        }
        let why = "required for kind = \"lidar\" without ring_elevations_deg";
        let rings = need(self.rings, "rings", why)?;
        if !(1..=edtmap_core::sensor::MAX_RINGS).contains(&rings) {
            return Err(CoreError::InvalidParam { field: "rings", value: rings.to_string(), reason: "must be between 1 and 4096" });
        }
        let (lo, hi) = (need(self.elevation_min_deg, "elevation_min_deg", why)?, need(self.elevation_max_deg, "elevation_max_deg", why)?);
        Ok(SpinningLidar::uniform(rings, lo.to_radians(), hi.to_radians(), bins, range))
    }

    fn ogm_options(&self, voxel_size_m: f64, sensor: &Sensor) -> Result<OgmOptions, CoreError> {
        let mut o = OgmOptions::for_voxel_size(voxel_size_m);
        o.clear_no_return = self.clear_no_return;
        o.construction = match self.construction {
            ConstructionName::Auto => Construction::Auto,
            ConstructionName::Raycast => Construction::RayCasting,
            ConstructionName::Projection if sensor.supports_projection() => Construction::Projection,
            ConstructionName::Projection => {
                return Err(CoreError::InvalidParam { field: "construction", value: "\"projection\"".into(), reason: "a point cloud sensor has no model to project into; use \"raycast\"" })
            }
        };
        // Both are in range: `Config::check_limits` ran first.
        o.free_margin_m = self.free_margin_m.unwrap_or(o.free_margin_m);
        o.planar_half_thickness_m = self.planar_half_thickness_m.unwrap_or(o.planar_half_thickness_m);
        Ok(o)
    }
}
