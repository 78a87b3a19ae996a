//! Occupancy by ray casting (paper §IV-A): a 3D DDA from the sensor to each
//! return, clipped to the local volume; the return's voxel gets a hit, the
//! voxels before it a miss.

use super::{dda, Observations};
use edtmap_core::sensor::SensorRay;
use edtmap_core::{OBS_HIT, OBS_MISS};
use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

/// Rays per rayon task: enough to amortise scheduling, small enough to
/// balance rays of very different lengths.
const RAYS_PER_TASK: usize = 256;

/// Casts every ray (sensor frame) from the pose into `obs`.
pub fn cast_rays(obs: &Observations, t_world_sensor: &Isometry3<f64>, rays: &[SensorRay]) {
    let vol = *obs.volume();
    let inv = 1.0 / vol.voxel_size_m;
    let corner = Vector3::from(vol.min_corner_m());
    let origin = (t_world_sensor.translation.vector - corner) * inv;
    let rot = t_world_sensor.rotation.to_rotation_matrix();
    rays.par_chunks(RAYS_PER_TASK).for_each(|chunk| {
        for ray in chunk {
            let dir = Vector3::new(ray.dir[0] as f64, ray.dir[1] as f64, ray.dir[2] as f64);
            let end = origin + rot * dir * (ray.range_m as f64 * inv);
            let (a, b) = (Point3::from(origin), Point3::from(end));
            let end_cell = ray.hit.then(|| vol.local(local_voxel(b, vol.origin.0))).flatten();
            dda::traverse(a.coords.into(), b.coords.into(), vol.dims, |c| {
                if Some(c) != end_cell {
                    obs.mark(c, OBS_MISS);
                }
            });
            if let Some(c) = end_cell {
                obs.mark(c, OBS_HIT);
            }
        }
    });
}

/// The world voxel of local point `p` (voxel units from the volume corner).
fn local_voxel(p: Point3<f64>, origin: [i32; 3]) -> edtmap_core::VoxelIndex {
    let f = |k: usize| {
        let v = p[k].floor();
        if v.is_finite() { (v as i64 + origin[k] as i64).clamp(i32::MIN as i64, i32::MAX as i64) as i32 } else { i32::MIN }
    };
    edtmap_core::VoxelIndex([f(0), f(1), f(2)])
}
