//! The occupancy stage (paper §IV-A): a frame's observations of the local
//! volume, by ray casting or volumetric projection on the backend, with
//! the host's share (ray set-up, the returns' hits) around it, then fused
//! into the map on the backend.
//!
//! Both constructions write one observation per voxel per frame (a hit wins
//! over a miss), so the fused map does not depend on thread scheduling.

use edtmap_core::construction::{project_job, scatter_returns, Construction, OgmOptions, Returns};
use edtmap_core::fixed_ray::{prepare_rays, FixedRay};
use edtmap_core::sensor::{Frame, Sensor, SensorRay};
use edtmap_core::{Backend, BackendError, CoreError, FuseReport, GlobalMap, LocalVolume, Observations};

/// The occupancy stage with its buffers, reused from frame to frame.
#[derive(Debug, Default)]
pub struct OccupancyStage {
    obs: Option<Observations>,
    rays: Vec<SensorRay>,
    fixed_rays: Vec<FixedRay>,
    returns: Returns,
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
        let job = match opts.construction {
            Construction::RayCasting => None,
            Construction::Auto => project_job(sensor, frame, volume, opts),
            Construction::Projection => Some(project_job(sensor, frame, volume, opts).ok_or_else(|| {
                let what = format!("volumetric projection of a {} from a {}", frame.measurement.kind(), sensor.kind());
                CoreError::Unsupported(what)
            })?),
        };
        if let Some(job) = job {
            // The returns' voxels are found on another thread while the
            // projection runs (its set-up is mostly serial), and marked
            // after it.
            let (returns, rays) = (&mut self.returns, &mut self.rays);
            let mut found = false;
            rayon::in_place_scope(|s| {
                s.spawn(|_| found = returns.find(&volume, sensor, frame, rays));
                backend.project_volume(&job, obs)
            })?;
            if !(found && returns.mark(obs)) {
                scatter_returns(obs, sensor, frame, rays);
            }
        } else {
            sensor.rays(&frame.measurement, opts.clear_no_return, &mut self.rays);
            // Room for a quarter more rays than this frame has: a sensor's
            // count varies a little from frame to frame, and a buffer grown
            // to each larger frame writes to fresh pages, which cost more
            // than the set-up itself.
            let want = self.rays.len();
            if self.fixed_rays.capacity() < want {
                self.fixed_rays.clear();
                // Where even that cannot be had, the set-up reserves what it needs.
                let _ = self.fixed_rays.try_reserve_exact(want + want / 4);
            }
            let q = prepare_rays(
                obs.volume(),
                &frame.t_world_sensor,
                &self.rays,
                opts.free_margin_at(volume.voxel_size_m),
                &mut self.fixed_rays,
            )?;
            backend.cast_rays(&self.fixed_rays, q, obs)?;
        }
        Ok(obs)
    }
}

/// Fuses `obs` into `map`'s occupancy layer on `backend`
/// ([`Backend::fuse`]), which may hold some of the observations on its
/// device.
pub fn fuse_on<B: Backend + ?Sized>(
    backend: &mut B,
    map: &mut GlobalMap,
    obs: &Observations,
) -> Result<FuseReport, BackendError> {
    let (occupancy, log_odds) = map.occupancy_and_log_odds();
    backend.fuse(occupancy, obs, log_odds)
}
