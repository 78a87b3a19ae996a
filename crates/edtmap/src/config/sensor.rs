//! `[sensor]`: the sensor model, and how its frames become occupancy.
//!
//! The section is one flat TOML table (`kind = "lidar"`, `rings = 32`, ...),
//! read into the fields every kind shares plus one group per kind
//! ([`LidarFields`], [`CameraFields`]); [`SensorSection::model`] checks the
//! group that `kind` names, by hand.
//!
//! Why not a serde enum tagged by `kind`: serde reads an internally tagged
//! enum through a buffer, so every error in the section would point at its
//! `[sensor]` header, a value of the wrong type would no longer name its
//! field (`invalid type: string "small", expected f32`), and a config whose
//! kind was switched would be refused for the other kind's fields
//! (`unknown field rings`) rather than for what the new kind lacks
//! (`invalid fx = missing: required for kind = "depth"`). Fields of
//! another kind are accepted and unused, as before; a misspelt field is
//! still refused.

use edtmap_core::construction::{Construction, OgmOptions};
use edtmap_core::sensor::{PinholeCamera, RangeLimits, Sensor, SpinningLidar};
use edtmap_core::CoreError;
use nalgebra::{Isometry3, Quaternion, Translation3};
use serde::Deserialize;

/// `[sensor]`: the sensor model, and how its frames become occupancy.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(from = "SensorTable")]
pub struct SensorSection {
    /// `[[sensors]]`: the sensor's name in frames and reports (default:
    /// its kind's name).
    pub name: Option<String>,
    /// `[[sensors]]`: where the sensor sits on the robot, `T_body_sensor`,
    /// as `[x, y, z, qx, qy, qz, qw]` (metres, unit quaternion); identity
    /// by default. A single `[sensor]`'s is `[dataset] sensor_in_body`.
    pub sensor_in_body: Option<[f64; 7]>,
    /// `[[sensors]]`, for ROS recordings and the live node: the topic the
    /// sensor's messages come on (`PointCloud2`, `Image` or `LaserScan`).
    /// A single `[sensor]`'s is `[dataset]` (or `[ros]`) `sensor_topic`.
    pub topic: Option<String>,
    /// `[[sensors]]`, depth cameras: the camera info topic (default: the
    /// image topic's sibling `camera_info`). A single `[sensor]`'s is
    /// `[dataset]` (or `[ros]`) `camera_info_topic`.
    pub camera_info_topic: Option<String>,
    /// `depth`, `lidar`, `points` or `planar`.
    pub kind: SensorKind,
    /// `auto` (projection when the model allows), `projection` or `raycast`.
    pub construction: ConstructionName,
    /// Whether rays with no return clear space up to `max_range_m`.
    pub clear_no_return: bool,
    /// Shortest valid return, metres.
    pub min_range_m: f32,
    /// Longest valid return, metres.
    pub max_range_m: f32,
    /// Both constructions: a voxel is free only when it lies more than this in front of the return, metres (default half a voxel diagonal).
    pub free_margin_m: Option<f32>,
    /// Planar projection: half thickness of the observed slab, metres (default half a voxel).
    pub planar_half_thickness_m: Option<f32>,
    /// `kind = "lidar"`: the rings and azimuth bins.
    pub lidar: LidarFields,
    /// `kind = "depth"`: the pinhole camera; for recordings also the
    /// intrinsics of folders without their own.
    pub camera: CameraFields,
}

/// The fields of a spinning LiDAR (`kind = "lidar"`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LidarFields {
    /// Number of evenly spread rings.
    pub rings: Option<usize>,
    /// Elevation of the lowest ring, degrees.
    pub elevation_min_deg: Option<f64>,
    /// Elevation of the highest ring, degrees.
    pub elevation_max_deg: Option<f64>,
    /// Explicit ring elevations in degrees (instead of `rings`).
    pub ring_elevations_deg: Option<Vec<f64>>,
    /// Azimuth bins per turn.
    pub azimuth_bins: Option<usize>,
}

/// The fields of a pinhole depth camera (`kind = "depth"`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CameraFields {
    /// Focal length x, pixels.
    pub fx: Option<f64>,
    /// Focal length y, pixels.
    pub fy: Option<f64>,
    /// Principal point x, pixels.
    pub cx: Option<f64>,
    /// Principal point y, pixels.
    pub cy: Option<f64>,
    /// Image width, pixels.
    pub width: Option<u32>,
    /// Image height, pixels.
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

/// `[sensor]` as the file writes it: one flat table, unknown fields refused
/// with their line.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorTable {
    name: Option<String>,
    sensor_in_body: Option<[f64; 7]>,
    topic: Option<String>,
    camera_info_topic: Option<String>,
    kind: SensorKind,
    #[serde(default)]
    construction: ConstructionName,
    #[serde(default)]
    clear_no_return: bool,
    min_range_m: f32,
    max_range_m: f32,
    free_margin_m: Option<f32>,
    planar_half_thickness_m: Option<f32>,
    rings: Option<usize>,
    elevation_min_deg: Option<f64>,
    elevation_max_deg: Option<f64>,
    ring_elevations_deg: Option<Vec<f64>>,
    azimuth_bins: Option<usize>,
    fx: Option<f64>,
    fy: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    width: Option<u32>,
    height: Option<u32>,
}

impl From<SensorTable> for SensorSection {
    fn from(t: SensorTable) -> Self {
        SensorSection {
            name: t.name,
            sensor_in_body: t.sensor_in_body,
            topic: t.topic,
            camera_info_topic: t.camera_info_topic,
            kind: t.kind,
            construction: t.construction,
            clear_no_return: t.clear_no_return,
            min_range_m: t.min_range_m,
            max_range_m: t.max_range_m,
            free_margin_m: t.free_margin_m,
            planar_half_thickness_m: t.planar_half_thickness_m,
            lidar: LidarFields {
                rings: t.rings,
                elevation_min_deg: t.elevation_min_deg,
                elevation_max_deg: t.elevation_max_deg,
                ring_elevations_deg: t.ring_elevations_deg,
                azimuth_bins: t.azimuth_bins,
            },
            camera: CameraFields { fx: t.fx, fy: t.fy, cx: t.cx, cy: t.cy, width: t.width, height: t.height },
        }
    }
}

fn need<T: Copy>(v: Option<T>, field: &'static str, kind: &'static str) -> Result<T, CoreError> {
    v.ok_or(CoreError::InvalidParam { field, value: "missing".into(), reason: kind })
}

impl SensorSection {
    /// The sensor's name: `name`, else its kind's.
    pub fn name(&self) -> &str {
        self.name.as_deref().unwrap_or(match self.kind {
            SensorKind::Depth => "depth",
            SensorKind::Lidar => "lidar",
            SensorKind::Points => "points",
            SensorKind::Planar => "planar",
        })
    }

    /// `T_body_sensor` from `sensor_in_body` (identity when absent).
    pub fn t_body_sensor(&self) -> Result<Isometry3<f64>, CoreError> {
        sensor_in_body("sensor_in_body", self.sensor_in_body)
    }

    /// The sensor model and how its frames become occupancy, every field
    /// checked: each number in its range, then the model's own checks. An
    /// error names the field.
    pub fn checked(&self) -> Result<(Sensor, OgmOptions), CoreError> {
        self.check_limits()?;
        let sensor = self.model()?;
        let ogm = self.ogm_options(&sensor)?;
        Ok((sensor, ogm))
    }

    /// The sensor model this section describes (its numbers' ranges
    /// unchecked: [`Self::checked`] checks them first).
    fn model(&self) -> Result<Sensor, CoreError> {
        let range = RangeLimits { min_m: self.min_range_m, max_m: self.max_range_m };
        let sensor = match self.kind {
            SensorKind::Depth => Sensor::Depth(self.camera.camera(range)?),
            SensorKind::Lidar => Sensor::Lidar(self.lidar.lidar(range)?),
            SensorKind::Points => Sensor::Points(range),
            SensorKind::Planar => Sensor::Planar,
        };
        if self.kind == SensorKind::Planar && !(range.min_m >= 0.0 && range.max_m > range.min_m) {
            return Err(CoreError::InvalidParam {
                field: "min_range_m/max_range_m",
                value: format!("{}..{}", range.min_m, range.max_m),
                reason: "need 0 ≤ min < max",
            });
        }
        sensor.validate()?;
        Ok(sensor)
    }

    /// How frames of `sensor` become occupancy (lengths not set follow the
    /// voxel size in use).
    fn ogm_options(&self, sensor: &Sensor) -> Result<OgmOptions, CoreError> {
        let construction = match self.construction {
            ConstructionName::Auto => Construction::Auto,
            ConstructionName::Raycast => Construction::RayCasting,
            ConstructionName::Projection => Construction::Projection,
        };
        check_construction(sensor, construction)?;
        // Both lengths are in range: `Self::checked` checked them first.
        Ok(OgmOptions {
            construction,
            clear_no_return: self.clear_no_return,
            free_margin_m: self.free_margin_m,
            planar_half_thickness_m: self.planar_half_thickness_m,
        })
    }
}

impl LidarFields {
    /// The LiDAR with these rings and `range`: from `ring_elevations_deg`,
    /// else `rings` spread evenly between the two elevations.
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
            return Err(CoreError::InvalidParam {
                field: "rings",
                value: rings.to_string(),
                reason: "must be between 1 and 4096",
            });
        }
        let (lo, hi) = (
            need(self.elevation_min_deg, "elevation_min_deg", why)?,
            need(self.elevation_max_deg, "elevation_max_deg", why)?,
        );
        Ok(SpinningLidar::uniform(rings, lo.to_radians(), hi.to_radians(), bins, range))
    }
}

impl CameraFields {
    /// The pinhole camera with these intrinsics and `range`; every field
    /// is needed.
    fn camera(&self, range: RangeLimits) -> Result<PinholeCamera, CoreError> {
        let why = "required for kind = \"depth\"";
        Ok(PinholeCamera {
            fx: need(self.fx, "fx", why)?,
            fy: need(self.fy, "fy", why)?,
            cx: need(self.cx, "cx", why)?,
            cy: need(self.cy, "cy", why)?,
            width: need(self.width, "width", why)?,
            height: need(self.height, "height", why)?,
            range,
        })
    }

    /// `[fx, fy, cx, cy]` when all four are given.
    pub fn intrinsics(&self) -> Option<[f64; 4]> {
        self.fx.zip(self.fy).zip(self.cx.zip(self.cy)).map(|((fx, fy), (cx, cy))| [fx, fy, cx, cy])
    }
}

/// `T_body_sensor` from `[x, y, z, qx, qy, qz, qw]` (identity when absent),
/// the quaternion checked for unit length; `field` names it in errors.
pub fn sensor_in_body(field: &'static str, pose: Option<[f64; 7]>) -> Result<Isometry3<f64>, CoreError> {
    let Some([x, y, z, qx, qy, qz, qw]) = pose else {
        return Ok(Isometry3::identity());
    };
    let finite = [x, y, z, qx, qy, qz, qw].iter().all(|v| v.is_finite());
    match edtmap_core::sensor::rotation_from_quaternion(Quaternion::new(qw, qx, qy, qz)) {
        Ok((rotation, _)) if finite => Ok(Isometry3::from_parts(Translation3::new(x, y, z), rotation)),
        _ => Err(CoreError::InvalidParam {
            field,
            value: format!("{:?}", [x, y, z, qx, qy, qz, qw]),
            reason: "must be [x, y, z, qx, qy, qz, qw] with a unit quaternion (norm within 1e-2 of 1)",
        }),
    }
}

/// Refuses volumetric projection for a sensor projection cannot read.
pub(crate) fn check_construction(sensor: &Sensor, construction: Construction) -> Result<(), CoreError> {
    if construction == Construction::Projection && !sensor.supports_projection() {
        return Err(CoreError::InvalidParam {
            field: "construction",
            value: "\"projection\"".into(),
            reason: "a point cloud sensor has no model to project into; use \"raycast\"",
        });
    }
    Ok(())
}
