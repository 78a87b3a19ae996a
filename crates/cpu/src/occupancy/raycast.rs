//! Occupancy by ray casting (paper §IV-A): a 3D DDA from the sensor to each
//! return, clipped to the local volume; the return's voxel gets a hit, the
//! voxels well before it a miss.

use super::{dda, Observations};
use edtmap_core::sensor::SensorRay;
use edtmap_core::{OBS_HIT, OBS_MISS};
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;

/// Rays per rayon task: enough to amortise scheduling, small enough to
/// balance rays of very different lengths.
const RAYS_PER_TASK: usize = 256;

/// Casts every ray (sensor frame) from the pose into `obs`.
///
/// A voxel is a miss only if the ray leaves it more than `free_margin_m`
/// before the return: the surface is located to a voxel, so a voxel the
/// ray crosses just before it may hold part of the surface.
pub fn cast_rays(obs: &Observations, t_world_sensor: &Isometry3<f64>, rays: &[SensorRay], free_margin_m: f32) {
    let vol = *obs.volume();
    let inv = 1.0 / vol.voxel_size_m;
    let corner = Vector3::from(vol.min_corner_m());
    let origin = (t_world_sensor.translation.vector - corner) * inv;
    let rot = t_world_sensor.rotation.to_rotation_matrix();
    rays.par_chunks(RAYS_PER_TASK).for_each(|chunk| {
        for ray in chunk {
            let dir = Vector3::new(ray.dir[0] as f64, ray.dir[1] as f64, ray.dir[2] as f64);
            let end = origin + rot * dir * (ray.range_m as f64 * inv);
            // Every voxel on the way is a miss; the last one is the return's
            // when the walk reached it, and then a hit wins over the miss.
            let margin = if ray.hit { free_margin_m / ray.range_m.max(f32::MIN_POSITIVE) } else { 0.0 };
            let free_until = 1.0 - margin as f64;
            let walk = dda::traverse(origin.into(), end.into(), vol.dims, |c, i, t_exit| {
                if t_exit <= free_until {
                    obs.mark(c, i, OBS_MISS);
                }
            });
            if let (true, Some((c, i))) = (ray.hit, walk.end) {
                obs.mark(c, i, OBS_HIT);
            }
        }
    });
}
