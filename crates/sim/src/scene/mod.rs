//! A scene built from one of the `layouts`: static solids, walking
//! pedestrians and a sensor trajectory, with simulated measurements
//! (`render`) and exact ground truth (`truth`, `seen`).

mod name;
mod render;
mod seen;
mod truth;

pub use name::{SceneName, SceneOptions, SceneSection};
pub use render::{points_pattern, PLANAR_BEAMS, PLANAR_RANGE};

use crate::geometry::{Aabb, Primitive};
use crate::layouts::{self, Layout};
use crate::pedestrian::Pedestrian;
use crate::trajectory::Route;
use crate::SimError;
use edtmap_core::sensor::Sensor;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};

/// How far the built-in worlds are moved from their nominal layout, metres:
/// the odd offsets keep faces off the voxel boundaries of common voxel sizes
/// (0.01 to 0.2 m), so ground truth does not hinge on rounding.
pub const WORLD_SHIFT_M: [f64; 3] = [0.0173, 0.0291, -0.013];

/// A built-in scene: geometry, motion and the sensor that observes it.
#[derive(Debug, Clone)]
pub struct Scene {
    name: SceneName,
    options: SceneOptions,
    statics: Vec<Primitive>,
    walkers: Vec<Pedestrian>,
    trajectory: Route,
    sensor: Sensor,
    frame_period_s: f64,
    default_frames: usize,
    extent: Aabb,
}

impl Scene {
    /// Builds scene `name`; the layout and the noise follow `options.seed`.
    /// Fails naming the option when the noise or dropout is out of range.
    pub fn new(name: SceneName, options: &SceneOptions) -> Result<Scene, SimError> {
        options.validate()?;
        let layout = layouts::build(name, options.seed);
        Ok(Scene::from_layout(name, options.clone(), layout.translated(WORLD_SHIFT_M)))
    }

    pub(crate) fn from_layout(name: SceneName, options: SceneOptions, layout: Layout) -> Scene {
        let Layout { statics, walkers, trajectory, sensor, frame_period_s, default_frames } = layout;
        let extent = world_extent(&statics);
        Scene { name, options, statics, walkers, trajectory, sensor, frame_period_s, default_frames, extent }
    }

    /// Which built-in scene this is.
    pub fn name(&self) -> SceneName {
        self.name
    }

    /// The options the scene was built with.
    pub fn options(&self) -> &SceneOptions {
        &self.options
    }

    /// The sensor the scene was designed for (see [`SceneName`]).
    pub fn default_sensor(&self) -> Sensor {
        self.sensor.clone()
    }

    /// Time between frames, seconds.
    pub fn frame_period_s(&self) -> f64 {
        self.frame_period_s
    }

    /// A run length that covers the interesting part of the scene, frames.
    pub fn default_frames(&self) -> usize {
        self.default_frames
    }

    /// `T_world_body` at time `t_s`: x forward, y left, z up, with the body
    /// origin at the sensor. Level, heading along the path, except for the
    /// hand-held camera of `room`, which looks at the room's centre.
    pub fn body_pose(&self, t_s: f64) -> Isometry3<f64> {
        self.trajectory.pose(t_s)
    }

    /// `T_world_sensor` at time `t_s`: the body pose, turned into the optical
    /// frame (x right, y down, z forward) for a depth camera.
    pub fn sensor_pose(&self, sensor: &Sensor, t_s: f64) -> Isometry3<f64> {
        self.mounted_pose(sensor, &Isometry3::identity(), t_s)
    }

    /// `T_world_sensor` at time `t_s` of a sensor mounted at
    /// `t_body_sensor` (its extrinsics, x forward, y left, z up in the
    /// sensor's mount), turned into the optical frame for a depth camera.
    pub fn mounted_pose(&self, sensor: &Sensor, t_body_sensor: &Isometry3<f64>, t_s: f64) -> Isometry3<f64> {
        let mount = self.body_pose(t_s) * t_body_sensor;
        match sensor {
            Sensor::Depth(_) => mount * body_from_optical(),
            _ => mount,
        }
    }

    /// Every solid at time `t_s`: the static ones, then the pedestrians.
    pub fn solids_at(&self, t_s: f64) -> Vec<Primitive> {
        let walkers = self.walkers.iter().map(|w| Primitive::Cylinder(w.at(t_s)));
        self.statics.iter().copied().chain(walkers).collect()
    }

    /// Distance from `p` (world, metres) to the nearest solid at time `t_s`.
    pub fn clearance_m(&self, p: [f64; 3], t_s: f64) -> f64 {
        self.solids_at(t_s).iter().map(|s| s.distance(p)).fold(f64::INFINITY, f64::min)
    }

    /// Exact distance along the unit ray `origin + t·dir` (world) to the
    /// nearest solid at time `t_s`, if within `max_m`.
    pub fn ray_distance(&self, origin: [f64; 3], dir: [f64; 3], t_s: f64, max_m: f64) -> Option<f64> {
        let walkers = self.walkers.iter().map(|w| Primitive::Cylinder(w.at(t_s)));
        let mut best = max_m;
        let mut hit = None;
        for s in self.statics.iter().copied().chain(walkers) {
            if s.bounds().distance(origin) > best {
                continue;
            }
            if let Some(t) = s.ray_hit(origin, dir, best) {
                (best, hit) = (t, Some(t));
            }
        }
        hit
    }

    /// Extent of the static world: the box holding every finite solid,
    /// reaching down to the ground's surface where there is one.
    pub fn bounds(&self) -> Aabb {
        self.extent
    }
}

/// The rotation from the optical frame (x right, y down, z forward) to the
/// body frame (x forward, y left, z up).
fn body_from_optical() -> Isometry3<f64> {
    #[rustfmt::skip]
    let m = Matrix3::new(
        0.0, 0.0, 1.0,
        -1.0, 0.0, 0.0,
        0.0, -1.0, 0.0,
    );
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
    Isometry3::from_parts(Translation3::identity(), rotation)
}

fn world_extent(statics: &[Primitive]) -> Aabb {
    let finite = |b: &Aabb| b.min.iter().chain(&b.max).all(|v| v.is_finite());
    let bounds: Vec<Aabb> = statics.iter().map(Primitive::bounds).collect();
    let mut extent =
        bounds.iter().filter(|b| finite(b)).fold(None, |acc: Option<Aabb>, b| Some(acc.map_or(*b, |a| a.union(b))));
    let ground = bounds.iter().filter(|b| !finite(b)).map(|b| b.max[2]).fold(f64::INFINITY, f64::min);
    if let Some(e) = &mut extent {
        e.min[2] = e.min[2].min(ground);
    }
    extent.unwrap_or(Aabb { min: [0.0; 3], max: [0.0; 3] })
}

#[cfg(test)]
mod tests;
