//! The occupancy stage (paper §IV-A): a frame's observations of the local
//! volume, by ray casting or volumetric projection on the backend, with
//! the host's share (ray set-up, the returns' hits) around it.
//!
//! Both constructions write one observation per voxel per frame (a hit wins
//! over a miss), so the fused map does not depend on thread scheduling.

use crate::fixed_ray::{prepare_rays, FixedRay};
use crate::sensor::{Frame, Measurement, Sensor, SensorRay};
use crate::{Backend, BackendError, CoreError, LocalVolume, Observations, ProjectJob, VoxelIndex, OBS_HIT};
use nalgebra::Vector3;
use rayon::prelude::*;

/// How a frame's occupancy is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Construction {
    /// Projection where the sensor model allows it, else ray casting.
    #[default]
    Auto,
    /// Ray casting (an exact fixed-point 3D DDA) from the sensor to each
    /// return.
    RayCasting,
    /// Volumetric projection of every voxel into the measurement.
    Projection,
}

/// Options of the occupancy stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OgmOptions {
    /// Which construction runs.
    pub construction: Construction,
    /// Whether a ray with no return clears space up to the maximum range.
    pub clear_no_return: bool,
    /// Both constructions: a voxel is free only if it lies more than this
    /// in front of the return (ray casting: the ray leaves it that far
    /// before the return), metres. Voxels between are left unobserved, as
    /// the surface is only located to a voxel.
    pub free_margin_m: f32,
    /// Projection of planar scans: voxels within this height of the scan
    /// plane are observed, metres.
    pub planar_half_thickness_m: f32,
}

impl OgmOptions {
    /// Defaults for a voxel size: half a voxel of planar thickness, half a
    /// voxel diagonal of free margin.
    pub fn for_voxel_size(voxel_size_m: f64) -> Self {
        let half = (voxel_size_m / 2.0) as f32;
        let half_diagonal = (voxel_size_m * 3f64.sqrt() / 2.0) as f32;
        OgmOptions {
            construction: Construction::Auto,
            clear_no_return: false,
            free_margin_m: half_diagonal,
            planar_half_thickness_m: half,
        }
    }
}

/// The occupancy stage with its buffers, reused from frame to frame.
#[derive(Debug, Default)]
pub struct OccupancyStage {
    obs: Option<Observations>,
    rays: Vec<SensorRay>,
    fixed_rays: Vec<FixedRay>,
}

impl OccupancyStage {
    /// Observes `frame` (already checked against `sensor`) over `volume`,
    /// casting the rays or projecting the volume on `backend`.
    pub fn observe<B: Backend + ?Sized>(
        &mut self,
        backend: &mut B,
        sensor: &Sensor,
        frame: &Frame,
        volume: LocalVolume,
        opts: &OgmOptions,
    ) -> Result<&Observations, BackendError> {
        if let Some(o) = &mut self.obs {
            o.reset(volume);
        }
        let obs = self.obs.get_or_insert_with(|| Observations::new(volume));
        let projectable = sensor.supports_projection() && !matches!(frame.measurement, Measurement::Points(_));
        let project = match opts.construction {
            Construction::Auto => projectable,
            Construction::RayCasting => false,
            Construction::Projection if projectable => true,
            Construction::Projection => {
                let what = format!("volumetric projection of a {} from a {}", frame.measurement.kind(), sensor.kind());
                return Err(CoreError::Unsupported(what).into());
            }
        };
        if project {
            backend.project_volume(&project_job(sensor, frame, volume, opts), obs)?;
            scatter_returns(obs, sensor, frame, &mut self.rays);
        } else {
            sensor.rays(&frame.measurement, opts.clear_no_return, &mut self.rays);
            let q = prepare_rays(obs.volume(), &frame.t_world_sensor, &self.rays, opts.free_margin_m, &mut self.fixed_rays)?;
            backend.cast_rays(&self.fixed_rays, q, obs)?;
        }
        Ok(obs)
    }
}

/// The projection of `frame` over `volume` as a backend receives it.
pub fn project_job<'a>(sensor: &'a Sensor, frame: &'a Frame, volume: LocalVolume, opts: &OgmOptions) -> ProjectJob<'a> {
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

/// Marks the voxel of every return as a hit: volumetric projection's hits
/// (voxels are usually larger than a beam's spacing, so testing only the
/// beam nearest a voxel's centre would miss a surface crossing it
/// off-centre; one pass over the returns finds them all).
pub fn scatter_returns(obs: &Observations, sensor: &Sensor, frame: &Frame, rays: &mut Vec<SensorRay>) {
    sensor.rays(&frame.measurement, false, rays);
    let vol = *obs.volume();
    let pose = frame.t_world_sensor;
    rays.par_iter().with_min_len(1024).filter(|r| r.hit).for_each(|r| {
        let local = Vector3::new(r.dir[0] as f64, r.dir[1] as f64, r.dir[2] as f64) * r.range_m as f64;
        let p = pose.transform_point(&local.into());
        let voxel = VoxelIndex::containing(p.coords.into(), vol.voxel_size_m);
        if let Some(c) = voxel.and_then(|v| vol.local(v)) {
            obs.mark(c, vol.linear(c), OBS_HIT);
        }
    });
}
