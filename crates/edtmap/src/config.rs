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
pub(crate) use sensor::check_construction;
pub use sensor::{sensor_in_body, CameraFields, ConstructionName, LidarFields, SensorKind, SensorSection};

use crate::{MapError, Mapper, MapperParams, MapperSensor};
use edtmap_core::sensor::Sensor;
use edtmap_core::Backend;
use edtmap_core::{EdtParams, GlobalParams, OccupancyParams, VolumeParams};
use nalgebra::Isometry3;
use serde::de::{DeserializeOwned, IgnoredAny};
use serde::Deserialize;
use std::path::Path;

/// A whole configuration file, as the library reads it: the mapper's
/// sections. The sections the applications read from the same file
/// (`[scene]`: the built-in scenes, `[output]`: the CLI's pictures,
/// `[dataset]`: recordings, `[ros]`: the live node) are accepted here and
/// left to them; each parses its own with [`sections`].
///
/// A robot with several sensors lists them as `[[sensors]]` entries, each
/// a `[sensor]` table with its `name` and `sensor_in_body`; one
/// sensor is a `[sensor]` section.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(try_from = "ConfigFile")]
pub struct Config {
    /// The first sensor: `[sensor]`, or the first `[[sensors]]` entry.
    pub sensor: SensorSection,
    /// The other `[[sensors]]` entries, in the file's order (none with a
    /// `[sensor]` section).
    pub other_sensors: Vec<SensorSection>,
    /// Voxels, local volume and log-odds fusion.
    pub occupancy: OccupancySection,
    /// Batch EDT.
    pub edt: EdtParams,
    /// Global EDT: cutoff, connectivity, integration mode, forbidden zones.
    pub global: GlobalParams,
    /// The memory budget.
    pub memory: MemorySection,
}

/// [`Config`] as the file writes it (the applications' sections are
/// accepted, not read).
#[allow(dead_code)]
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFile {
    sensor: Option<SensorSection>,
    #[serde(default)]
    sensors: Vec<SensorSection>,
    occupancy: OccupancySection,
    #[serde(default)]
    edt: EdtParams,
    #[serde(default)]
    global: GlobalParams,
    #[serde(default)]
    memory: MemorySection,
    #[serde(default)]
    scene: IgnoredAny,
    #[serde(default)]
    output: IgnoredAny,
    #[serde(default)]
    dataset: IgnoredAny,
    #[serde(default)]
    ros: IgnoredAny,
}

impl TryFrom<ConfigFile> for Config {
    type Error = String;

    fn try_from(f: ConfigFile) -> Result<Config, String> {
        let (sensor, other_sensors) = match (f.sensor, f.sensors) {
            (Some(s), more) if more.is_empty() => {
                let per_entry = [
                    ("sensor_in_body", s.sensor_in_body.is_some()),
                    ("topic", s.topic.is_some()),
                    ("camera_info_topic", s.camera_info_topic.is_some()),
                ];
                if let Some((field, _)) = per_entry.iter().find(|(_, set)| *set) {
                    let dataset = if *field == "topic" { "sensor_topic" } else { field };
                    return Err(format!(
                        "[sensor] takes no {field}: one sensor's is [dataset] (or [ros]) {dataset}; several \
                         sensors are [[sensors]] entries, each with its own {field}"
                    ));
                }
                (s, Vec::new())
            }
            (None, mut sensors) if !sensors.is_empty() => (sensors.remove(0), sensors),
            (Some(_), _) => {
                return Err("both [sensor] and [[sensors]]: one sensor is a [sensor] section, several are \
                            [[sensors]] entries"
                    .into())
            }
            (None, _) => return Err("missing [sensor] (one sensor) or [[sensors]] entries (several)".into()),
        };
        let names: Vec<&str> = std::iter::once(&sensor).chain(&other_sensors).map(|s| s.name()).collect();
        for (i, name) in names.iter().enumerate() {
            if names[..i].contains(name) {
                return Err(format!("two sensors are named {name:?}: give each [[sensors]] entry its own name"));
            }
        }
        Ok(Config { sensor, other_sensors, occupancy: f.occupancy, edt: f.edt, global: f.global, memory: f.memory })
    }
}

/// `[occupancy]`: voxels, the local volume and log-odds fusion.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(from = "OccupancyTable")]
pub struct OccupancySection {
    /// Voxel edge length, metres.
    pub voxel_size_m: f64,
    /// Local volume edge lengths, metres.
    pub local_size_m: [f64; 3],
    /// Height of the local volume's centre for ground robots, metres.
    pub fixed_height_m: Option<f64>,
    /// Log-odds probabilities (OctoMap's defaults).
    pub probabilities: OccupancyParams,
}

/// `[occupancy]` as the file writes it: one flat table. Read field by
/// field rather than with the probabilities flattened in, so that an
/// unknown key is refused at its line with the list of the section's keys
/// (serde reads a flattened struct through a buffer, which loses both).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct OccupancyTable {
    voxel_size_m: f64,
    #[serde(default = "default_local_size")]
    local_size_m: [f64; 3],
    #[serde(default)]
    fixed_height_m: Option<f64>,
    prob_hit: Option<f64>,
    prob_miss: Option<f64>,
    clamp_min: Option<f64>,
    clamp_max: Option<f64>,
    occupied_threshold: Option<f64>,
}

impl From<OccupancyTable> for OccupancySection {
    fn from(t: OccupancyTable) -> Self {
        let d = OccupancyParams::default();
        OccupancySection {
            voxel_size_m: t.voxel_size_m,
            local_size_m: t.local_size_m,
            fixed_height_m: t.fixed_height_m,
            probabilities: OccupancyParams {
                prob_hit: t.prob_hit.unwrap_or(d.prob_hit),
                prob_miss: t.prob_miss.unwrap_or(d.prob_miss),
                clamp_min: t.clamp_min.unwrap_or(d.clamp_min),
                clamp_max: t.clamp_max.unwrap_or(d.clamp_max),
                occupied_threshold: t.occupied_threshold.unwrap_or(d.occupied_threshold),
            },
        }
    }
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
        config.mapper_sensors()?;
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

    /// Names `mapper`'s first sensor (made with [`Self::mapper_params`]'s)
    /// as the config does and adds the config's other sensors, in order.
    pub fn add_sensors_to<B: Backend>(&self, mapper: &mut Mapper<B>) -> Result<(), MapError> {
        mapper.rename_sensor(0, self.sensor.name())?;
        for (sensor, _) in self.mapper_sensors()?.into_iter().skip(1) {
            mapper.add_sensor(sensor)?;
        }
        Ok(())
    }

    /// Every sensor: [`Self::sensor`], then [`Self::other_sensors`].
    pub fn sensors(&self) -> impl Iterator<Item = &SensorSection> {
        std::iter::once(&self.sensor).chain(&self.other_sensors)
    }

    /// Every sensor, to change (a recording's calibration).
    pub fn sensors_mut(&mut self) -> impl Iterator<Item = &mut SensorSection> {
        std::iter::once(&mut self.sensor).chain(&mut self.other_sensors)
    }

    /// Keeps the sensors named in `names` (in the config's order) and drops
    /// the others; the error names an unknown sensor and lists the
    /// config's, or says that none is left.
    pub fn keep_sensors(&mut self, names: &[String]) -> Result<(), String> {
        let known: Vec<&str> = self.sensors().map(|s| s.name()).collect();
        if let Some(unknown) = names.iter().find(|n| !known.contains(&n.as_str())) {
            return Err(format!("no sensor is named {unknown:?} (the sensors: {})", known.join(", ")));
        }
        let mut kept = self.sensors().filter(|s| names.iter().any(|n| n == s.name())).cloned();
        let Some(first) = kept.next() else { return Err("no sensor is named: name one or more".into()) };
        let rest: Vec<SensorSection> = kept.collect();
        // A lone sensor keeps its entry's name, so its frames say which it is.
        let mut first = first;
        first.name = Some(first.name().to_string());
        self.sensor = first;
        self.other_sensors = rest;
        Ok(())
    }

    /// Every sensor, checked as [`Self::mapper_params`] checks the first,
    /// with its mount on the robot (`T_body_sensor`); an error names the
    /// sensor. The first's occupancy options are the parameters' `ogm`.
    pub fn mapper_sensors(&self) -> Result<Vec<(MapperSensor, Isometry3<f64>)>, MapError> {
        self.sensors()
            .map(|s| {
                let in_sensor = |source: edtmap_core::CoreError| match self.other_sensors.len() {
                    0 => MapError::Config { section: "sensor", source },
                    _ => MapError::ConfigFile {
                        path: format!("[[sensors]] {:?}", s.name()),
                        message: source.to_string(),
                    },
                };
                let (sensor, ogm) = s.checked().map_err(in_sensor)?;
                let mount = s.t_body_sensor().map_err(in_sensor)?;
                Ok((MapperSensor { name: s.name().to_string(), sensor, ogm }, mount))
            })
            .collect()
    }
}
