//! The GPU backend of edtmap: the pipeline's kernels as wgpu compute
//! shaders in WGSL (each `.wgsl` file beside the module that dispatches
//! it), on Vulkan, Metal or DX12, and on Mesa's lavapipe (software Vulkan)
//! where there is no GPU. Every result is an integer bit-identical to the
//! CPU backend's; the conformance suite of `edtmap-sim` checks both.
//!
//! [`GpuBackend::new`] fails with [`BackendError::NoAdapter`] when no
//! adapter exists; a lost device is [`BackendError::DeviceLost`] on the
//! next call, never a hang (every wait has a timeout) or a partial result.
#![warn(missing_docs)]

mod context;
mod dispatch;
mod edt;
mod integrate;
mod project;
mod raycast;

pub use context::GpuContext;
pub use edt::GpuEdt;
pub use integrate::GpuIntegrator;
pub use project::GpuProject;
pub use raycast::GpuRaycast;

use edtmap_core::fixed_ray::{cast_fixed, FixedRay};
use edtmap_core::region::{Packing, Region};
use edtmap_core::stages::exact::{recompute_exact, ExactBuffers};
use edtmap_core::{
    decide_uncertain, mark_misses, Backend, BackendError, BatchEdt, EdtField, Grid3, IntegrateJob, IntegrateReport, Integration, Observations, ProjectJob,
    WaveCounts,
};

/// The GPU as a [`Backend`] of the mapper: one device, kernels compiled
/// once, buffers reused across frames. Every stage runs on the device
/// where its kernel applies; where it does not (a LiDAR's projection, a
/// volume past the fixed-point walk's range) the backend computes the
/// same definition on the host, so its results are the CPU's either way.
#[derive(Debug)]
pub struct GpuBackend {
    ctx: GpuContext,
    edt: GpuEdt,
    integrator: GpuIntegrator,
    raycast: GpuRaycast,
    project: GpuProject,
    exact: ExactBuffers,
    /// Observation bytes read back from the device.
    bits: Vec<u8>,
}

impl GpuBackend {
    /// Opens the best adapter (see [`GpuContext::new`]) and compiles the
    /// kernels.
    pub fn new() -> Result<Self, BackendError> {
        let ctx = GpuContext::new()?;
        let edt = GpuEdt::new(&ctx)?;
        let integrator = GpuIntegrator::new(&ctx)?;
        let raycast = GpuRaycast::new(&ctx)?;
        let project = GpuProject::new(&ctx)?;
        Ok(GpuBackend { ctx, edt, integrator, raycast, project, exact: ExactBuffers::default(), bits: Vec::new() })
    }

    /// The device in use.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// The device's projection alone: one byte per voxel of `job.volume`
    /// into `bits` ([`edtmap_core::PROJ_MISS`], [`edtmap_core::PROJ_NOT_MISS`]
    /// or [`edtmap_core::PROJ_UNCERTAIN`]), before the host decides the
    /// uncertain ones; `Ok(false)` where the kernel does not apply. For
    /// measuring how much the host has to decide.
    pub fn project_bits(&mut self, job: &ProjectJob<'_>, bits: &mut Vec<u8>) -> Result<bool, BackendError> {
        self.project.run(job, bits)
    }
}

impl BatchEdt for GpuEdt {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        self.run(mask, out)
    }
}

impl BatchEdt for GpuBackend {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        self.edt.run(mask, out)
    }
}

impl Backend for GpuBackend {
    fn name(&self) -> String {
        format!("gpu: {}", self.ctx.name())
    }

    fn device_counters(&self) -> Option<edtmap_core::DeviceCounters> {
        Some(self.ctx.counters())
    }

    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, obs: &Observations) -> Result<(), BackendError> {
        if self.raycast.run(rays, q, obs.volume().dims, &mut self.bits)? {
            obs.load_bits(&self.bits);
        } else {
            cast_fixed(obs, rays, q);
        }
        Ok(())
    }

    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError> {
        if self.project.run(job, &mut self.bits)? {
            decide_uncertain(job, &mut self.bits);
            obs.load_bits(&self.bits);
        } else {
            mark_misses(obs, job);
        }
        Ok(())
    }

    fn integrate(&mut self, job: IntegrateJob<'_>) -> Result<IntegrateReport, BackendError> {
        let IntegrateJob { map, obstacles, cutoff, work } = job;
        match work {
            Integration::Wavefront { window, batch, offsets } => self.integrator.run(map, window, batch, cutoff, offsets),
            Integration::Changes { blocks } => {
                // Exact over every voxel within the cutoff of the changed
                // blocks: the same map as the CPU's line-by-line update.
                let Some(region) = Region::bounding(blocks) else { return Ok(IntegrateReport::default()) };
                let region = region.grown(cutoff.reach);
                let packing = Packing::new(region, cutoff)?;
                let written = recompute_exact(&mut self.edt, map, &obstacles, &packing, &mut self.exact)?;
                Ok(written.into_report(region.len(), WaveCounts::default()))
            }
            Integration::Recompute { region } => {
                // The batch EDT of the source box on the device, the rest
                // on the host, as on the CPU.
                let packing = Packing::new(region, cutoff)?;
                let written = recompute_exact(&mut self.edt, map, &obstacles, &packing, &mut self.exact)?;
                Ok(written.into_report(region.len(), WaveCounts::default()))
            }
        }
    }
}
