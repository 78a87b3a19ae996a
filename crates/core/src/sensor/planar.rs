//! Planar 2D LiDAR with ROS `sensor_msgs/LaserScan` semantics.

use super::{RangeLimits, SensorModel, SensorRay, View};
use crate::CoreError;

/// One planar scan in the sensor's x–y plane (x forward, y left): beam `i`
/// points at `angle_min_rad + i · angle_increment_rad` from x towards y.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserScan {
    /// Angle of the first beam, radians.
    pub angle_min_rad: f64,
    /// Angle between beams, radians (may be negative).
    pub angle_increment_rad: f64,
    /// Measured ranges in metres; NaN, inf, 0 or out of range is no return.
    pub ranges: Vec<f32>,
    /// Valid range of the scanner.
    pub range: RangeLimits,
}

impl LaserScan {
    /// Checks the scan's geometry.
    pub fn validate(&self) -> Result<(), CoreError> {
        if self.ranges.is_empty() {
            return Err(CoreError::BadMeasurement("laser scan has no ranges".into()));
        }
        let inc = self.angle_increment_rad;
        if !self.angle_min_rad.is_finite() || !inc.is_finite() || inc == 0.0 {
            return Err(CoreError::BadMeasurement(format!(
                "laser scan angle_min {} / angle_increment {inc} must be finite, increment non-zero",
                self.angle_min_rad
            )));
        }
        if (inc.abs() * self.ranges.len() as f64) > 2.0 * std::f64::consts::PI + inc.abs() {
            return Err(CoreError::BadMeasurement(format!(
                "{} beams of {inc} rad cover more than a turn",
                self.ranges.len()
            )));
        }
        super::check_range(&self.range)
    }

    /// The beam nearest to the direction of `p` (in the scan plane).
    #[inline]
    pub fn beam(&self, p: [f32; 3]) -> Option<usize> {
        let tau = 2.0 * std::f64::consts::PI;
        let az = (p[1] as f64).atan2(p[0] as f64);
        let rel = (az - self.angle_min_rad) / self.angle_increment_rad;
        // Turn the angle into the scan's sweep, whichever way it goes.
        let per_turn = tau / self.angle_increment_rad.abs();
        let i = (rel.rem_euclid(per_turn) + 0.5).floor();
        let i = if i >= per_turn.floor() && (i - per_turn).abs() < 1.0 { 0.0 } else { i };
        (i >= 0.0 && (i as usize) < self.ranges.len()).then_some(i as usize)
    }

    pub(super) fn rays(&self, clear_no_return: bool, out: &mut Vec<SensorRay>) {
        for (i, &d) in self.ranges.iter().enumerate() {
            let a = self.angle_min_rad + i as f64 * self.angle_increment_rad;
            let dir = [a.cos() as f32, a.sin() as f32, 0.0];
            out.extend(SensorRay::from_range(dir, d, &self.range, clear_no_return));
        }
    }
}

/// A planar LiDAR: each [`LaserScan`] carries its own geometry and range
/// limits, so the model has no parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PlanarLidar;

impl SensorModel for PlanarLidar {
    type Data = LaserScan;
    const NAME: &'static str = "planar";
    const KIND: &'static str = "planar LiDAR";
    const PROJECTS: bool = true;

    fn validate(&self) -> Result<(), CoreError> {
        Ok(())
    }

    fn check(&self, scan: &LaserScan) -> Result<(), CoreError> {
        scan.validate()
    }

    /// Unbounded: each scan carries its own.
    fn range(&self) -> RangeLimits {
        RangeLimits { min_m: 0.0, max_m: f32::MAX }
    }

    fn range_of(&self, scan: &LaserScan) -> RangeLimits {
        scan.range
    }

    fn rays(&self, scan: &LaserScan, clear_no_return: bool, out: &mut Vec<SensorRay>) {
        scan.rays(clear_no_return, out)
    }

    fn view<'a>(&'a self, scan: &'a LaserScan) -> Option<View<'a>> {
        Some(View::Sweep { scan })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beams_round_trip_both_directions() {
        for inc in [0.01f64, -0.01] {
            let scan = LaserScan {
                angle_min_rad: 1.0,
                angle_increment_rad: inc,
                ranges: vec![1.0; 600],
                range: RangeLimits { min_m: 0.1, max_m: 10.0 },
            };
            scan.validate().expect("valid");
            for i in (0..600).step_by(13) {
                let a = 1.0 + i as f64 * inc;
                assert_eq!(scan.beam([a.cos() as f32, a.sin() as f32, 0.0]), Some(i));
            }
            let behind = 1.0 + 300.0 * inc + std::f64::consts::PI;
            assert_eq!(scan.beam([behind.cos() as f32, behind.sin() as f32, 0.0]), None);
        }
    }
}
