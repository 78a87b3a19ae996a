//! What every sensor kind provides: [`SensorModel`], implemented once per
//! kind in its own file, and [`View`], the geometries projection decides
//! voxels in.
//!
//! A sensor kind is a model type (its intrinsics, ring table or range
//! limits) with its measurement type. The model checks its parameters and
//! its measurements, turns a measurement into rays for ray casting, and,
//! when volumetric projection can interpret it, shows the measurement as a
//! [`View`]: a pinhole depth image, a range image of rings, or a planar
//! sweep of beams. Projection (the per-voxel definition, the tile culling,
//! the host's fast paths and the GPU kernel) is written against the views,
//! not against sensor kinds, so a new kind whose measurements are one of
//! these geometries projects on every backend with nothing more than its
//! model. [`super::Sensor`] lists the kinds for configuration files, the
//! bindings and the command line, and hands each call to the kind's model.

use super::{classify, DepthImage};
use super::{norm, LaserScan, LidarScan, PinholeCamera, Projection, RangeLimits, SensorRay, SpinningLidar};
use crate::CoreError;

/// One sensor kind: its model's checks, rays and projection view.
pub trait SensorModel {
    /// The measurement this kind of sensor delivers.
    type Data;
    /// The kind's name as configuration files and the bindings spell it
    /// (`[sensor] kind`).
    const NAME: &'static str;
    /// The kind in words, for messages.
    const KIND: &'static str;
    /// Whether volumetric projection can interpret this kind's own
    /// measurements (its [`Self::view`] is `Some`).
    const PROJECTS: bool;

    /// Checks the model's parameters.
    fn validate(&self) -> Result<(), CoreError>;

    /// Checks that `m` is a valid measurement of this sensor.
    fn check(&self, m: &Self::Data) -> Result<(), CoreError>;

    /// The range of the sensor's valid returns.
    fn range(&self) -> RangeLimits;

    /// The range `m`'s returns are judged by: the sensor's, unless a
    /// measurement carries its own.
    fn range_of(&self, _m: &Self::Data) -> RangeLimits {
        self.range()
    }

    /// Appends every ray of a checked measurement, in the sensor frame.
    /// Rays with no return are included, reaching the maximum range, when
    /// `clear_no_return`.
    fn rays(&self, m: &Self::Data, clear_no_return: bool, out: &mut Vec<SensorRay>);

    /// Calls `f` with the points of every return of a checked measurement
    /// (sensor frame, metres), a batch at a time, from the host's threads
    /// in any order; by default through [`Self::rays`] (kept in `rays`).
    fn par_returns(&self, m: &Self::Data, rays: &mut Vec<SensorRay>, f: impl Fn(&ReturnBatch) + Sync) {
        use rayon::prelude::*;
        rays.clear();
        self.rays(m, false, rays);
        rays.par_chunks(RETURN_BATCH).with_min_len(16).for_each(|chunk| {
            let mut batch = ReturnBatch::new();
            for r in chunk.iter().filter(|r| r.hit) {
                batch.push(r.dir.map(|c| c as f64 * r.range_m as f64));
            }
            f(&batch);
        });
    }

    /// The measurement as projection sees it; `None` where projection
    /// cannot interpret it (ray casting only).
    fn view<'a>(&'a self, m: &'a Self::Data) -> Option<View<'a>>;
}

/// Most points a [`ReturnBatch`] holds.
pub const RETURN_BATCH: usize = 64;

/// The points of up to [`RETURN_BATCH`] returns (sensor frame, metres),
/// one array per coordinate so that a consumer transforms a batch in
/// vector registers. Points `0..len` are returns, except that a point
/// with a NaN coordinate is none (a pixel with no valid depth); entries
/// from `len` on are NaN.
#[derive(Debug, Clone)]
pub struct ReturnBatch {
    /// The points' x, y and z.
    pub xyz: [[f64; RETURN_BATCH]; 3],
    /// How many entries are filled.
    pub len: usize,
}

impl ReturnBatch {
    /// A batch of no points.
    pub fn new() -> Self {
        ReturnBatch { xyz: [[f64::NAN; RETURN_BATCH]; 3], len: 0 }
    }

    /// Appends `p`; the caller keeps to [`RETURN_BATCH`] points.
    #[inline]
    pub fn push(&mut self, p: [f64; 3]) {
        for (k, c) in p.into_iter().enumerate() {
            self.xyz[k][self.len] = c;
        }
        self.len += 1;
    }

    /// The points `0..len`, NaN ones included.
    pub fn points(&self) -> impl Iterator<Item = [f64; 3]> + '_ {
        (0..self.len).map(|i| self.xyz.map(|c| c[i]))
    }
}

impl Default for ReturnBatch {
    fn default() -> Self {
        Self::new()
    }
}

/// A measurement laid out in a geometry that volumetric projection decides
/// voxels in, with the sensor parameters that geometry needs.
#[derive(Debug, Clone, Copy)]
pub enum View<'a> {
    /// A depth image through a pinhole: a point's pixel is the nearest to
    /// its projection, its range is its depth.
    Pinhole {
        /// The intrinsics and range limits.
        camera: &'a PinholeCamera,
        /// The depths.
        image: &'a DepthImage,
    },
    /// A range image of rings at fixed elevations swept in azimuth: a
    /// point's beam is the nearest ring and bin, its range its distance,
    /// and a beam must pass within half a voxel of it.
    Rings {
        /// The ring table, bins and range limits.
        lidar: &'a SpinningLidar,
        /// The ranges, ring-major.
        scan: &'a LidarScan,
    },
    /// A planar sweep of beams: a point within the plane's thickness has
    /// the beam nearest its azimuth, its range its horizontal distance.
    Sweep {
        /// The beams' angles, ranges and range limits.
        scan: &'a LaserScan,
    },
}

impl View<'_> {
    /// Where point `p` (sensor frame) falls in the measurement.
    #[inline]
    pub fn project(&self, p: [f32; 3]) -> Projection {
        match *self {
            View::Pinhole { camera, image } => match camera.project(p) {
                None => Projection::Unseen,
                Some(i) => classify(p[2], image.depth_m(i), &camera.range),
            },
            View::Rings { lidar, scan } => match lidar.project(p) {
                None => Projection::Unseen,
                Some((r, b)) => classify(norm(p), scan.ranges[r * lidar.azimuth_bins + b], &lidar.range),
            },
            View::Sweep { scan } => match scan.beam(p) {
                None => Projection::Unseen,
                Some(i) => classify((p[0] * p[0] + p[1] * p[1]).sqrt(), scan.ranges[i], &scan.range),
            },
        }
    }

    /// Whether a point `p` is in the part of space the measurement
    /// observes across its beams: a planar sweep's within
    /// `half_thickness_m` of its plane, any other everywhere.
    #[inline]
    pub fn in_plane(&self, p: [f32; 3], half_thickness_m: f32) -> bool {
        !matches!(self, View::Sweep { .. }) || p[2].abs() <= half_thickness_m
    }

    /// Whether the beam nearest to the direction of `p` passes within
    /// `radius_m` of `p`. A LiDAR's rings are sparse: a voxel between two
    /// rings is crossed by no beam, and the nearest ring says nothing about
    /// it. Pixels and planar beams are dense enough to be taken as passing.
    #[inline]
    pub fn beam_passes_within(&self, p: [f32; 3], radius_m: f32) -> bool {
        match self {
            View::Rings { lidar, .. } => lidar.ring_passes_within(p, radius_m),
            _ => true,
        }
    }

    /// The range limits returns are judged by.
    pub fn range(&self) -> &RangeLimits {
        match self {
            View::Pinhole { camera, .. } => &camera.range,
            View::Rings { lidar, .. } => &lidar.range,
            View::Sweep { scan } => &scan.range,
        }
    }

    /// Calls `f` with every beam's or pixel's measured range, in the
    /// measurement's order (metres; depth for a camera).
    pub fn for_each_measured(&self, mut f: impl FnMut(f32)) {
        match self {
            View::Pinhole { image, .. } => {
                (0..image.width as usize * image.height as usize).for_each(|i| f(image.depth_m(i)))
            }
            View::Rings { scan, .. } => scan.ranges.iter().for_each(|&d| f(d)),
            View::Sweep { scan } => scan.ranges.iter().for_each(|&d| f(d)),
        }
    }
}
