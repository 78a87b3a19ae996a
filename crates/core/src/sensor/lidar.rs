//! Spinning 3D LiDAR with a table of rings, as a range image.

use super::{check_range, RangeLimits, SensorModel, SensorRay, View};
use crate::CoreError;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A spinning LiDAR: rings at fixed elevations, swept in azimuth. Sensor
/// frame: x forward, y left, z up; azimuth is measured from x towards y.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpinningLidar {
    /// Elevation of each ring in radians, strictly increasing.
    pub ring_elevations_rad: Vec<f64>,
    /// Azimuth bins per turn; bin `b` is centred on `−π + (b + ½)·2π/bins`.
    pub azimuth_bins: usize,
    /// Valid range in metres.
    pub range: RangeLimits,
}

/// One sweep of a [`SpinningLidar`]: a range image, ring-major
/// (`ranges[ring * azimuth_bins + bin]`, metres; NaN, inf, 0 or out of range
/// means no return).
#[derive(Debug, Clone, PartialEq)]
pub struct LidarScan {
    /// The ranges.
    pub ranges: Vec<f32>,
}

/// Most rings a spinning LiDAR may have (real ones have up to 128).
pub const MAX_RINGS: usize = 1 << 12;

impl SpinningLidar {
    /// `rings` rings evenly spread over `[lowest, highest]` radians.
    pub fn uniform(rings: usize, lowest_rad: f64, highest_rad: f64, azimuth_bins: usize, range: RangeLimits) -> Self {
        let step = if rings > 1 { (highest_rad - lowest_rad) / (rings - 1) as f64 } else { 0.0 };
        let ring_elevations_rad = (0..rings).map(|r| lowest_rad + step * r as f64).collect();
        SpinningLidar { ring_elevations_rad, azimuth_bins, range }
    }

    /// Checks the ring table and bins.
    pub fn validate(&self) -> Result<(), CoreError> {
        let rings = &self.ring_elevations_rad;
        let sorted = rings.windows(2).all(|w| w[0] < w[1]);
        let in_range = rings.iter().all(|e| e.is_finite() && e.abs() < PI / 2.0);
        if rings.len() > MAX_RINGS {
            return Err(CoreError::InvalidParam {
                field: "ring_elevations",
                value: format!("{} rings", rings.len()),
                reason: "at most 4096 rings",
            });
        }
        if rings.is_empty() || !sorted || !in_range {
            return Err(CoreError::InvalidParam {
                field: "ring_elevations",
                value: format!("{rings:?}"),
                reason: "need at least one ring, strictly increasing, within ±90°",
            });
        }
        if !(1..=1 << 20).contains(&self.azimuth_bins) {
            return Err(CoreError::InvalidParam {
                field: "azimuth_bins",
                value: self.azimuth_bins.to_string(),
                reason: "must be between 1 and 2^20",
            });
        }
        check_range(&self.range)
    }

    /// Checks that `scan` has one range per ring and bin.
    pub fn check(&self, scan: &LidarScan) -> Result<(), CoreError> {
        let expected = self.ring_elevations_rad.len() * self.azimuth_bins;
        if scan.ranges.len() != expected {
            return Err(CoreError::BadMeasurement(format!(
                "LiDAR scan has {} ranges, the sensor has {} rings × {} bins = {expected}",
                scan.ranges.len(),
                self.ring_elevations_rad.len(),
                self.azimuth_bins
            )));
        }
        Ok(())
    }

    /// Azimuth of bin `b`'s centre, radians.
    pub fn bin_azimuth(&self, b: usize) -> f64 {
        -PI + (b as f64 + 0.5) * 2.0 * PI / self.azimuth_bins as f64
    }

    /// Unit direction of ring `r`, bin `b`.
    pub fn direction(&self, r: usize, b: usize) -> [f64; 3] {
        let (el, az) = (self.ring_elevations_rad[r], self.bin_azimuth(b));
        [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()]
    }

    /// The ring and bin whose beam is nearest to the direction of `p`,
    /// when `p`'s elevation is within half a ring spacing of a ring (the
    /// outermost rings reach half a spacing beyond themselves).
    #[inline]
    pub fn project(&self, p: [f32; 3]) -> Option<(usize, usize)> {
        let ring = self.nearest_ring(Self::elevation(p).1)?;
        Some((ring, self.azimuth_bin(p)))
    }

    /// The horizontal distance of `p` (rounded to `f32`, then widened) and
    /// its elevation in radians: the one computation of both that every
    /// decision about `p` shares.
    #[inline]
    pub fn elevation(p: [f32; 3]) -> (f64, f64) {
        let horiz = (p[0] * p[0] + p[1] * p[1]).sqrt() as f64;
        (horiz, (p[2] as f64).atan2(horiz))
    }

    /// The azimuth bin of the direction of `p`.
    #[inline]
    pub fn azimuth_bin(&self, p: [f32; 3]) -> usize {
        let az = (p[1] as f64).atan2(p[0] as f64);
        let bin = ((az + PI) / (2.0 * PI) * self.azimuth_bins as f64).floor() as usize;
        bin.min(self.azimuth_bins - 1)
    }

    /// The lowest and highest elevation, radians, for which
    /// [`Self::nearest_ring`] finds a ring.
    pub fn fan_rad(&self) -> (f64, f64) {
        let rings = &self.ring_elevations_rad;
        let n = rings.len();
        let (below, above) = match n {
            1 => (PI / self.azimuth_bins as f64, PI / self.azimuth_bins as f64),
            _ => ((rings[1] - rings[0]).abs() / 2.0, (rings[n - 1] - rings[n - 2]).abs() / 2.0),
        };
        (rings[0] - below, rings[n - 1] + above)
    }

    /// The ring nearest to elevation `el` (radians, as [`Self::elevation`] gives
    /// it), if `el` is within the fan (see [`Self::project`]).
    #[inline]
    pub fn nearest_ring(&self, el: f64) -> Option<usize> {
        let rings = &self.ring_elevations_rad;
        let i = rings.partition_point(|&e| e < el);
        let spacing = |a: usize, b: usize| (rings[b] - rings[a]).abs();
        let candidates = [i.checked_sub(1), (i < rings.len()).then_some(i)];
        let best = candidates
            .into_iter()
            .flatten()
            .min_by(|&a, &b| (rings[a] - el).abs().total_cmp(&(rings[b] - el).abs()))?;
        let n = rings.len();
        let half = if n == 1 {
            // One ring: accept half a bin's angle either side.
            PI / self.azimuth_bins as f64
        } else if best == 0 {
            spacing(0, 1) / 2.0
        } else if best == n - 1 {
            spacing(n - 2, n - 1) / 2.0
        } else {
            // Inside the fan the nearest ring is always within half a spacing.
            f64::INFINITY
        };
        ((rings[best] - el).abs() <= half).then_some(best)
    }

    /// See [`View::beam_passes_within`].
    pub(super) fn ring_passes_within(&self, p: [f32; 3], radius_m: f32) -> bool {
        let (horiz, el) = Self::elevation(p);
        self.ring_passes_at(p, horiz, el, radius_m)
    }

    /// [`View::beam_passes_within`] of `p`, whose horizontal
    /// distance and elevation [`Self::elevation`] gave.
    #[inline]
    pub fn ring_passes_at(&self, p: [f32; 3], horiz: f64, el: f64, radius_m: f32) -> bool {
        let r = (horiz * horiz + (p[2] as f64).powi(2)).sqrt();
        if r <= radius_m as f64 {
            return true;
        }
        let reach = (radius_m as f64 / r).asin();
        let rings = &self.ring_elevations_rad;
        let i = rings.partition_point(|&e| e < el);
        [i.checked_sub(1), (i < rings.len()).then_some(i)].into_iter().flatten().any(|k| (rings[k] - el).abs() <= reach)
    }
}

impl SensorModel for SpinningLidar {
    type Data = LidarScan;
    const NAME: &'static str = "lidar";
    const KIND: &'static str = "spinning LiDAR";
    const PROJECTS: bool = true;

    fn validate(&self) -> Result<(), CoreError> {
        SpinningLidar::validate(self)
    }

    fn check(&self, scan: &LidarScan) -> Result<(), CoreError> {
        SpinningLidar::check(self, scan)
    }

    fn range(&self) -> RangeLimits {
        self.range
    }

    fn rays(&self, scan: &LidarScan, clear_no_return: bool, out: &mut Vec<SensorRay>) {
        for r in 0..self.ring_elevations_rad.len() {
            for b in 0..self.azimuth_bins {
                let d = scan.ranges[r * self.azimuth_bins + b];
                let dir = self.direction(r, b).map(|c| c as f32);
                out.extend(SensorRay::from_range(dir, d, &self.range, clear_no_return));
            }
        }
    }

    fn view<'a>(&'a self, scan: &'a LidarScan) -> Option<View<'a>> {
        Some(View::Rings { lidar: self, scan })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sensor() -> SpinningLidar {
        SpinningLidar::uniform(
            16,
            -15f64.to_radians(),
            15f64.to_radians(),
            360,
            RangeLimits { min_m: 0.2, max_m: 30.0 },
        )
    }

    #[test]
    fn beam_directions_project_to_their_own_cell() {
        let s = sensor();
        s.validate().expect("valid");
        for r in 0..16 {
            for b in (0..360).step_by(7) {
                let d = s.direction(r, b).map(|c| (c * 5.0) as f32);
                assert_eq!(s.project(d), Some((r, b)));
            }
        }
    }

    #[test]
    fn directions_outside_the_fan_are_unseen() {
        let s = sensor();
        assert_eq!(s.project([1.0, 0.0, 0.5]), None);
        assert_eq!(s.project([1.0, 0.0, -0.5]), None);
        assert!(s.project([1.0, 0.0, 0.27]).is_some());
    }

    #[test]
    fn unsorted_rings_are_rejected() {
        let mut s = sensor();
        s.ring_elevations_rad.swap(0, 1);
        assert!(s.validate().expect_err("unsorted").to_string().contains("ring_elevations"));
    }
}
