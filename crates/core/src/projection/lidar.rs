//! A spinning LiDAR's [`ProjectJob::is_miss_at`], its necessary conditions
//! tested cheapest first.
//!
//! The definition projects every voxel (two `atan2`), then asks whether a
//! ring passes near it (a square root and an `asin`). Most voxels of a
//! window fail on range (behind the wall a beam hit) or fall between
//! rings, so [`LidarMiss`] tests the range first, against the farthest free
//! range of the whole scan, then (one `atan2`) of the voxel's azimuth bin,
//! then (the second) of its beam, and only then whether a ring passes near
//! it, with the elevation computed once for the ring and the ring test. Each step is the
//! definition's own function on the same `f32` point, so the answer is
//! the definition's bit for bit; only the order, and so the work, differs.

use super::ProjectJob;
use crate::sensor::{norm, LidarScan, Measurement, Sensor, SpinningLidar};

/// [`ProjectJob::is_miss_at`] of a LiDAR job, with its bounds.
#[derive(Debug, Clone)]
pub(super) struct LidarMiss<'a> {
    job: ProjectJob<'a>,
    lidar: &'a SpinningLidar,
    scan: &'a LidarScan,
    /// Per azimuth bin, the largest [`ProjectJob::free_below_m`] of its
    /// beams: a voxel behind the walls that bin saw costs one `atan2`.
    bin_free_below_m: Vec<f32>,
    /// The largest of `bin_free_below_m`.
    free_below_m: f32,
    /// The radius `is_miss_at` gives the ring test, metres.
    half_voxel_m: f32,
}

impl<'a> LidarMiss<'a> {
    /// The decision for `job`, when it projects a LiDAR range image.
    pub(super) fn new(job: &ProjectJob<'a>) -> Option<Self> {
        let (Sensor::Lidar(lidar), Measurement::Lidar(scan)) = (job.sensor, job.measurement) else {
            return None;
        };
        let mut bin_free_below_m = vec![f32::MIN; lidar.azimuth_bins];
        for ring in scan.ranges.chunks(lidar.azimuth_bins) {
            for (sup, &d) in bin_free_below_m.iter_mut().zip(ring) {
                *sup = sup.max(job.free_below_m(d, &lidar.range));
            }
        }
        let free_below_m = bin_free_below_m.iter().copied().fold(f32::MIN, f32::max);
        let half_voxel_m = (job.volume.voxel_size_m / 2.0) as f32;
        Some(LidarMiss { job: *job, lidar, scan, bin_free_below_m, free_below_m, half_voxel_m })
    }

    /// [`ProjectJob::is_miss_at`]`(p)`: free in its beam (range below the
    /// beam's [`ProjectJob::free_below_m`], which is what
    /// `ProjectJob::is_free` compares for a return and for no return), in
    /// the fan, near a ring.
    #[inline]
    pub(super) fn is_miss_at(&self, p: [f32; 3]) -> bool {
        // A NaN range passes these bounds and fails the beam's `<` below.
        let point_m = norm(p);
        if point_m >= self.free_below_m {
            return false;
        }
        let bin = self.lidar.azimuth_bin(p);
        if point_m >= self.bin_free_below_m[bin] {
            return false;
        }
        let (horiz, el) = SpinningLidar::elevation(p);
        let Some(ring) = self.lidar.nearest_ring(el) else {
            return false;
        };
        let measured_m = self.scan.ranges[ring * self.lidar.azimuth_bins + bin];
        point_m < self.job.free_below_m(measured_m, &self.lidar.range) && self.lidar.ring_passes_at(p, horiz, el, self.half_voxel_m)
    }
}
