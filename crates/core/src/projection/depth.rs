//! A depth camera's [`ProjectJob::is_miss_at`], and tiles decided whole
//! from the depths their pixels measured.
//!
//! A camera's voxel is a miss when it lies in front of the camera, projects
//! into the image, and its depth is below its pixel's
//! [`ProjectJob::free_below_m`]. [`DepthMiss`] keeps that threshold per
//! pixel (one subtraction per pixel and frame, not per voxel) and, for
//! blocks of pixels, its least and largest value in a pyramid. A tile's
//! bounding sphere ([`super::cull`]) covers a box of pixels; where every
//! point of the sphere is deeper than the largest threshold of the box, no
//! voxel of the tile is a miss, and where every point is in front of the
//! camera, inside the image and shallower than the least threshold, every
//! voxel is one. Only tiles that straddle a surface or an image edge are
//! decided voxel by voxel.
//!
//! The sphere holds each voxel centre as the definition rounds it, and the
//! pixel box is widened by a pixel plus a relative slack far above the
//! `f32` rounding of [`crate::sensor::PinholeCamera::project`], so a tile
//! decided whole is decided as the definition decides each of its voxels.

use super::cull::{norm, tile_centre};
use super::{ProjectJob, Tile, VoxelToSensor};
use crate::sensor::{DepthData, DepthImage, PinholeCamera, View};
use rayon::prelude::*;

/// Edge of the pyramid's finest cells, pixels.
const CELL_PX: usize = 8;
/// Each level's cells are this many of the level below along each axis.
const FAN: usize = 4;
/// A box is looked up on the finest level whose cells it spans at most
/// this many of along each axis.
const MAX_CELLS: usize = 4;
/// Relative slack on pixel coordinates and depths, for `f32` rounding
/// (some ten times the few units in the last place they err by).
const REL_SLACK: f64 = 1e-6;
/// How far beyond the pixels a sphere projects to its box reaches, pixels.
const PIXEL_MARGIN: f64 = 1.0;

/// One level of the pyramid: per cell, the least and largest threshold.
#[derive(Debug, Clone)]
struct Level {
    /// Edge of a cell, pixels.
    cell_px: usize,
    /// Cells along x.
    cols: usize,
    /// Per cell, row-major: (least, largest) threshold, metres.
    bounds: Vec<(f32, f32)>,
}

/// [`ProjectJob::is_miss_at`] of a depth camera's job, with its bounds.
#[derive(Debug, Clone)]
pub(super) struct DepthMiss<'a> {
    camera: &'a PinholeCamera,
    /// `fx`, `fy`, `cx`, `cy` as [`PinholeCamera::project`] rounds them.
    intrinsics: [f32; 4],
    /// Width and height, pixels.
    size: [f32; 2],
    /// Per pixel, [`ProjectJob::free_below_m`] of its depth, metres, and
    /// last `f32::MIN` for points outside the image.
    free_below_m: Vec<f32>,
    /// Finest level first; the last has one cell.
    levels: Vec<Level>,
}

impl<'a> DepthMiss<'a> {
    /// The decision for `job`, when it projects a depth image.
    pub(super) fn new(job: &ProjectJob<'a>) -> Option<Self> {
        let View::Pinhole { camera, image } = job.view else {
            return None;
        };
        let mut free_below_m = thresholds(job, camera, image);
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mut levels = vec![finest(&free_below_m, w, h)];
        // The threshold of "no pixel": nothing is below it.
        free_below_m.push(f32::MIN);
        while levels.last().is_some_and(|l| l.bounds.len() > 1) {
            let next = coarser(levels.last().expect("a level"), w, h);
            levels.push(next);
        }
        let intrinsics = [camera.fx, camera.fy, camera.cx, camera.cy].map(|v| v as f32);
        let size = [camera.width as f32, camera.height as f32];
        Some(DepthMiss { camera, intrinsics, size, free_below_m, levels })
    }

    /// The largest [`ProjectJob::free_below_m`] of the image, metres.
    pub(super) fn free_below_sup(&self) -> f32 {
        self.levels.last().map_or(f32::MIN, |l| l.bounds.iter().fold(f32::MIN, |m, b| m.max(b.1)))
    }

    /// [`ProjectJob::is_miss_at`]`(p)`: in front of the camera, in the
    /// image, below its pixel's threshold. The pixel is
    /// [`PinholeCamera::project`]'s, the same operations in the same order,
    /// with no branch: outside the image it is the last threshold, which
    /// nothing is below, so the loads of neighbouring voxels overlap.
    #[inline(always)]
    pub(super) fn is_miss_at(&self, p: [f32; 3]) -> bool {
        let [fx, fy, cx, cy] = self.intrinsics;
        let u = (fx * p[0] / p[2] + cx + 0.5).floor();
        let v = (fy * p[1] / p[2] + cy + 0.5).floor();
        let outside = (p[2] <= 0.0) | (u < 0.0) | (v < 0.0) | (u >= self.size[0]) | (v >= self.size[1]);
        // Wrapping: outside the image the casts saturate, and the index is not used.
        let pixel = (u as usize).wrapping_add((self.camera.width as usize).wrapping_mul(v as usize));
        let i = if outside { self.free_below_m.len() - 1 } else { pixel };
        p[2] < self.free_below_m[i]
    }

    /// What the voxels `lo..hi` (local coordinates, per axis) of a tile are.
    ///
    /// Their centres lie in a box in the camera frame: the tile's centre
    /// `c` plus `±a₀ ± a₁ ± a₂`, the rotated half extents, each widened by
    /// twice the `f32` rounding of a centre (a camera-aligned cube of that
    /// rounding around each centre fits). Depth is linear, so its range is
    /// `c.z ± Σ|aₖ.z|`; `x / z` is linear-fractional, so over the box (in
    /// front of the camera) it is extreme at the corners.
    pub(super) fn tile(&self, geom: &VoxelToSensor, lo: [usize; 3], hi: [usize; 3]) -> Tile {
        let (c, half) = tile_centre(geom, lo, hi);
        let slack = 2.0 * REL_SLACK * (norm(&c) + norm(&half));
        let axes = [0, 1, 2].map(|k| [0, 1, 2].map(|i| geom.rot[i][k] * (half[k] + slack)));
        let depth_reach: f64 = axes.iter().map(|a| a[2].abs()).sum();
        let (near, far) = (c[2] - depth_reach, c[2] + depth_reach);
        if near <= 0.0 {
            return Tile::Each;
        }
        let corners = (0..8).map(|m: usize| {
            [0, 1, 2]
                .map(|i| c[i] + (0..3).map(|k| if m >> k & 1 == 1 { axes[k][i] } else { -axes[k][i] }).sum::<f64>())
        });
        let mut ratio = [(f64::INFINITY, f64::NEG_INFINITY); 2];
        for p in corners {
            for (r, x) in ratio.iter_mut().zip([p[0], p[1]]) {
                *r = (r.0.min(x / p[2]), r.1.max(x / p[2]));
            }
        }
        let Some(((u0, u1), (v0, v1))) = self.pixel_box(ratio) else {
            return Tile::None;
        };
        let (w, h) = (self.camera.width as f64, self.camera.height as f64);
        let inside = u0 >= 0.0 && v0 >= 0.0 && u1 < w && v1 < h;
        let clamp = |a: f64, n: f64| a.clamp(0.0, n - 1.0) as usize;
        let (least, largest) = self.bounds((clamp(u0, w), clamp(u1, w)), (clamp(v0, h), clamp(v1, h)));
        if near >= largest as f64 * (1.0 + REL_SLACK) {
            Tile::None
        } else if inside && far * (1.0 + REL_SLACK) < least as f64 {
            Tile::All
        } else {
            Tile::Each
        }
    }

    /// The pixels (columns, rows; floored pixel coordinates, not clamped)
    /// that points with `x / z` and `y / z` in `ratio` project to, widened
    /// by the margins; `None` when the box misses the image.
    fn pixel_box(&self, ratio: [(f64, f64); 2]) -> Option<((f64, f64), (f64, f64))> {
        let cam = self.camera;
        let [fx, fy, cx, cy] = self.intrinsics.map(f64::from);
        let span = |(lo, hi): (f64, f64), f: f64, k: f64, n: u32| {
            let (lo, hi) = (lo * f + k + 0.5, hi * f + k + 0.5);
            let m = PIXEL_MARGIN + REL_SLACK * (lo.abs().max(hi.abs()) + k.abs() + 1.0);
            let (lo, hi) = ((lo - m).floor(), (hi + m).floor());
            (hi >= 0.0 && lo < n as f64).then_some((lo, hi))
        };
        Some((span(ratio[0], fx, cx, cam.width)?, span(ratio[1], fy, cy, cam.height)?))
    }

    /// The least and largest threshold over pixel columns `u0..=u1` and
    /// rows `v0..=v1` (or over a box holding them).
    fn bounds(&self, (u0, u1): (usize, usize), (v0, v1): (usize, usize)) -> (f32, f32) {
        let level = self
            .levels
            .iter()
            .find(|l| u1 / l.cell_px - u0 / l.cell_px < MAX_CELLS && v1 / l.cell_px - v0 / l.cell_px < MAX_CELLS)
            .unwrap_or_else(|| self.levels.last().expect("a level"));
        let s = level.cell_px;
        let mut out = (f32::INFINITY, f32::NEG_INFINITY);
        for row in v0 / s..=v1 / s {
            for &(lo, hi) in &level.bounds[row * level.cols + u0 / s..=row * level.cols + u1 / s] {
                out = (out.0.min(lo), out.1.max(hi));
            }
        }
        out
    }
}

/// Per pixel, [`ProjectJob::free_below_m`] of its depth.
fn thresholds(job: &ProjectJob<'_>, camera: &PinholeCamera, image: &DepthImage) -> Vec<f32> {
    let w = camera.width as usize;
    let n = w * camera.height as usize;
    // Room for the threshold of "no pixel" that [`DepthMiss::new`] appends.
    let mut out = Vec::with_capacity(n + 1);
    out.resize(n, 0.0);
    // [`ProjectJob::free_below_m`] with its conditions evaluated together,
    // not one after another, so that a row's pixels are done in vector
    // registers: the same values.
    let range = camera.range;
    let none = if job.clear_no_return { range.max_m } else { f32::MIN };
    let margin = job.free_margin_m;
    let free = move |d: f32, returned: bool| {
        let accepted = returned & d.is_finite() & (d > 0.0) & (d >= range.min_m) & (d <= range.max_m);
        if accepted {
            d - margin
        } else {
            none
        }
    };
    match &image.data {
        DepthData::Metres(d) => out.par_chunks_mut(w).zip(d.par_chunks(w)).for_each(|(t, d)| {
            vector_row(t, d, |t, d: &[f32]| t.iter_mut().zip(d).for_each(|(t, &d)| *t = free(d, true)));
        }),
        // As `crate::sensor::raw_depth_m`: 0 is no return, else the value
        // times the unit.
        DepthData::U16 { values, metres_per_unit } => {
            let unit = *metres_per_unit;
            out.par_chunks_mut(w).zip(values.par_chunks(w)).for_each(|(t, v)| {
                vector_row(t, v, |t, v: &[u16]| {
                    t.iter_mut().zip(v).for_each(|(t, &v)| *t = free(v as f32 * unit, v != 0))
                });
            })
        }
    }
    out
}

/// `f(out, row)`, compiled for AVX2 where the CPU has it: `f` is a loop
/// without branches over a row, the same values either way.
#[inline(always)]
fn vector_row<T, F: Fn(&mut [f32], &[T])>(out: &mut [f32], row: &[T], f: F) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        #[target_feature(enable = "avx2")]
        unsafe fn avx2<T, F: Fn(&mut [f32], &[T])>(out: &mut [f32], row: &[T], f: F) {
            f(out, row)
        }
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { avx2(out, row, f) };
    }
    f(out, row)
}

/// The finest level: cells of [`CELL_PX`]² pixels (fewer at the edges).
/// A band of [`CELL_PX`] rows at a time: the least and largest of each
/// column over the band's rows (element by element, in vector registers),
/// then of each cell's columns; the comparisons skip NaN as `f32::min` and
/// `f32::max` do.
fn finest(free_below_m: &[f32], w: usize, h: usize) -> Level {
    debug_assert_eq!(free_below_m.len(), w * h);
    let cols = w.div_ceil(CELL_PX);
    let least = |a: f32, b: f32| if b < a { b } else { a };
    let largest = |a: f32, b: f32| if b > a { b } else { a };
    let bounds = free_below_m
        .par_chunks(w * CELL_PX)
        .flat_map_iter(|band| {
            let (mut lo, mut hi) = (vec![f32::INFINITY; w], vec![f32::NEG_INFINITY; w]);
            for row in band.chunks(w) {
                for ((lo, hi), &t) in lo.iter_mut().zip(hi.iter_mut()).zip(row) {
                    *lo = least(*lo, t);
                    *hi = largest(*hi, t);
                }
            }
            let cells = lo.chunks(CELL_PX).zip(hi.chunks(CELL_PX));
            cells
                .map(move |(lo, hi)| {
                    (
                        lo.iter().fold(f32::INFINITY, |a, &b| least(a, b)),
                        hi.iter().fold(f32::NEG_INFINITY, |a, &b| largest(a, b)),
                    )
                })
                .collect::<Vec<_>>()
        })
        .collect();
    Level { cell_px: CELL_PX, cols, bounds }
}

/// The level above `below`: cells of [`FAN`]² of its cells.
fn coarser(below: &Level, w: usize, h: usize) -> Level {
    let cell_px = below.cell_px * FAN;
    let (cols, rows) = (w.div_ceil(cell_px), h.div_ceil(cell_px));
    let below_rows = below.bounds.len() / below.cols;
    let mut bounds = vec![(f32::INFINITY, f32::NEG_INFINITY); cols * rows];
    for r in 0..below_rows {
        for c in 0..below.cols {
            let (lo, hi) = below.bounds[r * below.cols + c];
            let out = &mut bounds[(r / FAN) * cols + c / FAN];
            *out = (out.0.min(lo), out.1.max(hi));
        }
    }
    Level { cell_px, cols, bounds }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::RangeLimits;
    use crate::{LocalVolume, VoxelIndex};
    use nalgebra::Isometry3;
    use proptest::prelude::*;
    use proptest::test_runner::RngSeed;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, rng_seed: RngSeed::Fixed(0xDE97), ..ProptestConfig::default() })]
        /// The threshold pyramid's bounds over a box hold every pixel's
        /// threshold in it, and the decision is the definition's.
        #[test]
        fn bounds_hold_the_box_and_decisions_are_the_definition(
            w in 1u32..150, h in 1u32..120,
            depths in proptest::collection::vec(prop_oneof![0.0f32..5.0, Just(f32::NAN), Just(0.0)], 150 * 120),
            corner in (0.0f64..1.0, 0.0f64..1.0), size in (0.0f64..1.0, 0.0f64..1.0),
            points in proptest::collection::vec(proptest::array::uniform3(-3.0f32..3.0), 64),
            clear_no_return in any::<bool>(),
        ) {
            let camera = PinholeCamera { fx: 0.8 * w as f64, fy: 0.8 * w as f64, cx: w as f64 / 2.0, cy: h as f64 / 2.0, width: w, height: h, range: RangeLimits { min_m: 0.1, max_m: 4.0 } };
            let n = (w * h) as usize;
            let image = DepthImage { width: w, height: h, data: DepthData::Metres(depths[..n].to_vec()) };
            let pose = Isometry3::identity();
            let job = ProjectJob {
                view: View::Pinhole { camera: &camera, image: &image }, t_world_sensor: &pose,
                volume: LocalVolume { origin: VoxelIndex([0; 3]), dims: [8; 3], voxel_size_m: 0.1 },
                free_margin_m: 0.07, clear_no_return, planar_half_thickness_m: 0.05,
            };
            let d = DepthMiss::new(&job).expect("a depth job");
            let (w, h) = (w as usize, h as usize);
            let u0 = (corner.0 * w as f64) as usize;
            let v0 = (corner.1 * h as f64) as usize;
            let u1 = (u0 + (size.0 * w as f64) as usize).min(w - 1);
            let v1 = (v0 + (size.1 * h as f64) as usize).min(h - 1);
            let (least, largest) = d.bounds((u0, u1), (v0, v1));
            for v in v0..=v1 {
                for u in u0..=u1 {
                    let t = job.free_below_m(image.depth_m(u + w * v), &camera.range);
                    prop_assert!(least <= t && t <= largest, "pixel ({u}, {v}): {t} outside {least}..{largest}");
                }
            }
            for p in points {
                prop_assert_eq!(d.is_miss_at(p), job.is_miss_at(p), "point {:?}", p);
            }
        }
    }
}
