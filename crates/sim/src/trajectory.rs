//! Sensor trajectories: closed planar paths of straight lines and circular
//! arcs, driven at constant speed, with a smooth height profile.
//!
//! Lines and arcs keep the heading continuous (the curvature jumps at the
//! joints, as a robot following waypoints would), and every position has a
//! closed form. Times past the end of a path wrap around it.

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use std::f64::consts::TAU;

/// A line (curvature 0) or an arc (curvature ±1/radius, positive = left).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Segment {
    start: [f64; 2],
    heading_rad: f64,
    length_m: f64,
    curvature: f64,
}

impl Segment {
    /// Position and heading `u` metres into the segment.
    fn at(&self, u: f64) -> ([f64; 2], f64) {
        let (h, k, [x, y]) = (self.heading_rad, self.curvature, self.start);
        let h1 = h + k * u;
        if k == 0.0 {
            return ([x + u * h.cos(), y + u * h.sin()], h);
        }
        ([x + (h1.sin() - h.sin()) / k, y - (h1.cos() - h.cos()) / k], h1)
    }
}

/// A planar path built by driving: straight lines and constant-radius turns.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Path {
    start: [f64; 2],
    heading_rad: f64,
    segments: Vec<Segment>,
    length_m: f64,
}

impl Path {
    /// An empty path at `start`, facing `heading_rad` (from x towards y).
    pub(crate) fn new(start: [f64; 2], heading_rad: f64) -> Path {
        Path { start, heading_rad, segments: Vec::new(), length_m: 0.0 }
    }

    /// A counter-clockwise rectangle `[min, min + size]` with corners
    /// rounded to `radius_m`, starting at the start of its bottom side.
    pub(crate) fn rounded_rect(min: [f64; 2], size: [f64; 2], radius_m: f64) -> Path {
        let (w, h) = (size[0] - 2.0 * radius_m, size[1] - 2.0 * radius_m);
        let mut p = Path::new([min[0] + radius_m, min[1]], 0.0);
        for side in [w, h, w, h] {
            p = p.straight(side).turn(radius_m, 90.0);
        }
        p
    }

    /// Where the path ends and its heading there.
    pub(crate) fn end(&self) -> ([f64; 2], f64) {
        match self.segments.last() {
            Some(s) => s.at(s.length_m),
            None => (self.start, self.heading_rad),
        }
    }

    /// Adds a straight line of `length_m`.
    pub(crate) fn straight(self, length_m: f64) -> Path {
        self.push(length_m, 0.0)
    }

    /// Adds a turn of `angle_deg` (positive = left) on a circle of `radius_m`.
    pub(crate) fn turn(self, radius_m: f64, angle_deg: f64) -> Path {
        let k = angle_deg.signum() / radius_m;
        self.push(radius_m * angle_deg.to_radians().abs(), k)
    }

    fn push(mut self, length_m: f64, curvature: f64) -> Path {
        let (start, heading_rad) = self.end();
        self.segments.push(Segment { start, heading_rad, length_m, curvature });
        self.length_m += length_m;
        self
    }

    /// Total length, metres.
    pub(crate) fn length_m(&self) -> f64 {
        self.length_m
    }

    /// Position and heading at arc length `s` (wrapped into the path).
    pub(crate) fn at(&self, s: f64) -> ([f64; 2], f64) {
        if self.length_m <= 0.0 {
            return (self.start, self.heading_rad);
        }
        let mut u = s.rem_euclid(self.length_m);
        for seg in &self.segments {
            if u <= seg.length_m {
                return seg.at(u);
            }
            u -= seg.length_m;
        }
        self.end()
    }

    /// The path moved by `(dx, dy)`.
    pub(crate) fn translated(mut self, d: [f64; 2]) -> Path {
        let add = |p: [f64; 2]| [p[0] + d[0], p[1] + d[1]];
        self.start = add(self.start);
        for s in &mut self.segments {
            s.start = add(s.start);
        }
        self
    }
}

/// Where the body's x axis points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Heading {
    /// Along the path, body level.
    AlongPath,
    /// At a fixed world point (yaw and pitch, no roll), as a hand-held camera.
    LookAt([f64; 3]),
}

/// A path driven at constant speed with height `base + amp·sin(2π·cycles·s/L)`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Route {
    /// The planar path.
    pub(crate) path: Path,
    /// Speed along the path, m/s.
    pub(crate) speed_mps: f64,
    /// Arc length at time 0, metres.
    pub(crate) start_s: f64,
    /// Mean height, metres.
    pub(crate) height_m: f64,
    /// Height oscillation amplitude, metres.
    pub(crate) bob_m: f64,
    /// Height oscillations per lap (an integer keeps the loop closed).
    pub(crate) bob_cycles: f64,
    /// Where the body looks.
    pub(crate) heading: Heading,
}

impl Route {
    /// Position at arc length `s` and the path heading there.
    pub(crate) fn position_at(&self, s: f64) -> ([f64; 3], f64) {
        let ([x, y], h) = self.path.at(s);
        let lap = self.path.length_m().max(f64::MIN_POSITIVE);
        let z = self.height_m + self.bob_m * (TAU * self.bob_cycles * s / lap).sin();
        ([x, y, z], h)
    }

    /// `T_world_body` at time `t_s`: x forward, y left, z up.
    pub(crate) fn pose(&self, t_s: f64) -> Isometry3<f64> {
        let (p, path_heading) = self.position_at(self.start_s + self.speed_mps * t_s);
        let (yaw, pitch) = match self.heading {
            Heading::AlongPath => (path_heading, 0.0),
            Heading::LookAt(q) => {
                let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
                (d[1].atan2(d[0]), (-d[2]).atan2(d[0].hypot(d[1])))
            }
        };
        let rotation = UnitQuaternion::from_euler_angles(0.0, pitch, yaw);
        Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), rotation)
    }

    /// Positions every `spacing_m` along one whole lap.
    pub(crate) fn samples(&self, spacing_m: f64) -> Vec<[f64; 3]> {
        let n = (self.path.length_m() / spacing_m).ceil().max(1.0) as usize;
        (0..=n).map(|i| self.position_at(i as f64 * self.path.length_m() / n as f64).0).collect()
    }

    /// The trajectory moved by `shift` metres.
    pub(crate) fn translated(mut self, shift: [f64; 3]) -> Route {
        self.path = self.path.translated([shift[0], shift[1]]);
        self.height_m += shift[2];
        if let Heading::LookAt(q) = &mut self.heading {
            *q = [0, 1, 2].map(|i| q[i] + shift[i]);
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounded_rect_closes_with_continuous_heading() {
        let p = Path::rounded_rect([1.0, 2.0], [10.0, 6.0], 1.5);
        let (end, h) = p.end();
        assert!((end[0] - 2.5).abs() < 1e-12 && (end[1] - 2.0).abs() < 1e-12, "{end:?}");
        assert!((h - TAU).abs() < 1e-12);
        let expected = 2.0 * (7.0 + 3.0) + TAU * 1.5;
        assert!((p.length_m() - expected).abs() < 1e-12);
        // Small steps move by their length: no jumps at the joints.
        let step = 0.01;
        for i in 0..(p.length_m() / step) as usize {
            let (a, ha) = p.at(i as f64 * step);
            let (b, hb) = p.at((i + 1) as f64 * step);
            let d = (b[0] - a[0]).hypot(b[1] - a[1]);
            assert!((d - step).abs() < 1e-4, "step {i}: {d}");
            assert!((hb - ha).rem_euclid(TAU) < 0.01, "heading jumps at step {i}");
        }
    }

    #[test]
    fn look_at_points_the_body_x_axis_at_the_target() {
        let t = Route {
            path: Path::new([1.0, 1.0], 0.0),
            speed_mps: 0.0,
            start_s: 0.0,
            height_m: 2.0,
            bob_m: 0.0,
            bob_cycles: 0.0,
            heading: Heading::LookAt([0.0, 0.0, 0.0]),
        };
        let pose = t.pose(3.0);
        let x = pose.rotation * nalgebra::Vector3::x();
        let want = nalgebra::Vector3::new(-1.0, -1.0, -2.0).normalize();
        assert!((x - want).norm() < 1e-12, "{x:?}");
        let y = pose.rotation * nalgebra::Vector3::y();
        assert!(y.z.abs() < 1e-12, "no roll");
    }
}
