//! Occupancy by ray casting (paper §IV-A): a 3D DDA from the sensor to each
//! return, clipped to the local volume; the return's voxel gets a hit, the
//! voxels well before it a miss.
//!
//! The rays are set up on the host in `f64` ([`prepare_rays`]) and walked in
//! exact fixed point ([`edtmap_core::fixed_ray`]), so any backend that walks
//! the same [`FixedRay`]s observes the same voxels, bit for bit.

use super::Observations;
use crate::CpuError;
use edtmap_core::fixed_ray::{self, FixedRay, NO_HIT};
use edtmap_core::sensor::SensorRay;
use edtmap_core::{LocalVolume, OBS_HIT, OBS_MISS};
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;

/// Rays per rayon task: enough to amortise scheduling, small enough to
/// balance rays of very different lengths.
const RAYS_PER_TASK: usize = 256;

/// Casts every ray (sensor frame) from the pose into `obs`:
/// [`prepare_rays`], then [`cast_fixed`]. Fails only on a volume too large
/// for the fixed-point walk ([`fixed_ray::fixed_scale`]).
pub fn cast_rays(obs: &Observations, t_world_sensor: &Isometry3<f64>, rays: &[SensorRay], free_margin_m: f32) -> Result<(), CpuError> {
    let mut fixed = Vec::new();
    let q = prepare_rays(obs.volume(), t_world_sensor, rays, free_margin_m, &mut fixed)?;
    cast_fixed(obs, &fixed, q);
    Ok(())
}

/// Sets up every ray (sensor frame) from the pose for a walk through
/// `obs_volume`, into `out` (one per ray, in order), and returns the
/// fixed-point scale `q` they use.
///
/// A voxel is a miss only if the ray leaves it more than `free_margin_m`
/// (metres) before the return: the surface is located to a voxel, so a
/// voxel the ray crosses just before it may hold part of the surface. The
/// return's own voxel is the hit.
pub fn prepare_rays(obs_volume: &LocalVolume, t_world_sensor: &Isometry3<f64>, rays: &[SensorRay], free_margin_m: f32, out: &mut Vec<FixedRay>) -> Result<u32, CpuError> {
    let (dims, inv) = (obs_volume.dims, 1.0 / obs_volume.voxel_size_m);
    let q = fixed_ray::fixed_scale(dims)?;
    let corner = Vector3::from(obs_volume.min_corner_m());
    let origin = (t_world_sensor.translation.vector - corner) * inv;
    let rot = t_world_sensor.rotation.to_rotation_matrix();
    rays.par_iter()
        .with_min_len(RAYS_PER_TASK)
        .map(|ray| {
            let dir = rot * Vector3::new(ray.dir[0] as f64, ray.dir[1] as f64, ray.dir[2] as f64) * inv;
            let end = origin + dir * ray.range_m as f64;
            // Voxels the ray leaves before `free_end` are misses: walk to it
            // and, for a return, leave out its own voxel, which the ray
            // leaves beyond it.
            let margin = if ray.hit { free_margin_m.min(ray.range_m) as f64 } else { 0.0 };
            let free_end = origin + dir * (ray.range_m as f64 - margin);
            fixed_ray::setup_ray(origin.into(), free_end.into(), end.into(), ray.hit, dims, q)
        })
        .collect_into_vec(out);
    Ok(q)
}

/// Walks rays prepared for `obs`'s volume at scale `q` ([`prepare_rays`]):
/// the voxels they pass through become misses, their hits hits.
pub fn cast_fixed(obs: &Observations, rays: &[FixedRay], q: u32) {
    let dims = obs.volume().dims;
    rays.par_chunks(RAYS_PER_TASK).for_each(|chunk| {
        for ray in chunk {
            fixed_ray::walk_cells(ray, dims, q, |c, i| obs.mark(c.map(|v| v as usize), i as usize, OBS_MISS));
            if ray.hit != NO_HIT && (ray.hit as usize) < obs.volume().len() {
                let i = ray.hit as usize;
                let c = [i % dims[0], (i / dims[0]) % dims[1], i / (dims[0] * dims[1])];
                obs.mark(c, i, OBS_HIT);
            }
        }
    });
}
