//! The catalogue of built-in scenes: what each one is made of (solids,
//! walkers, the sensor's path and the sensor), in nominal coordinates
//! (floor at z = 0), one file per scene. [`crate::Scene::new`] moves a
//! layout by [`crate::WORLD_SHIFT_M`]; the `scene` module simulates it.

mod planar;
mod room;
mod uav_pillars;
mod ugv_corridor;

use crate::geometry::{Aabb, Primitive};
use crate::pedestrian::Pedestrian;
use crate::trajectory::Route;
use crate::SceneName;
use edtmap_core::sensor::Sensor;
use rand::rngs::StdRng;
use rand::Rng;
use std::ops::Range;

/// Everything that makes a scene.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    /// Solids that never move.
    pub(crate) statics: Vec<Primitive>,
    /// Walking pedestrians.
    pub(crate) walkers: Vec<Pedestrian>,
    /// The sensor's path.
    pub(crate) trajectory: Route,
    /// The scene's own sensor.
    pub(crate) sensor: Sensor,
    /// Time between frames, seconds.
    pub(crate) frame_period_s: f64,
    /// Frames of a default run.
    pub(crate) default_frames: usize,
}

impl Layout {
    /// The layout moved by `shift` metres.
    pub(crate) fn translated(self, shift: [f64; 3]) -> Layout {
        Layout {
            statics: self.statics.iter().map(|s| s.translated(shift)).collect(),
            walkers: self.walkers.iter().map(|w| w.translated(shift)).collect(),
            trajectory: self.trajectory.translated(shift),
            ..self
        }
    }
}

/// The nominal layout of scene `name` under `seed`.
pub(crate) fn build(name: SceneName, seed: u64) -> Layout {
    match name {
        SceneName::UavPillars => uav_pillars::build(seed),
        SceneName::UgvCorridor => ugv_corridor::build(seed),
        SceneName::Room => room::build(seed),
        SceneName::Planar => planar::build(seed),
    }
}

/// A draw from `range` rounded to whole centimetres: with
/// [`crate::WORLD_SHIFT_M`], random faces keep off common voxel grids too.
fn cm(rng: &mut StdRng, range: Range<f64>) -> f64 {
    (rng.random_range(range) * 100.0).round() / 100.0
}

/// A box from two corners.
fn block(a: [f64; 3], b: [f64; 3]) -> Primitive {
    Aabb::new(a, b).into()
}

/// Keeps clutter at least a clearance away from every point of a path.
struct KeepOut {
    samples: Vec<[f64; 3]>,
    clearance_m: f64,
}

/// Spacing of the path samples a [`KeepOut`] checks, metres.
const SAMPLE_SPACING_M: f64 = 0.05;

impl KeepOut {
    fn new(trajectory: &Route, clearance_m: f64) -> KeepOut {
        // A path point lies within half a spacing of a sample.
        KeepOut { samples: trajectory.samples(SAMPLE_SPACING_M), clearance_m: clearance_m + SAMPLE_SPACING_M / 2.0 }
    }

    fn allows(&self, solid: &Primitive) -> bool {
        let b = solid.bounds();
        self.samples.iter().all(|&p| b.distance(p) >= self.clearance_m || solid.distance(p) >= self.clearance_m)
    }
}

/// `count` solids from `draw` that `keep` allows, redrawing refused ones
/// (at most 100 draws per solid, so a crowded field gets fewer).
fn scatter(
    rng: &mut StdRng,
    count: usize,
    keep: &KeepOut,
    mut draw: impl FnMut(&mut StdRng) -> Primitive,
) -> Vec<Primitive> {
    let mut out = Vec::with_capacity(count);
    for _ in 0..count * 100 {
        if out.len() == count {
            break;
        }
        let s = draw(rng);
        if keep.allows(&s) {
            out.push(s);
        }
    }
    out
}
