//! Occupancy by volumetric projection (paper §IV-A): every voxel of the
//! local volume is projected into the measurement and classified by
//! comparing its range with the measured one. One writer per voxel, so no
//! atomics are needed and the result is deterministic.
//!
//! The return is taken along the beam through the voxel's centre: the voxel
//! is a hit when that surface point lies inside it (within
//! `hit_tolerance_m` of the centre along every world axis), free when the
//! centre is more than `free_margin_m` in front of the return, and unseen
//! otherwise. Comparing ranges alone would call a voxel in front of a
//! slanted surface a hit, or miss a voxel the surface crosses off-centre.

use super::{Observations, OgmOptions};
use edtmap_core::sensor::{Frame, Projection, Sensor};
use edtmap_core::{OBS_HIT, OBS_MISS, OBS_NONE};
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;

/// Projects every voxel centre of `obs`'s volume into `frame`.
pub fn project_volume(obs: &Observations, sensor: &Sensor, frame: &Frame, opts: &OgmOptions) {
    let vol = *obs.volume();
    let [nx, ny, nz] = vol.dims;
    let vs = vol.voxel_size_m;
    let inv = frame.t_world_sensor.inverse();
    let rot = inv.rotation.to_rotation_matrix();
    let to_world = frame.t_world_sensor.rotation.to_rotation_matrix();
    let step_x = rot * Vector3::new(vs, 0.0, 0.0);
    let corner = Vector3::from(vol.min_corner_m());
    let planar = matches!(sensor, Sensor::Planar);
    (0..nz).into_par_iter().for_each(|z| {
        for y in 0..ny {
            let first = corner + Vector3::new(0.5 * vs, (y as f64 + 0.5) * vs, (z as f64 + 0.5) * vs);
            let mut p = inv.transform_point(&first.into()).coords;
            for x in 0..nx {
                let ps = [p.x as f32, p.y as f32, p.z as f32];
                let obs_code = if planar && ps[2].abs() > opts.planar_half_thickness_m {
                    OBS_NONE
                } else {
                    classify(sensor.project(&frame.measurement, ps), &p, &to_world, opts)
                };
                if obs_code != OBS_NONE {
                    obs.mark([x, y, z], x + nx * (y + ny * z), obs_code);
                }
                p += step_x;
            }
        }
    });
}

/// Classifies the voxel centred at `centre` (sensor frame) from where it
/// projects; `to_world` turns sensor-frame offsets into world axes.
#[inline]
fn classify(p: Projection, centre: &Vector3<f64>, to_world: &Rotation3<f64>, opts: &OgmOptions) -> u8 {
    match p {
        Projection::Unseen => OBS_NONE,
        Projection::Return { point_m, measured_m } => {
            if point_m < measured_m - opts.free_margin_m {
                OBS_MISS
            } else if point_m <= measured_m + opts.free_margin_m && point_m > 0.0 {
                // The return along the beam through the centre, relative to it.
                let offset = to_world * (centre * (measured_m as f64 / point_m as f64 - 1.0));
                let inside = offset.iter().all(|c| c.abs() <= opts.hit_tolerance_m as f64);
                if inside { OBS_HIT } else { OBS_NONE }
            } else {
                OBS_NONE
            }
        }
        Projection::NoReturn { point_m, max_m } => {
            if opts.clear_no_return && point_m < max_m { OBS_MISS } else { OBS_NONE }
        }
    }
}
