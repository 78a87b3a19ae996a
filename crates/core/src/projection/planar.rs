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

use super::lidar::{fast_atan2, ATAN};
use super::ProjectJob;
use crate::sensor::{LaserScan, View};
use std::f64::consts::TAU;

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
        Some(PlanarMiss { job: *job, scan, free_below_m, per_turn, margin })
    }

    /// The largest threshold of the scan, metres.
    pub(super) fn free_below_sup(&self) -> f32 {
        self.free_below_m.iter().fold(f32::MIN, |m, &t| m.max(t))
    }

    /// [`ProjectJob::is_miss_at`]`(p)`.
    #[inline]
    pub(super) fn is_miss_at(&self, p: [f32; 3]) -> bool {
        // As the definition tests it (NaN is not in the plane).
        let in_plane = p[2].abs() <= self.job.planar_half_thickness_m;
        if !in_plane {
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
        let rel = (az - self.scan.angle_min_rad) / self.scan.angle_increment_rad;
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
        // `x` is positive: truncation is the floor, without a call to
        // libm's `floor`.
        let i = x as u64 as f64;
        if x - i < m || i + 1.0 - x < m {
            return None;
        }
        let i = if i >= self.per_turn.floor() && (i - self.per_turn).abs() < 1.0 { 0.0 } else { i };
        // Every index is non-negative here; one past the beams is no beam.
        Some(if (i as usize) < self.scan.ranges.len() { i as usize } else { usize::MAX })
    }
}
