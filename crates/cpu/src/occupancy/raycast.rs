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
            let dir = rot * Vector3::new(ray.dir[0] as f64, ray.dir[1] as f64, ray.dir[2] as f64) * inv;
            let end = origin + dir * ray.range_m as f64;
            // Voxels the ray leaves before `free_end` are misses: walk to it
            // and, for a return, leave out its own voxel, which the ray
            // leaves beyond it.
            let margin = if ray.hit { free_margin_m.min(ray.range_m) as f64 } else { 0.0 };
            let free_end = origin + dir * (ray.range_m as f64 - margin);
            dda::traverse(origin.into(), free_end.into(), vol.dims, ray.hit, |c, i| obs.mark(c, i, OBS_MISS));
            if ray.hit {
                if let Some(c) = local_cell(end.into(), vol.dims) {
                    obs.mark(c, vol.linear(c), OBS_HIT);
                }
            }
        }
    });
}

/// The cell of `p` (voxel units from the volume's corner), if inside.
fn local_cell(p: [f64; 3], dims: [usize; 3]) -> Option<[usize; 3]> {
    let mut c = [0usize; 3];
    for k in 0..3 {
        let f = p[k].floor();
        if !(f >= 0.0 && f < dims[k] as f64) {
            return None;
        }
        c[k] = f as usize;
    }
    Some(c)
}
