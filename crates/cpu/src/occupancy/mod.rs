//! Occupancy mapping (paper §IV-A): a frame's observations of the local
//! volume, by ray casting or volumetric projection, fused into the global
//! log-odds map.
//!
//! Both constructions write one observation per voxel per frame (a hit wins
//! over a miss), so the fused map does not depend on thread scheduling.

mod fuse;
mod observe;
mod project;
mod raycast;

pub use fuse::{fuse, read_states, FuseReport};
pub use observe::Observations;
pub use project::{decide_uncertain, project_job, project_volume, scatter_returns};
pub use raycast::{cast_fixed, cast_rays, prepare_rays};

use crate::CpuError;
use edtmap_core::fixed_ray::FixedRay;
use edtmap_core::sensor::{Frame, Measurement, Sensor, SensorRay};
use edtmap_core::LocalVolume;

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
    /// Observation bits a backend cast the rays into.
    bits: Vec<u8>,
}

impl OccupancyStage {
    /// Observes `frame` (already checked against `sensor`) over `volume`.
    pub fn observe(&mut self, sensor: &Sensor, frame: &Frame, volume: LocalVolume, opts: &OgmOptions) -> Result<&Observations, CpuError> {
        self.observe_on(&mut crate::CpuBackend::default(), sensor, frame, volume, opts)
    }

    /// [`Self::observe`], with the rays cast or the volume projected by
    /// `backend` when it can.
    pub fn observe_on<B: edtmap_core::Backend + ?Sized>(
        &mut self,
        backend: &mut B,
        sensor: &Sensor,
        frame: &Frame,
        volume: LocalVolume,
        opts: &OgmOptions,
    ) -> Result<&Observations, CpuError> {
        if let Some(o) = &mut self.obs {
            o.reset(volume);
        }
        let obs = self.obs.get_or_insert_with(|| Observations::new(volume));
        let projectable = sensor.supports_projection() && !matches!(frame.measurement, Measurement::Points(_));
        let project = match opts.construction {
            Construction::Auto => projectable,
            Construction::RayCasting => false,
            Construction::Projection if projectable => true,
            Construction::Projection => return Err(CpuError::Unsupported(format!("volumetric projection of a {} from a {}", frame.measurement.kind(), sensor.kind()))),
        };
        if project {
            let job = project_job(sensor, frame, volume, opts);
            if backend.project_volume(job, &mut self.bits)? {
                decide_uncertain(&job, &mut self.bits);
                obs.load_bits(&self.bits);
                scatter_returns(obs, sensor, frame, &mut self.rays);
            } else {
                project_volume(obs, sensor, frame, opts, &mut self.rays);
            }
        } else {
            sensor.rays(&frame.measurement, opts.clear_no_return, &mut self.rays);
            let q = prepare_rays(obs.volume(), &frame.t_world_sensor, &self.rays, opts.free_margin_m, &mut self.fixed_rays)?;
            if backend.cast_rays(&self.fixed_rays, q, volume.dims, &mut self.bits)? {
                obs.load_bits(&self.bits);
            } else {
                cast_fixed(obs, &self.fixed_rays, q);
            }
        }
        Ok(obs)
    }
}
