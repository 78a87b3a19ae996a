//! Walking pedestrians: vertical cylinders pacing along a segment.

use crate::geometry::Cylinder;
use std::f64::consts::PI;

/// A pedestrian walking back and forth between two points. The position
/// along the segment is `(1 − cos(ωt + φ))/2`, smooth in time, with
/// `ω = π·speed/length` so the mean speed over a walk is `mean_speed_mps`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Pedestrian {
    /// One end of the walk (x, y), metres.
    pub(crate) from: [f64; 2],
    /// The other end, metres.
    pub(crate) to: [f64; 2],
    /// Mean walking speed, m/s.
    pub(crate) mean_speed_mps: f64,
    /// Phase at time 0, radians (0 = at `from`).
    pub(crate) phase_rad: f64,
    /// Body radius, metres.
    pub(crate) radius_m: f64,
    /// Height of the feet, metres.
    pub(crate) floor_m: f64,
    /// Body height, metres.
    pub(crate) height_m: f64,
}

impl Pedestrian {
    /// The pedestrian's body at time `t_s`.
    pub(crate) fn at(&self, t_s: f64) -> Cylinder {
        let d = [self.to[0] - self.from[0], self.to[1] - self.from[1]];
        let len = d[0].hypot(d[1]);
        let f =
            if len > 0.0 { 0.5 * (1.0 - (PI * self.mean_speed_mps / len * t_s + self.phase_rad).cos()) } else { 0.0 };
        Cylinder {
            centre_xy: [self.from[0] + f * d[0], self.from[1] + f * d[1]],
            radius_m: self.radius_m,
            z_min: self.floor_m,
            z_max: self.floor_m + self.height_m,
        }
    }

    /// The pedestrian moved by `shift` metres.
    pub(crate) fn translated(mut self, shift: [f64; 3]) -> Pedestrian {
        self.from = [self.from[0] + shift[0], self.from[1] + shift[1]];
        self.to = [self.to[0] + shift[0], self.to[1] + shift[1]];
        self.floor_m += shift[2];
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn walks_between_the_ends_at_the_mean_speed() {
        let p = Pedestrian {
            from: [0.0, 0.0],
            to: [6.0, 0.0],
            mean_speed_mps: 1.2,
            phase_rad: 0.0,
            radius_m: 0.25,
            floor_m: 0.0,
            height_m: 1.7,
        };
        assert_eq!(p.at(0.0).centre_xy, [0.0, 0.0]);
        let there = p.at(5.0).centre_xy;
        assert!((there[0] - 6.0).abs() < 1e-12, "6 m at 1.2 m/s takes 5 s: {there:?}");
        let back = p.at(10.0).centre_xy;
        assert!(back[0].abs() < 1e-12);
    }
}
