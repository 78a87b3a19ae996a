//! A planar scan's [`ProjectJob::is_miss_at`] with the beam found without
//! `atan2`.
//!
//! The definition finds a voxel's beam from `atan2` of its direction and a
//! floored remainder ([`LaserScan::beam`]), then compares its horizontal
//! range with the beam's free range. [`PlanarMiss`] keeps each beam's
//! threshold ([`ProjectJob::free_below_m`]) and guesses the beam from a
//! table arctangent good to some 1e-7 rad; where that guess puts the
//! voxel's position in the sweep within a margin of a beam boundary (or of
//! the sweep's ends), the definition's own functions decide it. Elsewhere
//! the guessed position rounds to the same beam as the exact one, so the
//! answer is the definition's bit for bit.

use super::cull::{norm, tile_centre, REL_SLACK};
use super::lidar::{fast_atan2, ATAN};
use super::{ProjectJob, Tile, VoxelToSensor};
use crate::sensor::{LaserScan, View};
use std::f64::consts::TAU;

/// The most beams a tile's thresholds are read over; a tile whose
/// azimuths reach more (near the scanner) is decided voxel by voxel.
const TILE_BEAMS: usize = 64;

/// The thresholds of the beams a tile's voxels can fall in: a voxel in the
/// slab nearer than `least` is a miss, one as far as `largest` is not
/// (the comparison [`PlanarMiss::is_miss_at`] makes with its beam's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Span {
    /// The least threshold, `f32::MIN` where some azimuth has no beam.
    least: f32,
    /// The largest threshold.
    largest: f32,
}

impl Span {
    /// Any beam: nothing known.
    pub(super) const ANY: Span = Span { least: f32::MIN, largest: f32::INFINITY };
}

/// Error of [`fast_atan2`]'s angle, radians, with room to spare (it
/// guesses within 1e-7).
const ANGLE_ERROR_RAD: f64 = 2e-7;

/// [`ProjectJob::is_miss_at`] of a planar scan's job.
#[derive(Debug, Clone)]
pub(super) struct PlanarMiss<'a> {
    job: ProjectJob<'a>,
    scan: &'a LaserScan,
    /// Per beam, [`ProjectJob::free_below_m`] of its range, metres.
    free_below_m: Vec<f32>,
    /// Beams per turn, `2π / |increment|`.
    per_turn: f64,
    /// `1 / increment`: a voxel's position in the sweep is a product, not
    /// a quotient (the difference is far inside `margin`).
    per_increment: f64,
    /// How far a guessed position in the sweep may be from the exact one,
    /// beams.
    margin: f64,
}

impl<'a> PlanarMiss<'a> {
    /// The decision for `job`, when it projects a planar scan.
    pub(super) fn new(job: &ProjectJob<'a>) -> Option<Self> {
        let View::Sweep { scan } = job.view else {
            return None;
        };
        let free_below_m = scan.ranges.iter().map(|&d| job.free_below_m(d, &scan.range)).collect();
        let inc = scan.angle_increment_rad.abs();
        let per_turn = TAU / inc;
        // The angle's error over the increment, and the rounding of the
        // position's arithmetic (some 1e-16 of the sweep) a million times over.
        let margin = ANGLE_ERROR_RAD / inc + 1e-10 * (per_turn + scan.angle_min_rad.abs() / inc);
        let per_increment = 1.0 / scan.angle_increment_rad;
        Some(PlanarMiss { job: *job, scan, free_below_m, per_turn, per_increment, margin })
    }

    /// The largest threshold of the scan, metres.
    pub(super) fn free_below_sup(&self) -> f32 {
        self.free_below_m.iter().fold(f32::MIN, |m, &t| m.max(t))
    }

    /// What the voxels of tile `lo..hi` are, from a sphere holding their
    /// centres as [`VoxelToSensor::point`] rounds them: no miss where every
    /// point of the sphere is at least as far as the largest threshold of
    /// the beams its azimuths reach (or they reach no beam); a miss for
    /// every voxel in the slab where every point is nearer than the least
    /// threshold and every azimuth has a beam; else voxel by voxel. The
    /// slack on lengths and the margin on sweep positions are those of the
    /// voxel decisions, so the result is the definition's.
    pub(super) fn tile(&self, geom: &VoxelToSensor, lo: [usize; 3], hi: [usize; 3]) -> (Tile, Span) {
        let each = (Tile::Each, Span::ANY);
        let (c, half) = tile_centre(geom, lo, hi);
        let reach = norm(&half);
        let radius = reach * (1.0 + REL_SLACK) + REL_SLACK * (norm(&c) + geom.voxel_size_m);
        let d = (c[0] * c[0] + c[1] * c[1]).sqrt() * (1.0 - REL_SLACK);
        if d <= 2.0 * radius {
            return each;
        }
        // Azimuths within the sphere's half angle of its centre's, as
        // positions in the sweep; one that wraps past the sweep's start
        // (or reaches the last position, which can round to beam 0) is
        // left to the voxels. The half angle is `asin(r / d)`, bounded by
        // `tan` of it; the centre's azimuth is the table arctangent's, off
        // by at most its error.
        let sin = radius / d;
        let half_angle = sin / (1.0 - sin * sin).sqrt() + 2.0 * ANGLE_ERROR_RAD;
        let inc = self.scan.angle_increment_rad;
        let azimuth = fast_atan2(c[1], c[0], &ATAN);
        let centre = ((azimuth - self.scan.angle_min_rad) * self.per_increment).rem_euclid(self.per_turn);
        let width = half_angle / inc.abs() + self.margin;
        let (first, last) = (centre - width + 0.5, centre + width + 0.5);
        if first < 1.0 || last >= self.per_turn.floor() - 1.0 || last - first > TILE_BEAMS as f64 {
            return each;
        }
        let (first, last) = (first as usize, last as usize);
        let beams = self.free_below_m.len();
        if first >= beams {
            return (Tile::None, Span::ANY);
        }
        let thresholds = &self.free_below_m[first..=last.min(beams - 1)];
        let (least, largest) = thresholds.iter().fold((f32::MAX, f32::MIN), |(a, b), &t| (a.min(t), b.max(t)));
        let least = if last < beams { least } else { f32::MIN };
        let span = Span { least, largest };
        if (d - radius) * (1.0 - REL_SLACK) >= f64::from(largest) {
            (Tile::None, span)
        } else if (d + radius) * (1.0 + REL_SLACK) < f64::from(least) {
            (Tile::All, span)
        } else {
            (Tile::Each, span)
        }
    }

    /// Where the voxels `lo..hi` of the row whose [`VoxelToSensor::row`] is
    /// `row` lie against the scan's slab: all inside, all outside, or
    /// either. The height above the scan plane is affine along the row, so
    /// the two ends say it, with a slack far above the `f64` rounding of
    /// the terms and the `f32` rounding of [`VoxelToSensor::point`].
    #[inline]
    pub(super) fn row_in_slab(&self, geom: &VoxelToSensor, row: &[f64; 3], lo: usize, hi: usize) -> Option<bool> {
        let dx = |x: usize| (x as f64 + 0.5) * geom.voxel_size_m - geom.origin_m[0];
        let (d0, d1) = (dx(lo), dx(hi - 1));
        let (z0, z1) = (geom.rot[2][0] * d0 + row[2], geom.rot[2][0] * d1 + row[2]);
        let h = f64::from(self.job.planar_half_thickness_m);
        let terms = row[2].abs() + geom.rot[2][0].abs() * d0.abs().max(d1.abs());
        let slack = REL_SLACK * (h + terms) + 1e-12;
        let (near, far) = (z0.abs().min(z1.abs()), z0.abs().max(z1.abs()));
        if far < h - slack {
            Some(true)
        } else if near > h + slack && (z0 > 0.0) == (z1 > 0.0) {
            Some(false)
        } else {
            None
        }
    }

    /// Whether point `p` lies in the scan's slab, as the definition tests it.
    #[inline]
    pub(super) fn in_slab(&self, p: [f32; 3]) -> bool {
        p[2].abs() <= self.job.planar_half_thickness_m
    }

    /// [`Self::is_miss_at`]`(p)` for a point of a tile whose beams' thresholds
    /// are `span`: the beam is looked for only where the horizontal range
    /// lies between their least and largest.
    #[inline]
    pub(super) fn is_miss_in(&self, p: [f32; 3], span: Span) -> bool {
        if !self.in_slab(p) {
            return false;
        }
        let r = (p[0] * p[0] + p[1] * p[1]).sqrt();
        if r >= span.largest {
            false
        } else if r < span.least {
            true
        } else {
            self.is_miss_at(p)
        }
    }

    /// [`ProjectJob::is_miss_at`]`(p)`.
    #[inline]
    pub(super) fn is_miss_at(&self, p: [f32; 3]) -> bool {
        // NaN is not in the slab.
        if !self.in_slab(p) {
            return false;
        }
        let Some(beam) = self.beam(p) else {
            return self.job.is_miss_at(p);
        };
        let Some(&free_below_m) = self.free_below_m.get(beam) else {
            return false;
        };
        (p[0] * p[0] + p[1] * p[1]).sqrt() < free_below_m
    }

    /// [`LaserScan::beam`]'s index before its range check, from the guessed
    /// angle; `None` where the guess is too close to a boundary to tell.
    #[inline]
    fn beam(&self, p: [f32; 3]) -> Option<usize> {
        let az = fast_atan2(f64::from(p[1]), f64::from(p[0]), &ATAN);
        let rel = (az - self.scan.angle_min_rad) * self.per_increment;
        let m = self.margin;
        // `rem_euclid` of a position within one turn of the sweep's start:
        // itself, or one turn on; near 0 or a turn, the definition decides.
        let wrapped = if rel >= m && rel < self.per_turn - m {
            rel
        } else if rel <= -m && rel > m - self.per_turn {
            rel + self.per_turn
        } else {
            return None;
        };
        let x = wrapped + 0.5;
        // `x` is positive and below a turn's beams: truncation is the
        // floor, without a call to libm's `floor` (and through `i64`, one
        // instruction, where `u64` takes several).
        let k = x as i64;
        let i = k as f64;
        if x - i < m || i + 1.0 - x < m {
            return None;
        }
        let k = if i >= self.per_turn.floor() && (i - self.per_turn).abs() < 1.0 { 0 } else { k };
        // Every index is non-negative here; one past the beams is no beam.
        Some(usize::try_from(k).ok().filter(|&k| k < self.scan.ranges.len()).unwrap_or(usize::MAX))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::RangeLimits;
    use crate::{LocalVolume, VoxelIndex};
    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
    use proptest::prelude::*;
    use proptest::test_runner::RngSeed;
    use std::cell::Cell;
    use std::f64::consts::PI;

    thread_local! {
        /// Tiles decided whole so far, none and all.
        static WHOLE: Cell<(usize, usize)> = const { Cell::new((0, 0)) };
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 200, rng_seed: RngSeed::Fixed(0x9A7), ..ProptestConfig::default() })]
        /// A scan among walls (sectors of beams at one range, some open or
        /// with no return), from a slightly tilted scanner: a tile decided
        /// whole is what the definition says of every voxel in it.
        #[test]
        fn whole_tiles_are_the_definition(
            beams in prop_oneof![Just(360usize), Just(720), Just(1081)],
            full_turn in any::<bool>(), reverse in any::<bool>(), angle_min in -PI..PI,
            walls in proptest::collection::vec(prop_oneof![0.3f32..6.0, Just(f32::NAN), Just(20.0)], 1..9),
            voxel_size_m in prop_oneof![Just(0.05f64), Just(0.1)],
            at in proptest::array::uniform2(0.2f64..0.8), height in 0.0f64..1.0,
            tilt in proptest::array::uniform2(-0.05f64..0.05), yaw in -PI..PI,
            clear_no_return in any::<bool>(), margin in 0.0f32..0.1, thickness in 0.0f32..0.15,
        ) {
            let span = if full_turn { 2.0 * PI } else { 1.5 * PI };
            let inc = span / beams as f64 * if reverse { -1.0 } else { 1.0 };
            let ranges = (0..beams).map(|i| walls[i * walls.len() / beams]).collect();
            let scan = LaserScan { angle_min_rad: angle_min, angle_increment_rad: inc, ranges, range: RangeLimits { min_m: 0.1, max_m: 8.0 } };
            let volume = LocalVolume { origin: VoxelIndex([-40, -40, -1]), dims: [80, 80, 3], voxel_size_m };
            let side = 80.0 * voxel_size_m;
            let t = [-40.0 * voxel_size_m + at[0] * side, -40.0 * voxel_size_m + at[1] * side, (height * 3.0 - 1.0) * voxel_size_m];
            let rot = UnitQuaternion::from_euler_angles(tilt[0], tilt[1], yaw);
            let pose = Isometry3::from_parts(Translation3::from(Vector3::from(t)), rot);
            let job = ProjectJob {
                view: View::Sweep { scan: &scan }, t_world_sensor: &pose, volume,
                free_margin_m: margin, clear_no_return, planar_half_thickness_m: thickness,
            };
            let planar = PlanarMiss::new(&job).expect("a planar job");
            let geom = job.voxel_to_sensor();
            for (tx, ty) in (0..10).flat_map(|x| (0..10).map(move |y| (x, y))) {
                let (lo, hi) = ([tx * 8, ty * 8, 0], [tx * 8 + 8, ty * 8 + 8, 3]);
                let (tile, span) = planar.tile(&geom, lo, hi);
                WHOLE.with(|w| {
                    let (none, all) = w.get();
                    w.set(match tile { Tile::None => (none + 1, all), Tile::All => (none, all + 1), Tile::Each => (none, all) });
                });
                for c in (lo[0]..hi[0]).flat_map(|x| (lo[1]..hi[1]).flat_map(move |y| (0..3).map(move |z| [x, y, z]))) {
                    let p = geom.point(c);
                    let said = match tile {
                        Tile::None => false,
                        Tile::All => planar.in_slab(p),
                        Tile::Each => planar.is_miss_in(p, span),
                    };
                    prop_assert_eq!(said, job.is_miss(&geom, c), "{:?} tile, voxel {:?}, point {:?}", tile, c, p);
                }
            }
        }
    }

    #[test]
    fn scans_among_walls_decide_whole_tiles() {
        WHOLE.with(|w| w.set((0, 0)));
        whole_tiles_are_the_definition();
        let (none, all) = WHOLE.with(Cell::get);
        // The cases must reach both whole decisions, not only voxel by voxel.
        assert!(none > 1000 && all > 1000, "{none} tiles decided none, {all} all");
    }
}
