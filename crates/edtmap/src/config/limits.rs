//! The accepted range of every number of the configuration. Each float
//! field must be finite and physically meaningful before any stage sees it:
//! a focal length of 1e-30 px or a depth scale of 1e30 m per unit is a typo,
//! not a setting, and would otherwise make every frame empty or every ray
//! overflow. The ranges are generous; the stages check the relations
//! between fields (min below max, cutoff at least one voxel). The
//! applications check their own sections with the same [`Limit`]s.

use super::{CameraFields, LidarFields, SensorSection};
use crate::{MapError, MapperParams};
use edtmap_core::construction::OgmOptions;
use edtmap_core::{CoreError, GlobalParams, LocalVolume};

/// A closed, half-open or open interval of accepted values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limit {
    /// Lowest value.
    pub lo: f64,
    /// Whether `lo` itself is refused.
    pub lo_open: bool,
    /// Highest value.
    pub hi: f64,
    /// Whether `hi` itself is refused.
    pub hi_open: bool,
    /// What the error says the value must be: the interval and its unit,
    /// exactly as [`Limit::describe`] writes it (a unit test checks).
    pub accepted: &'static str,
}

/// Focal lengths, pixels.
pub(crate) const FOCAL_PX: Limit =
    Limit { lo: 1.0, lo_open: false, hi: 1e6, hi_open: false, accepted: "must be finite, in [1, 1e6] pixels" };
/// Sensor range limits, metres.
pub(crate) const RANGE_M: Limit =
    Limit { lo: 0.0, lo_open: false, hi: 1000.0, hi_open: false, accepted: "must be finite, in [0, 1000] metres" };
/// Margins and half thicknesses of the occupancy construction, metres.
pub(crate) const MARGIN_M: Limit =
    Limit { lo: 0.0, lo_open: false, hi: 10.0, hi_open: false, accepted: "must be finite, in [0, 10] metres" };
/// LiDAR ring elevations, degrees.
pub(crate) const ELEVATION_DEG: Limit =
    Limit { lo: -90.0, lo_open: true, hi: 90.0, hi_open: true, accepted: "must be finite, in (-90, 90) degrees" };
/// Voxel edge length, metres.
pub(crate) const VOXEL_M: Limit =
    Limit { lo: 1e-4, lo_open: false, hi: 10.0, hi_open: false, accepted: "must be finite, in [1e-4, 10] metres" };
/// Each edge of the local volume, metres.
pub(crate) const LOCAL_SIZE_M: Limit =
    Limit { lo: 0.0, lo_open: true, hi: 1000.0, hi_open: false, accepted: "must be finite, in (0, 1000] metres" };
/// World coordinates (heights, forbidden zones), metres.
pub const WORLD_M: Limit =
    Limit { lo: -1e6, lo_open: false, hi: 1e6, hi_open: false, accepted: "must be finite, in [-1e6, 1e6] metres" };
/// Cutoff of the global EDT, metres.
pub(crate) const MAX_DISTANCE_M: Limit =
    Limit { lo: 0.0, lo_open: true, hi: 1000.0, hi_open: false, accepted: "must be finite, in (0, 1000] metres" };
/// Scale of 16-bit depth images, metres per unit.
pub const DEPTH_SCALE_M: Limit = Limit {
    lo: 1e-6,
    lo_open: false,
    hi: 1000.0,
    hi_open: false,
    accepted: "must be finite, in [1e-6, 1000] metres per unit",
};
/// Largest time between two poses, seconds.
pub const POSE_GAP_S: Limit =
    Limit { lo: 0.0, lo_open: true, hi: 3600.0, hi_open: false, accepted: "must be finite, in (0, 3600] seconds" };
/// The sensor's offset on the robot, metres.
pub const OFFSET_M: Limit = Limit {
    lo: -1000.0,
    lo_open: false,
    hi: 1000.0,
    hi_open: false,
    accepted: "must be finite, in [-1000, 1000] metres",
};
/// The principal point's x, in image widths from the image's left edge:
/// within one image width around the image.
const PRINCIPAL_X: Limit = Limit {
    lo: -1.0,
    lo_open: false,
    hi: 2.0,
    hi_open: false,
    accepted: "must be finite, in [-1, 2] × the image width",
};
/// The principal point's y, in image heights from the top edge.
const PRINCIPAL_Y: Limit = Limit {
    lo: -1.0,
    lo_open: false,
    hi: 2.0,
    hi_open: false,
    accepted: "must be finite, in [-1, 2] × the image height",
};

impl Limit {
    /// Whether `v` is finite and inside the interval.
    pub fn accepts(&self, v: f64) -> bool {
        let above = if self.lo_open { v > self.lo } else { v >= self.lo };
        let below = if self.hi_open { v < self.hi } else { v <= self.hi };
        v.is_finite() && above && below
    }

    /// The interval as text, e.g. `finite, in (0, 1000] metres`.
    #[cfg(test)]
    fn describe(&self, unit: &str) -> String {
        let (open, close) = (if self.lo_open { '(' } else { '[' }, if self.hi_open { ')' } else { ']' });
        let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
        format!("must be finite, in {open}{}, {}{close}{unit}", short(self.lo), short(self.hi))
    }

    /// Checks `value` of `field`; `shown` is the value as the error prints it.
    pub fn check(&self, field: &'static str, value: f64, shown: String) -> Result<(), CoreError> {
        if self.accepts(value) {
            Ok(())
        } else {
            Err(CoreError::InvalidParam { field, value: shown, reason: self.accepted })
        }
    }

    /// Checks an `f64` field.
    pub fn f64(&self, field: &'static str, value: f64) -> Result<(), CoreError> {
        self.check(field, value, format!("{value:?}"))
    }

    /// Checks an `f32` field (printed as the `f32` it is).
    pub fn f32(&self, field: &'static str, value: f32) -> Result<(), CoreError> {
        self.check(field, f64::from(value), format!("{value:?}"))
    }

    /// Checks an optional `f64` field, if given.
    pub fn opt(&self, field: &'static str, value: Option<f64>) -> Result<(), CoreError> {
        value.map_or(Ok(()), |v| self.f64(field, v))
    }

    /// Checks every element of an array field; the error shows the array.
    pub fn all(&self, field: &'static str, values: &[f64]) -> Result<(), CoreError> {
        match values.iter().all(|&v| self.accepts(v)) {
            true => Ok(()),
            false => Err(CoreError::InvalidParam { field, value: format!("{values:?}"), reason: self.accepted }),
        }
    }
}

/// A bound as the accepted texts write it: plain for ordinary magnitudes,
/// `1e6` style for very large or small ones.
#[cfg(test)]
fn short(v: f64) -> String {
    if v == 0.0 || (1e-3..1e4).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

impl MapperParams {
    /// Checks every parameter, however the parameters were made (a file, the
    /// Python keywords, the C struct, by hand): each number finite and in
    /// its range, then the relations between them (the local volume's size
    /// in voxels, the log-odds, the cutoff, the forbidden zones). An error
    /// names the configuration section and field the value belongs to.
    pub fn validate(&self) -> Result<(), MapError> {
        let in_section = |section| move |source| MapError::Config { section, source };
        let in_occupancy = in_section("occupancy");
        VOXEL_M.f64("voxel_size_m", self.voxel_size_m).map_err(in_occupancy)?;
        LOCAL_SIZE_M.all("local_size_m", &self.volume.size_m).map_err(in_occupancy)?;
        WORLD_M.opt("fixed_height_m", self.volume.fixed_height_m).map_err(in_occupancy)?;
        self.occupancy.log_odds().map_err(in_occupancy)?;
        LocalVolume::centred(&self.volume, self.voxel_size_m, [0.0; 3]).map_err(in_occupancy)?;
        check_ogm(&self.ogm).map_err(in_section("sensor"))?;
        let in_global = in_section("global");
        check_global(&self.global).map_err(in_global)?;
        self.global.cutoff(self.voxel_size_m).map_err(in_global)?;
        self.global.check_forbidden().map_err(in_global)
    }
}

/// Checks a sensor's occupancy options: each length in its range.
pub(crate) fn check_ogm(ogm: &OgmOptions) -> Result<(), CoreError> {
    for (field, v) in [("free_margin_m", ogm.free_margin_m), ("planar_half_thickness_m", ogm.planar_half_thickness_m)] {
        v.map_or(Ok(()), |v| MARGIN_M.f32(field, v))?;
    }
    Ok(())
}

impl SensorSection {
    pub(super) fn check_limits(&self) -> Result<(), CoreError> {
        RANGE_M.f32("min_range_m", self.min_range_m)?;
        RANGE_M.f32("max_range_m", self.max_range_m)?;
        for (field, v) in
            [("free_margin_m", self.free_margin_m), ("planar_half_thickness_m", self.planar_half_thickness_m)]
        {
            v.map_or(Ok(()), |v| MARGIN_M.f32(field, v))?;
        }
        if let Some(pose) = &self.sensor_in_body {
            OFFSET_M.all("sensor_in_body", &pose[..3])?;
        }
        self.t_body_sensor()?;
        self.lidar.check_limits()?;
        self.camera.check_limits()
    }
}

impl LidarFields {
    fn check_limits(&self) -> Result<(), CoreError> {
        ELEVATION_DEG.opt("elevation_min_deg", self.elevation_min_deg)?;
        ELEVATION_DEG.opt("elevation_max_deg", self.elevation_max_deg)?;
        match &self.ring_elevations_deg {
            Some(table) => ELEVATION_DEG.all("ring_elevations_deg", table),
            None => Ok(()),
        }
    }
}

impl CameraFields {
    fn check_limits(&self) -> Result<(), CoreError> {
        FOCAL_PX.opt("fx", self.fx)?;
        FOCAL_PX.opt("fy", self.fy)?;
        principal_point(("cx", PRINCIPAL_X), self.cx, self.width, "width")?;
        principal_point(("cy", PRINCIPAL_Y), self.cy, self.height, "height")
    }
}

/// Checks a principal point coordinate against the image size along its
/// axis, when both are given (a missing one is reported by the sensor).
fn principal_point(
    (field, limit): (&'static str, Limit),
    value: Option<f64>,
    size: Option<u32>,
    size_name: &str,
) -> Result<(), CoreError> {
    let (Some(v), Some(n)) = (value, size) else { return Ok(()) };
    let images = v / f64::from(n.max(1));
    limit.check(field, images, format!("{v:?} (image {size_name} {n})"))
}

fn check_global(global: &GlobalParams) -> Result<(), CoreError> {
    MAX_DISTANCE_M.f64("max_distance_m", global.max_distance_m)?;
    for zone in &global.forbidden {
        let corners: Vec<f64> = zone.min_m.iter().chain(&zone.max_m).copied().collect();
        if !corners.iter().all(|&c| WORLD_M.accepts(c)) {
            let value = format!("{{ min_m = {:?}, max_m = {:?} }}", zone.min_m, zone.max_m);
            return Err(CoreError::InvalidParam {
                field: "forbidden",
                value,
                reason: "corners must be finite, in [-1e6, 1e6] metres",
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepted_texts_match_the_intervals() {
        let limits = [
            (FOCAL_PX, "pixels"),
            (RANGE_M, "metres"),
            (MARGIN_M, "metres"),
            (ELEVATION_DEG, "degrees"),
            (VOXEL_M, "metres"),
            (LOCAL_SIZE_M, "metres"),
            (WORLD_M, "metres"),
            (MAX_DISTANCE_M, "metres"),
            (DEPTH_SCALE_M, "metres per unit"),
            (POSE_GAP_S, "seconds"),
            (OFFSET_M, "metres"),
            (PRINCIPAL_X, "× the image width"),
            (PRINCIPAL_Y, "× the image height"),
        ];
        for (limit, unit) in limits {
            assert_eq!(limit.accepted, limit.describe(unit));
        }
    }

    #[test]
    fn ends_open_and_closed() {
        assert!(
            FOCAL_PX.accepts(1.0) && FOCAL_PX.accepts(1e6) && !FOCAL_PX.accepts(0.999) && !FOCAL_PX.accepts(f64::NAN)
        );
        assert!(!ELEVATION_DEG.accepts(90.0) && !ELEVATION_DEG.accepts(-90.0) && ELEVATION_DEG.accepts(89.9));
        assert!(!LOCAL_SIZE_M.accepts(0.0) && LOCAL_SIZE_M.accepts(1000.0) && !LOCAL_SIZE_M.accepts(f64::INFINITY));
    }

    #[test]
    fn principal_point_is_relative_to_the_image() {
        let cx = ("cx", PRINCIPAL_X);
        assert!(principal_point(cx, Some(320.0), Some(640), "width").is_ok());
        assert!(principal_point(cx, Some(-640.0), Some(640), "width").is_ok());
        assert!(principal_point(cx, Some(-641.0), Some(640), "width").is_err());
        let e = principal_point(cx, Some(1e30), Some(640), "width").expect_err("far outside");
        assert_eq!(e.to_string(), "invalid cx = 1e30 (image width 640): must be finite, in [-1, 2] × the image width");
    }
}
