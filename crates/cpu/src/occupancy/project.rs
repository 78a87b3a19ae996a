//! Occupancy by volumetric projection (paper §IV-A): every voxel of the
//! local volume is projected into the measurement and classified by
//! comparing its range with the measured one. One writer per voxel, so no
//! atomics are needed and the result is deterministic.

use super::{Observations, OgmOptions};
use edtmap_core::sensor::{Frame, Projection, Sensor};
use edtmap_core::{OBS_HIT, OBS_MISS, OBS_NONE};
use nalgebra::Vector3;
use rayon::prelude::*;

/// Projects every voxel centre of `obs`'s volume into `frame`.
pub fn project_volume(obs: &Observations, sensor: &Sensor, frame: &Frame, opts: &OgmOptions) {
    let vol = *obs.volume();
    let [nx, ny, nz] = vol.dims;
    let vs = vol.voxel_size_m;
    let inv = frame.t_world_sensor.inverse();
    let rot = inv.rotation.to_rotation_matrix();
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
                    classify(sensor.project(&frame.measurement, ps), opts)
                };
                if obs_code != OBS_NONE {
                    obs.mark([x, y, z], x + nx * (y + ny * z), obs_code);
                }
                p += step_x;
            }
        }
    });
}

/// A voxel in front of the return is free, one within the tolerance of it
/// occupied, one behind it unknown (occluded).
#[inline]
fn classify(p: Projection, opts: &OgmOptions) -> u8 {
    match p {
        Projection::Unseen => OBS_NONE,
        Projection::Return { point_m, measured_m } => {
            if point_m < measured_m - opts.hit_tolerance_m {
                OBS_MISS
            } else if point_m <= measured_m + opts.hit_tolerance_m {
                OBS_HIT
            } else {
                OBS_NONE
            }
        }
        Projection::NoReturn { point_m, max_m } => {
            if opts.clear_no_return && point_m < max_m { OBS_MISS } else { OBS_NONE }
        }
    }
}
