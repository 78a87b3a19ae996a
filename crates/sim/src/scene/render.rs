//! Simulated measurements: one exact ray cast per pixel or beam, then the
//! per-ray noise of [`crate::noise`]. Rays run in parallel (rayon); the
//! result does not depend on the schedule.

use super::Scene;
use crate::geometry::Primitive;
use crate::noise::RayNoise;
use crate::SimError;
use edtmap_core::sensor::{
    DepthData, DepthImage, Frame, LaserScan, LidarScan, Measurement, PinholeCamera, PointCloud, RangeLimits, Sensor,
    SpinningLidar,
};
use nalgebra::{Isometry3, Matrix3, Vector3};
use rayon::prelude::*;
use std::f64::consts::{PI, TAU};

/// Beams of a simulated planar scan: 720 over a full turn (0.5°), the first
/// pointing backwards (−π) and sweeping counter-clockwise.
pub const PLANAR_BEAMS: usize = 720;
/// Valid range of a simulated planar scan, metres.
pub const PLANAR_RANGE: RangeLimits = RangeLimits { min_m: 0.1, max_m: 12.0 };
/// The most rays one simulated frame may cast.
const MAX_RAYS: usize = 1 << 26;

/// The beam pattern of simulated point clouds ([`Sensor::Points`]): 32 rings
/// evenly from −15° to +15°, 900 azimuth bins (0.4°), within `range`. Points
/// come ring by ring, bins in order, and beams with no return give no point.
pub fn points_pattern(range: RangeLimits) -> SpinningLidar {
    SpinningLidar::uniform(32, -15f64.to_radians(), 15f64.to_radians(), 900, range)
}

impl Scene {
    /// The measurement of `sensor` at frame `index` (time `index · period`),
    /// from [`Scene::sensor_pose`]. Depth images hold the optical z of the
    /// first surface along each pixel's ray ([`PinholeCamera::pixel_ray`]);
    /// LiDAR ranges are along each beam ([`SpinningLidar::direction`]).
    /// Returns outside the sensor's range limits, lost returns and rays
    /// with no surface are NaN (no point, for point clouds). Fails on an
    /// invalid sensor or one with more than 2²⁶ rays.
    pub fn frame(&self, sensor: &Sensor, index: usize) -> Result<Frame, SimError> {
        self.mounted_frame(sensor, &Isometry3::identity(), index)
    }

    /// [`Self::frame`] of a sensor mounted at `t_body_sensor`, from
    /// [`Scene::mounted_pose`].
    pub fn mounted_frame(
        &self,
        sensor: &Sensor,
        t_body_sensor: &Isometry3<f64>,
        index: usize,
    ) -> Result<Frame, SimError> {
        sensor.validate()?;
        check_ray_count(sensor)?;
        let t_s = index as f64 * self.frame_period_s;
        let t_world_sensor = self.mounted_pose(sensor, t_body_sensor, t_s);
        let o = &self.options;
        let noise = RayNoise::new(o.seed, index, o.range_noise_m, o.dropout);
        let caster = Caster::new(self.solids_at(t_s), &t_world_sensor, reach_m(sensor), noise);
        let measurement = match sensor {
            Sensor::Depth(c) => Measurement::Depth(caster.depth(c)),
            Sensor::Lidar(l) => Measurement::Lidar(LidarScan { ranges: caster.lidar(l) }),
            Sensor::Points(r) => Measurement::Points(caster.points(&points_pattern(*r))),
            Sensor::Planar => Measurement::Scan(caster.planar()),
        };
        Ok(Frame { stamp_s: t_s, t_world_sensor, measurement })
    }
}

fn check_ray_count(sensor: &Sensor) -> Result<(), SimError> {
    let rays = match sensor {
        Sensor::Depth(c) => c.width as u128 * c.height as u128,
        Sensor::Lidar(l) => l.ring_elevations_rad.len() as u128 * l.azimuth_bins as u128,
        Sensor::Points(_) => 32 * 900,
        Sensor::Planar => PLANAR_BEAMS as u128,
    };
    match rays <= MAX_RAYS as u128 {
        true => Ok(()),
        false => Err(SimError::TooManyRays { rays, limit: MAX_RAYS }),
    }
}

/// The farthest a ray of `sensor` can reach, metres.
fn reach_m(sensor: &Sensor) -> f64 {
    match sensor {
        Sensor::Depth(c) => {
            let corners = [(0, 0), (c.width - 1, 0), (0, c.height - 1), (c.width - 1, c.height - 1)];
            let stretch = corners.iter().map(|&(u, v)| norm(c.pixel_ray(u, v))).fold(1.0, f64::max);
            c.range.max_m as f64 * stretch
        }
        Sensor::Lidar(l) => l.range.max_m as f64,
        Sensor::Points(r) => r.max_m as f64,
        Sensor::Planar => PLANAR_RANGE.max_m as f64,
    }
}

fn candidate(solid: Primitive, origin: [f64; 3]) -> Candidate {
    let b = solid.bounds();
    let near_m = b.distance(origin);
    if b.min.iter().chain(&b.max).any(|v| !v.is_finite()) {
        return Candidate { solid, near_m, centre: [0.0; 3], radius_sq: f64::INFINITY };
    }
    let centre = [0, 1, 2].map(|a| 0.5 * (b.min[a] + b.max[a]) - origin[a]);
    let half = [0, 1, 2].map(|a| 0.5 * (b.max[a] - b.min[a]));
    let dist_sq = centre[0] * centre[0] + centre[1] * centre[1] + centre[2] * centre[2];
    // Widened past the rounding of `may_hit`, so it never culls a graze.
    let radius_sq = (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]) + 1e-9 * (1.0 + dist_sq);
    Candidate { solid, near_m, centre, radius_sq }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// A solid within reach, with what its culling tests need.
struct Candidate {
    solid: Primitive,
    /// Distance from the sensor to the solid's box, metres.
    near_m: f64,
    /// Centre of the box's bounding sphere relative to the sensor, and its
    /// squared radius (infinite for unbounded solids).
    centre: [f64; 3],
    radius_sq: f64,
}

impl Candidate {
    /// Whether the unit ray from the sensor along `d` may meet the
    /// bounding sphere (no divisions, unlike the exact test).
    #[inline]
    fn may_hit(&self, d: [f64; 3]) -> bool {
        let c = self.centre;
        let along = c[0] * d[0] + c[1] * d[1] + c[2] * d[2];
        let off_sq = c[0] * c[0] + c[1] * c[1] + c[2] * c[2] - along * along;
        off_sq <= self.radius_sq && (along >= 0.0 || along * along <= self.radius_sq)
    }
}

/// Casts sensor-frame rays into the solids within reach of one pose.
struct Caster {
    /// The solids within reach, nearest box first.
    solids: Vec<Candidate>,
    origin: [f64; 3],
    rotation: Matrix3<f64>,
    noise: RayNoise,
}

impl Caster {
    fn new(solids: Vec<Primitive>, pose: &Isometry3<f64>, reach_m: f64, noise: RayNoise) -> Caster {
        let origin: [f64; 3] = pose.translation.vector.into();
        let mut solids: Vec<Candidate> =
            solids.into_iter().map(|s| candidate(s, origin)).filter(|c| c.near_m <= reach_m).collect();
        solids.sort_by(|a, b| a.near_m.total_cmp(&b.near_m));
        Caster { solids, origin, rotation: pose.rotation.to_rotation_matrix().into_inner(), noise }
    }

    /// Exact distance along the unit sensor-frame direction `dir`, if a
    /// surface is within `max_m`.
    fn cast(&self, dir: [f64; 3], max_m: f64) -> Option<f64> {
        let d: [f64; 3] = (self.rotation * Vector3::from(dir)).into();
        let mut best = max_m;
        let mut hit = None;
        for c in &self.solids {
            if c.near_m > best {
                // Every later solid is farther than the hit so far.
                break;
            }
            if !c.may_hit(d) {
                continue;
            }
            if let Some(t) = c.solid.ray_hit(self.origin, d, best) {
                (best, hit) = (t, Some(t));
            }
        }
        hit
    }

    /// Ray `ray`'s measured value: noisy, NaN when lost or out of `limits`.
    fn measure(&self, ray: usize, value: Option<f64>, limits: &RangeLimits) -> f32 {
        let Some(v) = value else { return f32::NAN };
        let m = self.noise.apply(ray, v) as f32;
        if limits.accepts(m) {
            m
        } else {
            f32::NAN
        }
    }

    fn depth(&self, c: &PinholeCamera) -> DepthImage {
        let w = c.width as usize;
        let max_depth = c.range.max_m as f64;
        let depths = (0..w * c.height as usize)
            .into_par_iter()
            .map(|i| {
                let ray = c.pixel_ray((i % w) as u32, (i / w) as u32);
                let n = norm(ray);
                // Depth is range over the ray's stretch n (its z is 1).
                let depth = self.cast(ray.map(|r| r / n), max_depth * n).map(|t| t / n);
                self.measure(i, depth, &c.range)
            })
            .collect();
        DepthImage { width: c.width, height: c.height, data: DepthData::Metres(depths) }
    }

    fn lidar(&self, l: &SpinningLidar) -> Vec<f32> {
        let bins = l.azimuth_bins;
        (0..l.ring_elevations_rad.len() * bins)
            .into_par_iter()
            .map(|i| self.measure(i, self.cast(l.direction(i / bins, i % bins), l.range.max_m as f64), &l.range))
            .collect()
    }

    fn points(&self, pattern: &SpinningLidar) -> PointCloud {
        let bins = pattern.azimuth_bins;
        let ranges = self.lidar(pattern);
        let points = ranges
            .iter()
            .enumerate()
            .filter(|(_, r)| r.is_finite())
            .map(|(i, &r)| pattern.direction(i / bins, i % bins).map(|c| c as f32 * r))
            .collect();
        PointCloud { points }
    }

    fn planar(&self) -> LaserScan {
        let increment = TAU / PLANAR_BEAMS as f64;
        let ranges = (0..PLANAR_BEAMS)
            .into_par_iter()
            .map(|i| {
                let a = -PI + i as f64 * increment;
                self.measure(i, self.cast([a.cos(), a.sin(), 0.0], PLANAR_RANGE.max_m as f64), &PLANAR_RANGE)
            })
            .collect();
        LaserScan { angle_min_rad: -PI, angle_increment_rad: increment, ranges, range: PLANAR_RANGE }
    }
}
