//! Occupancy by volumetric projection (paper §IV-A): every voxel of the
//! local volume is projected into the measurement and classified by
//! comparing its range with the measured one.
//!
//! A voxel is a **hit** when a return lies inside it. Voxels are usually
//! larger than a beam's spacing, so testing only the beam nearest the
//! centre would miss a surface crossing the voxel off-centre; the returns
//! are instead scattered into their voxels first (one pass over the
//! returns, so the cost stays that of the volume plus the measurement). A
//! voxel without a return is **free** when the beam nearest its centre
//! returns more than `free_margin_m` beyond it and a beam passes within half
//! a voxel of its centre (a LiDAR's rings are sparse: the nearest ring may
//! pass well above or below a voxel), and unseen otherwise. Voxel updates
//! are `fetch_or`s of bits, so the result is deterministic.

use super::{Observations, OgmOptions};
use edtmap_core::sensor::{Frame, Projection, Sensor, SensorRay};
use edtmap_core::{OBS_HIT, OBS_MISS};
use nalgebra::Vector3;
use rayon::prelude::*;

/// Projects every voxel centre of `obs`'s volume into `frame`; `rays` is a
/// scratch buffer for the returns.
pub fn project_volume(obs: &Observations, sensor: &Sensor, frame: &Frame, opts: &OgmOptions, rays: &mut Vec<SensorRay>) {
    scatter_returns(obs, sensor, frame, rays);
    let vol = *obs.volume();
    let [nx, ny, nz] = vol.dims;
    let vs = vol.voxel_size_m;
    let inv = frame.t_world_sensor.inverse();
    let step_x = inv.rotation * Vector3::new(vs, 0.0, 0.0);
    let corner = Vector3::from(vol.min_corner_m());
    let half_voxel = (vs / 2.0) as f32;
    let planar = matches!(sensor, Sensor::Planar);
    (0..nz).into_par_iter().for_each(|z| {
        for y in 0..ny {
            let first = corner + Vector3::new(0.5 * vs, (y as f64 + 0.5) * vs, (z as f64 + 0.5) * vs);
            let mut p = inv.transform_point(&first.into()).coords;
            for x in 0..nx {
                let ps = [p.x as f32, p.y as f32, p.z as f32];
                let in_plane = !planar || ps[2].abs() <= opts.planar_half_thickness_m;
                if in_plane && is_free(sensor.project(&frame.measurement, ps), opts) && sensor.beam_passes_within(ps, half_voxel) {
                    obs.mark([x, y, z], x + nx * (y + ny * z), OBS_MISS);
                }
                p += step_x;
            }
        }
    });
}

/// Marks the voxel of every return as a hit.
fn scatter_returns(obs: &Observations, sensor: &Sensor, frame: &Frame, rays: &mut Vec<SensorRay>) {
    sensor.rays(&frame.measurement, false, rays);
    let vol = *obs.volume();
    let pose = frame.t_world_sensor;
    rays.par_iter().with_min_len(1024).filter(|r| r.hit).for_each(|r| {
        let local = Vector3::new(r.dir[0] as f64, r.dir[1] as f64, r.dir[2] as f64) * r.range_m as f64;
        let p = pose.transform_point(&local.into());
        let voxel = edtmap_core::VoxelIndex::containing(p.coords.into(), vol.voxel_size_m);
        if let Some(c) = voxel.and_then(|v| vol.local(v)) {
            obs.mark(c, vol.linear(c), OBS_HIT);
        }
    });
}

/// Whether the measurement shows the voxel as free space.
#[inline]
fn is_free(p: Projection, opts: &OgmOptions) -> bool {
    match p {
        Projection::Return { point_m, measured_m } => point_m < measured_m - opts.free_margin_m,
        Projection::NoReturn { point_m, max_m } => opts.clear_no_return && point_m < max_m,
        Projection::Unseen => false,
    }
}
