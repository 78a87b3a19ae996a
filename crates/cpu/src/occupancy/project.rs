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
//!
//! A voxel's decision is `edtmap_core::ProjectJob::is_miss`, a pure
//! function of the frame and the voxel (no rounding carried along a row),
//! so a backend can take it over: [`Backend::project_volume`] decides the
//! voxels it is sure of and [`decide_uncertain`] the rest, on the host.
//!
//! [`Backend::project_volume`]: edtmap_core::Backend::project_volume

use super::{Observations, OgmOptions};
use edtmap_core::sensor::{Frame, Sensor, SensorRay};
use edtmap_core::{ProjectJob, OBS_HIT, OBS_MISS, PROJ_UNCERTAIN};
use nalgebra::Vector3;
use rayon::prelude::*;

/// Projects every voxel centre of `obs`'s volume into `frame`; `rays` is a
/// scratch buffer for the returns. Each voxel is decided by
/// [`ProjectJob::is_miss`], the definition every backend follows.
pub fn project_volume(obs: &Observations, sensor: &Sensor, frame: &Frame, opts: &OgmOptions, rays: &mut Vec<SensorRay>) {
    scatter_returns(obs, sensor, frame, rays);
    let job = project_job(sensor, frame, *obs.volume(), opts);
    let geom = job.voxel_to_sensor();
    let [nx, ny, nz] = job.volume.dims;
    (0..ny * nz).into_par_iter().with_min_len(8).for_each(|row| {
        let (y, z) = (row % ny, row / ny);
        let shared = geom.row(y, z);
        for x in 0..nx {
            if job.is_miss_at(geom.point_in_row(&shared, x)) {
                obs.mark([x, y, z], x + nx * row, OBS_MISS);
            }
        }
    });
}

/// The projection of `frame` over `volume` as a backend receives it.
pub fn project_job<'a>(sensor: &'a Sensor, frame: &'a Frame, volume: edtmap_core::LocalVolume, opts: &OgmOptions) -> ProjectJob<'a> {
    ProjectJob {
        sensor,
        measurement: &frame.measurement,
        t_world_sensor: &frame.t_world_sensor,
        volume,
        free_margin_m: opts.free_margin_m,
        clear_no_return: opts.clear_no_return,
        planar_half_thickness_m: opts.planar_half_thickness_m,
    }
}

/// Decides every voxel a backend left [`PROJ_UNCERTAIN`] in `bits` (one
/// byte per voxel of `job.volume`) with [`ProjectJob::is_miss`], leaving
/// only `OBS_MISS` or nothing; returns how many there were.
pub fn decide_uncertain(job: &ProjectJob<'_>, bits: &mut [u8]) -> usize {
    let geom = job.voxel_to_sensor();
    let [nx, ny, _] = job.volume.dims;
    bits.par_chunks_mut(nx).enumerate().map(|(row, line)| {
        let (y, z) = (row % ny, row / ny);
        let mut n = 0;
        for (x, b) in line.iter_mut().enumerate().filter(|(_, b)| **b == PROJ_UNCERTAIN) {
            *b = if job.is_miss(&geom, [x, y, z]) { OBS_MISS } else { 0 };
            n += 1;
        }
        n
    }).sum()
}

/// Marks the voxel of every return as a hit.
pub fn scatter_returns(obs: &Observations, sensor: &Sensor, frame: &Frame, rays: &mut Vec<SensorRay>) {
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
