//! Tiles of a projection's volume that provably hold no miss, skipped
//! before any of their voxels is decided.
//!
//! A depth camera sees a few percent of its window, a LiDAR's returns end
//! well inside theirs, a planar scan observes one slab. [`TileCull`] bounds
//! each tile (an 8³ observation cell) by a sphere in the sensor frame and
//! skips it only when no point of the sphere could pass one of the
//! necessary conditions of [`ProjectJob::is_miss_at`]:
//!
//! * the range (depth for cameras) below which a point is free, whatever
//!   beam or pixel it falls in: the largest [`ProjectJob::free_below_m`]
//!   over the measurement;
//! * a camera's image: in front of the camera and inside the four planes
//!   through its centre and the image's edges, widened by a pixel;
//! * a LiDAR's fan of rings ([`crate::sensor::SpinningLidar::fan_rad`]),
//!   and the largest free range of the azimuth bins the tile spans (a
//!   tile behind the walls its bins saw holds no miss);
//! * a planar scan's slab.
//!
//! The sphere holds every voxel centre of the tile as the decision sees it
//! (rounded to `f32`) with a voxel to spare, and every comparison keeps a
//! relative slack far above the `f32` rounding of the sensor models, so a
//! skipped voxel is one the definition rejects: the misses are the
//! definition's, bit for bit, and a tile that is not skipped is decided
//! voxel by voxel as before.

use super::{ProjectJob, VoxelToSensor};
use crate::sensor::{PinholeCamera, View};

/// Edge of a tile, voxels: an observation cell.
pub(super) const TILE: usize = 8;
/// Relative slack on lengths for `f32` rounding (of a voxel centre, of a
/// norm): some ten times the few units in the last place they err by.
pub(super) const REL_SLACK: f64 = 1e-6;
/// How far outside the image a pixel coordinate must be for a tile to be
/// skipped, pixels (its `f32` rounding errs by far less).
const PIXEL_MARGIN: f64 = 1.0;
/// How far outside a LiDAR's fan an elevation must be, radians (the
/// decision's elevation errs by an `f32` rounding, ~1e-7).
const FAN_MARGIN_RAD: f64 = 1e-6;
/// How far beyond a tile's azimuths a bin is still taken, radians (the
/// decision's azimuth errs by an `f32` rounding and an `atan2`, ~1e-7).
const AZIMUTH_MARGIN_RAD: f64 = 1e-6;
/// Intrinsics beyond which the frustum is not used (the margins above
/// assume moderate pixel coordinates).
const MAX_INTRINSIC: f64 = 1e6;

/// What a tile must satisfy to possibly hold a miss.
#[derive(Debug, Clone, Copy)]
enum Shape {
    /// A camera: in front of it (depth is the range), inside these planes
    /// (unit normals, `n · p ≥ 0` inside) when the intrinsics allow.
    Depth(Option<[[f64; 3]; 4]>),
    /// A LiDAR: the range is the norm, elevations within the fan, and the
    /// range below the largest free range of the azimuth bins spanned.
    Lidar { fan_rad: (f64, f64) },
    /// A planar scan: the range is horizontal, within the slab.
    Planar { half_thickness_m: f64 },
}

/// A job's tile test: [`Self::may_miss`].
#[derive(Debug, Clone, Copy)]
pub(super) struct TileCull<'a> {
    geom: VoxelToSensor,
    /// No point at this range or beyond is free, metres.
    free_below_m: f64,
    shape: Shape,
    /// A LiDAR's largest free range per azimuth bin, metres (bin `b` as
    /// [`crate::sensor::SpinningLidar::azimuth_bin`] numbers it).
    bin_free_below_m: &'a [f32],
}

impl<'a> TileCull<'a> {
    /// The test for `job`, or `None` when no voxel can be a miss (no
    /// return frees anything, or the sensor does not project this
    /// measurement). `bin_free_below_m`: a LiDAR's largest
    /// [`ProjectJob::free_below_m`] per azimuth bin, over its rings;
    /// `sup`: the largest over the measurement, where the caller has it.
    pub(super) fn new(
        job: &ProjectJob<'_>,
        geom: &VoxelToSensor,
        bin_free_below_m: &'a [f32],
        sup: Option<f32>,
    ) -> Option<Self> {
        let free_below_m = sup.unwrap_or_else(|| free_below_sup(job)) as f64;
        // Every range the definition compares is ≥ 0 (depth > 0); the
        // supremum is never NaN (`f32::max` drops NaN thresholds, which free
        // nothing).
        if free_below_m <= 0.0 {
            return None;
        }
        let shape = match job.view {
            View::Pinhole { camera, .. } => Shape::Depth(frustum(camera)),
            View::Rings { lidar, .. } => Shape::Lidar { fan_rad: lidar.fan_rad() },
            View::Sweep { .. } => Shape::Planar { half_thickness_m: job.planar_half_thickness_m as f64 },
        };
        Some(TileCull { geom: *geom, free_below_m, shape, bin_free_below_m })
    }

    /// Whether the voxels `lo..hi` (local coordinates, per axis) may hold a
    /// miss; `false` only when none can.
    pub(super) fn may_miss(&self, lo: [usize; 3], hi: [usize; 3]) -> bool {
        let (c, r) = self.sphere(lo, hi);
        let far = self.free_below_m * (1.0 + REL_SLACK);
        match self.shape {
            Shape::Depth(planes) => {
                let in_view = planes.is_none_or(|ps| ps.iter().all(|n| dot(n, &c) + r >= 0.0));
                c[2] + r > 0.0 && c[2] - r < self.free_below_m && in_view
            }
            Shape::Lidar { fan_rad } => {
                let near = norm(&c) - r;
                near < far && fan_overlaps(&c, r, fan_rad) && near < self.bins_free_below_m(&c, r) * (1.0 + REL_SLACK)
            }
            Shape::Planar { half_thickness_m } => c[0].hypot(c[1]) - r < far && c[2].abs() - r <= half_thickness_m,
        }
    }

    /// The largest free range of the azimuth bins that a point of the
    /// sphere `(c, r)` can fall in (every bin's when it holds the axis),
    /// metres. The sphere's azimuths lie within `asin(r / h)` of its
    /// centre's (`h` the centre's horizontal distance); the bins of that
    /// span widened by [`AZIMUTH_MARGIN_RAD`] and a bin on each side, taken
    /// around the ±π cut, hold every bin the definition can give.
    fn bins_free_below_m(&self, c: &[f64; 3], r: f64) -> f64 {
        let bins = self.bin_free_below_m.len();
        let h = c[0].hypot(c[1]);
        if bins == 0 || h <= r * (1.0 + REL_SLACK) {
            return self.free_below_m;
        }
        let spread = (r / h).asin() + AZIMUTH_MARGIN_RAD;
        let per_rad = bins as f64 / (2.0 * std::f64::consts::PI);
        let az = c[1].atan2(c[0]) + std::f64::consts::PI;
        let first = ((az - spread) * per_rad).floor() as i64 - 1;
        let last = ((az + spread) * per_rad).floor() as i64 + 1;
        if last - first + 1 >= bins as i64 {
            return self.free_below_m;
        }
        (first..=last).map(|b| self.bin_free_below_m[b.rem_euclid(bins as i64) as usize]).fold(f32::MIN, f32::max)
            as f64
    }

    /// A sphere in the sensor frame holding every voxel centre of
    /// `lo..hi` as [`VoxelToSensor::point`] rounds it: centre, radius.
    fn sphere(&self, lo: [usize; 3], hi: [usize; 3]) -> ([f64; 3], f64) {
        let (c, half) = tile_centre(&self.geom, lo, hi);
        let reach = norm(&half);
        (c, reach + self.geom.voxel_size_m + REL_SLACK * (norm(&c) + reach))
    }
}

/// The centre of the voxel centres `lo..hi` in the sensor frame, and their
/// half extents along the volume's axes, metres (before the rounding of
/// [`VoxelToSensor::point`]).
pub(super) fn tile_centre(geom: &VoxelToSensor, lo: [usize; 3], hi: [usize; 3]) -> ([f64; 3], [f64; 3]) {
    let s = geom.voxel_size_m;
    let mid = [0, 1, 2].map(|k| (lo[k] + hi[k]) as f64 * 0.5 * s - geom.origin_m[k]);
    let half = [0, 1, 2].map(|k| (hi[k] - lo[k] - 1) as f64 * 0.5 * s);
    (geom.rot.map(|row| dot(&row, &mid)), half)
}

/// The largest range below which [`ProjectJob::is_miss_at`] may call a
/// point free, over every beam or pixel of the measurement, metres;
/// `f32::MIN` when none frees anything.
fn free_below_sup(job: &ProjectJob<'_>) -> f32 {
    let mut sup = f32::MIN;
    job.view.for_each_measured(|d| sup = sup.max(job.free_below_m(d, job.view.range())));
    sup
}

/// The camera's four image planes, widened by [`PIXEL_MARGIN`], with the
/// intrinsics rounded to `f32` as [`PinholeCamera::project`] uses them;
/// `None` for intrinsics too large for the margin.
///
/// Pixel column `u ≥ 0` needs `fx x / z + cx + ½ ≥ 0`; a point with
/// `fx x + (cx + ½ + m) z < 0` and `z > 0` has it below `−m`, which `f32`
/// rounding (relative 2⁻²⁴ on each of four operations) cannot lift to 0.
/// Likewise `u < width`, and the rows.
fn frustum(c: &PinholeCamera) -> Option<[[f64; 3]; 4]> {
    let [fx, fy, cx, cy] = [c.fx, c.fy, c.cx, c.cy].map(|v| v as f32 as f64);
    let (w, h) = (c.width as f64, c.height as f64);
    if ![fx, fy, cx.abs(), cy.abs()].iter().all(|v| v.is_finite() && *v < MAX_INTRINSIC) {
        return None;
    }
    let m = PIXEL_MARGIN + REL_SLACK * (cx.abs() + cy.abs() + w + h + 1.0);
    let (bx, by) = (cx + 0.5, cy + 0.5);
    let planes = [[fx, 0.0, bx + m], [-fx, 0.0, w + m - bx], [0.0, fy, by + m], [0.0, -fy, h + m - by]];
    Some(planes.map(|n| {
        let l = norm(&n);
        n.map(|v| v / l)
    }))
}

/// Whether some point of the sphere `(c, r)` has an elevation within
/// `fan_rad` (widened by [`FAN_MARGIN_RAD`]).
fn fan_overlaps(c: &[f64; 3], r: f64, fan_rad: (f64, f64)) -> bool {
    let d = norm(c);
    if d <= r {
        return true;
    }
    let el = c[2].atan2(c[0].hypot(c[1]));
    let spread = (r / d).asin();
    el + spread >= fan_rad.0 - FAN_MARGIN_RAD && el - spread <= fan_rad.1 + FAN_MARGIN_RAD
}

#[inline]
fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub(super) fn norm(a: &[f64; 3]) -> f64 {
    dot(a, a).sqrt()
}
