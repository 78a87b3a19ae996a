//! Volumetric projection's decision for one voxel, shared by every backend.
//!
//! Projection (paper §IV-A) asks, for every voxel of the local volume,
//! whether the measurement shows it as free space (a *miss*). Floats cannot
//! be made bit-identical across devices (a GPU's division is not correctly
//! rounded, drivers may fuse multiply-adds), so the decision is defined
//! once, here, as a pure function of the job and the voxel's coordinates
//! ([`ProjectJob::is_miss`]): no state carried along a row, so no rounding
//! that depends on the loop. The voxel centre is taken relative to the
//! volume's lowest corner and the sensor origin relative to that corner, in
//! `f64` (small numbers, whatever the map's extent), rotated into the
//! sensor frame and rounded to `f32` for the sensor model.
//!
//! A backend that projects with its own floats (the GPU's `project.wgsl`)
//! decides only the voxels whose quantities lie safely away from every
//! threshold and marks the others [`PROJ_UNCERTAIN`]; the host decides
//! those with this function, so the result is this function's, bit for bit.

mod cull;
mod depth;
mod lidar;
mod planar;

use crate::sensor::{Projection, RangeLimits, View};
use crate::{LocalVolume, Observations, OBS_MISS};
use cull::{TileCull, TILE};
use depth::DepthMiss;
use lidar::LidarMiss;
use nalgebra::Isometry3;
use planar::{PlanarMiss, Span};
use rayon::prelude::*;

/// [`crate::Backend::project_volume`]'s byte for a voxel that is not a miss.
pub const PROJ_NOT_MISS: u8 = 0;
/// [`crate::Backend::project_volume`]'s byte for a miss (equal to
/// [`crate::OBS_MISS`]).
pub const PROJ_MISS: u8 = crate::OBS_MISS;
/// [`crate::Backend::project_volume`]'s byte for a voxel the backend could
/// not decide with certainty: the host decides it with
/// [`ProjectJob::is_miss`].
pub const PROJ_UNCERTAIN: u8 = 2;

/// One frame's volumetric projection, as [`crate::Backend::project_volume`]
/// receives it: everything the per-voxel decision depends on.
#[derive(Debug, Clone, Copy)]
pub struct ProjectJob<'a> {
    /// The measurement as projection sees it, with its sensor's
    /// parameters ([`crate::sensor::SensorModel::view`]).
    pub view: View<'a>,
    /// Pose of the sensor in the world, `T_world_sensor`.
    pub t_world_sensor: &'a Isometry3<f64>,
    /// The local volume whose voxels are decided.
    pub volume: LocalVolume,
    /// A voxel is free only if it lies more than this in front of the
    /// return, metres.
    pub free_margin_m: f32,
    /// Whether a beam with no return clears space up to the maximum range.
    pub clear_no_return: bool,
    /// Planar scans: voxels within this height of the scan plane are
    /// observed, metres.
    pub planar_half_thickness_m: f32,
}

/// The transform of voxel centres into the sensor frame, in volume-local
/// `f64` coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelToSensor {
    /// Rotation sensor ← world, row-major.
    pub rot: [[f64; 3]; 3],
    /// The sensor's origin relative to the volume's lowest corner, metres.
    pub origin_m: [f64; 3],
    /// Voxel edge length, metres.
    pub voxel_size_m: f64,
}

impl VoxelToSensor {
    /// The transform for a sensor at `t_world_sensor` over `volume`.
    pub fn new(t_world_sensor: &Isometry3<f64>, volume: &LocalVolume) -> Self {
        let m = t_world_sensor.rotation.inverse().to_rotation_matrix().into_inner();
        let corner = volume.min_corner_m();
        let t = t_world_sensor.translation.vector;
        VoxelToSensor {
            rot: [0, 1, 2].map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)]]),
            origin_m: [0, 1, 2].map(|k| t[k] - corner[k]),
            voxel_size_m: volume.voxel_size_m,
        }
    }

    /// The centre of voxel `c` (local coordinates) in the sensor frame,
    /// metres: `R ((c + ½) s − o)` in `f64`, rounded to `f32`. Each row of
    /// the product is `r₀ d₀ + (r₁ d₁ + r₂ d₂)`, so that a loop along x can
    /// take the bracket from [`Self::row`] and still give these bits.
    #[inline]
    pub fn point(&self, c: [usize; 3]) -> [f32; 3] {
        self.point_in_row(&self.row(c[1], c[2]), c[0])
    }

    /// The part of [`Self::point`] shared by the voxels of row `(y, z)`.
    #[inline]
    pub fn row(&self, y: usize, z: usize) -> [f64; 3] {
        let s = self.voxel_size_m;
        let dy = (y as f64 + 0.5) * s - self.origin_m[1];
        let dz = (z as f64 + 0.5) * s - self.origin_m[2];
        self.rot.map(|r| r[1] * dy + r[2] * dz)
    }

    /// [`Self::point`] of voxel `x` of the row whose [`Self::row`] is `row`.
    #[inline]
    pub fn point_in_row(&self, row: &[f64; 3], x: usize) -> [f32; 3] {
        let dx = (x as f64 + 0.5) * self.voxel_size_m - self.origin_m[0];
        [0, 1, 2].map(|i| (self.rot[i][0] * dx + row[i]) as f32)
    }
}

impl ProjectJob<'_> {
    /// The transform of this job's voxel centres into the sensor frame.
    pub fn voxel_to_sensor(&self) -> VoxelToSensor {
        VoxelToSensor::new(self.t_world_sensor, &self.volume)
    }

    /// Whether voxel `c` (local coordinates) is a miss: its centre `p` (see
    /// [`VoxelToSensor::point`]) is within the planar scan's thickness (planar
    /// scans only), the beam or pixel it projects to returns more than
    /// `free_margin_m` beyond it (or has no return, with
    /// `clear_no_return`, and `p` is within the maximum range), and a beam
    /// passes within half a voxel of it.
    #[inline]
    pub fn is_miss(&self, geom: &VoxelToSensor, c: [usize; 3]) -> bool {
        self.is_miss_at(geom.point(c))
    }

    /// [`Self::is_miss`] of the voxel whose centre in the sensor frame is
    /// `p` ([`VoxelToSensor::point`]).
    #[inline]
    pub fn is_miss_at(&self, p: [f32; 3]) -> bool {
        let half_voxel = (self.volume.voxel_size_m / 2.0) as f32;
        self.view.in_plane(p, self.planar_half_thickness_m)
            && self.is_free(self.view.project(p))
            && self.view.beam_passes_within(p, half_voxel)
    }

    /// The range below which a point projecting to a beam or pixel that
    /// measured `measured_m` (valid within `range`) is free, compared with
    /// `<`, as [`Self::is_miss`] decides it; `f32::MIN` where nothing is.
    #[inline]
    pub fn free_below_m(&self, measured_m: f32, range: &RangeLimits) -> f32 {
        if range.accepts(measured_m) {
            measured_m - self.free_margin_m
        } else if self.clear_no_return {
            range.max_m
        } else {
            f32::MIN
        }
    }

    #[inline]
    fn is_free(&self, p: Projection) -> bool {
        match p {
            Projection::Return { point_m, measured_m } => point_m < measured_m - self.free_margin_m,
            Projection::NoReturn { point_m, max_m } => self.clear_no_return && point_m < max_m,
            Projection::Unseen => false,
        }
    }
}

/// Marks every voxel of `obs`'s volume that `job` shows as free a miss, on
/// the host's cores: the CPU backend's projection, and the reference a
/// device falls back on where its kernel does not apply (a LiDAR's rings).
///
/// The volume is visited in 8³ tiles; a tile that provably holds no miss
/// ([`cull`]) is skipped, the others decided voxel by voxel with
/// [`ProjectJob::is_miss_at`] (a LiDAR's with the same conditions in a
/// cheaper order, [`lidar`]; a camera's against per-pixel thresholds,
/// [`depth`], which also decides whole tiles from the depths their pixels
/// measured; a planar scan's against per-beam thresholds, its beam found
/// without `atan2`, which also decides whole tiles from the thresholds of
/// the beams they span, [`planar`]). The misses are exactly the
/// definition's.
///
/// Each tile is marked by one thread with [`Observations::mark_alone`]:
/// nothing else may mark `obs` while this runs.
pub fn mark_misses(obs: &Observations, job: &ProjectJob<'_>) {
    let geom = job.voxel_to_sensor();
    let lidar = LidarMiss::new(job);
    let bin_free_below_m = lidar.as_ref().map_or(&[][..], |l| l.bin_free_below_m());
    let depth = DepthMiss::new(job);
    let planar = PlanarMiss::new(job);
    let decide = match (&lidar, &depth, &planar) {
        (Some(l), _, _) => Decide::Lidar(l),
        (None, Some(d), _) => Decide::Depth(d),
        (None, None, Some(p)) => Decide::Planar(p, Span::ANY),
        (None, None, None) => Decide::Definition(job),
    };
    let sup = match &decide {
        Decide::Lidar(l) => Some(l.free_below_sup()),
        Decide::Depth(d) => Some(d.free_below_sup()),
        Decide::Planar(p, _) => Some(p.free_below_sup()),
        Decide::Definition(_) => None,
    };
    let Some(cull) = TileCull::new(job, &geom, bin_free_below_m, sup) else {
        return;
    };
    let tiles = job.volume.dims.map(|n| n.div_ceil(TILE));
    (0..tiles[0] * tiles[1] * tiles[2]).into_par_iter().for_each(|t| {
        let at = [t % tiles[0], (t / tiles[0]) % tiles[1], t / (tiles[0] * tiles[1])];
        let lo = at.map(|a| a * TILE);
        let hi = [0, 1, 2].map(|k| (lo[k] + TILE).min(job.volume.dims[k]));
        if !cull.may_miss(lo, hi) {
            return;
        }
        match &decide {
            Decide::Depth(d) => mark_depth_tile(obs, &geom, d, lo, hi, TILE),
            Decide::Planar(p, _) => mark_planar_tile(obs, &geom, p, lo, hi, TILE),
            _ => mark_tile(obs, &geom, &decide, lo, hi),
        }
    });
}

/// Smallest edge [`mark_depth_tile`] splits a tile down to, voxels: below
/// it, deciding a part whole costs about as much as its voxels.
const SUBTILE: usize = 4;

/// A camera's tile `lo..hi` (edge `edge`): decided whole where its pixels'
/// depths allow, else in halves along each axis down to [`SUBTILE`], else
/// voxel by voxel.
fn mark_depth_tile(
    obs: &Observations,
    geom: &VoxelToSensor,
    d: &DepthMiss<'_>,
    lo: [usize; 3],
    hi: [usize; 3],
    edge: usize,
) {
    match d.tile(geom, lo, hi) {
        Tile::None => {}
        Tile::All => mark_all(obs, lo, hi),
        Tile::Each if edge > SUBTILE => {
            for (sub_lo, sub_hi) in halves(lo, hi, edge / 2, 3) {
                mark_depth_tile(obs, geom, d, sub_lo, sub_hi, edge / 2);
            }
        }
        Tile::Each => mark_tile(obs, geom, &Decide::Depth(d), lo, hi),
    }
}

/// The non-empty parts of the box `lo..hi` cut at `half` from `lo` along
/// its first `axes` axes (the others whole): 2^`axes` parts at most.
fn halves(lo: [usize; 3], hi: [usize; 3], half: usize, axes: usize) -> impl Iterator<Item = ([usize; 3], [usize; 3])> {
    (0..1usize << axes).filter_map(move |part| {
        let cut = |k: usize| k < axes;
        let sub_lo = [0, 1, 2].map(|k| lo[k] + if cut(k) && part >> k & 1 == 1 { half } else { 0 });
        let sub_hi = [0, 1, 2].map(|k| if cut(k) { (sub_lo[k] + half).min(hi[k]) } else { hi[k] });
        (0..3).all(|k| sub_lo[k] < sub_hi[k]).then_some((sub_lo, sub_hi))
    })
}

/// What a tile's voxels are, decided whole from a sphere around them
/// (a camera's pixels, a planar scan's beams).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tile {
    /// No voxel is a miss.
    None,
    /// Every voxel is a miss (a planar scan's: every voxel in its slab).
    All,
    /// Decide voxel by voxel.
    Each,
}

// [`mark_tile`] keeps a row's decisions in the bits of a `u32`.
const _: () = assert!(TILE <= 32);

/// How [`mark_tile`] decides a voxel.
enum Decide<'a, 'j> {
    /// A LiDAR's reordered conditions.
    Lidar(&'a LidarMiss<'j>),
    /// A camera's per-pixel thresholds.
    Depth(&'a DepthMiss<'j>),
    /// A planar scan's per-beam thresholds, and what a tile's beams bound.
    Planar(&'a PlanarMiss<'j>, Span),
    /// [`ProjectJob::is_miss_at`] itself.
    Definition(&'a ProjectJob<'j>),
}

/// Marks every voxel of `lo..hi` a miss.
fn mark_all(obs: &Observations, lo: [usize; 3], hi: [usize; 3]) {
    let [nx, ny, _] = obs.volume().dims;
    for z in lo[2]..hi[2] {
        for y in lo[1]..hi[1] {
            for x in lo[0]..hi[0] {
                obs.mark_alone([x, y, z], x + nx * (y + ny * z), OBS_MISS);
            }
        }
    }
}

/// A planar scan's tile `lo..hi` (edge `edge` across the scan): decided
/// whole where its beams' thresholds allow, else in quarters across the
/// scan down to [`SUBTILE`], else voxel by voxel.
fn mark_planar_tile(
    obs: &Observations,
    geom: &VoxelToSensor,
    p: &PlanarMiss<'_>,
    lo: [usize; 3],
    hi: [usize; 3],
    edge: usize,
) {
    let (tile, span) = p.tile(geom, lo, hi);
    match tile {
        Tile::None => {}
        Tile::All => mark_slab(obs, geom, p, lo, hi),
        Tile::Each if edge > SUBTILE => {
            for (sub_lo, sub_hi) in halves(lo, hi, edge / 2, 2) {
                mark_planar_tile(obs, geom, p, sub_lo, sub_hi, edge / 2);
            }
        }
        Tile::Each => mark_tile(obs, geom, &Decide::Planar(p, span), lo, hi),
    }
}

/// Marks the voxels `lo..hi` that lie in a planar scan's slab: a tile
/// whose every voxel there is a miss.
fn mark_slab(obs: &Observations, geom: &VoxelToSensor, p: &PlanarMiss<'_>, lo: [usize; 3], hi: [usize; 3]) {
    let [nx, ny, _] = obs.volume().dims;
    for z in lo[2]..hi[2] {
        for y in lo[1]..hi[1] {
            let shared = geom.row(y, z);
            let all = match p.row_in_slab(geom, &shared, lo[0], hi[0]) {
                Some(false) => continue,
                Some(true) => true,
                None => false,
            };
            for x in lo[0]..hi[0] {
                if all || p.in_slab(geom.point_in_row(&shared, x)) {
                    obs.mark_alone([x, y, z], x + nx * (y + ny * z), OBS_MISS);
                }
            }
        }
    }
}

/// [`mark_misses`] over the voxels `lo..hi` of one tile, compiled for AVX2
/// where the CPU has it: a row's decisions then run eight voxels at a time
/// and round down in a vector instruction, with the same results.
fn mark_tile(obs: &Observations, geom: &VoxelToSensor, decide: &Decide<'_, '_>, lo: [usize; 3], hi: [usize; 3]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { mark_tile_avx2(obs, geom, decide, lo, hi) };
    }
    mark_tile_voxels(obs, geom, decide, lo, hi)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn mark_tile_avx2(
    obs: &Observations,
    geom: &VoxelToSensor,
    decide: &Decide<'_, '_>,
    lo: [usize; 3],
    hi: [usize; 3],
) {
    mark_tile_voxels(obs, geom, decide, lo, hi)
}

#[inline(always)]
fn mark_tile_voxels(obs: &Observations, geom: &VoxelToSensor, decide: &Decide<'_, '_>, lo: [usize; 3], hi: [usize; 3]) {
    let [nx, ny, _] = obs.volume().dims;
    for z in lo[2]..hi[2] {
        for y in lo[1]..hi[1] {
            let shared = geom.row(y, z);
            if let Decide::Planar(p, _) = decide {
                if p.row_in_slab(geom, &shared, lo[0], hi[0]) == Some(false) {
                    continue;
                }
            }
            let mut ring_hint = 0;
            // A row's decisions first, its marks after: a camera's
            // decisions have no branch, so their loads overlap.
            let mut misses = 0u32;
            for x in lo[0]..hi[0] {
                let p = geom.point_in_row(&shared, x);
                let miss = match decide {
                    Decide::Lidar(l) => l.is_miss_at(p, &mut ring_hint),
                    Decide::Depth(d) => d.is_miss_at(p),
                    Decide::Planar(s, span) => s.is_miss_in(p, *span),
                    Decide::Definition(job) => job.is_miss_at(p),
                };
                misses |= u32::from(miss) << (x - lo[0]);
            }
            while misses != 0 {
                let x = lo[0] + misses.trailing_zeros() as usize;
                misses &= misses - 1;
                obs.mark_alone([x, y, z], x + nx * (y + ny * z), OBS_MISS);
            }
        }
    }
}

/// Decides every voxel a backend left [`PROJ_UNCERTAIN`] in `bits` (one
/// byte per voxel of `job.volume`) with [`ProjectJob::is_miss`], leaving
/// only `OBS_MISS` or nothing; returns how many there were.
pub fn decide_uncertain(job: &ProjectJob<'_>, bits: &mut [u8]) -> usize {
    let geom = job.voxel_to_sensor();
    let [nx, ny, _] = job.volume.dims;
    bits.par_chunks_mut(nx)
        .enumerate()
        .map(|(row, line)| {
            let (y, z) = (row % ny, row / ny);
            let mut n = 0;
            for (x, b) in line.iter_mut().enumerate().filter(|(_, b)| **b == PROJ_UNCERTAIN) {
                *b = if job.is_miss(&geom, [x, y, z]) { OBS_MISS } else { 0 };
                n += 1;
            }
            n
        })
        .sum()
}
