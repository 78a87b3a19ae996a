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
mod exact;
mod integrate;
mod project;
mod raycast;

pub use context::GpuContext;
use context::Stage;
use exact::GpuExact;
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
    exact: GpuExact,
    /// The host-side exact integration, for cutoffs the device's pool
    /// cannot encode.
    exact_host: ExactBuffers,
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
        let exact = GpuExact::new(&ctx)?;
        Ok(GpuBackend { ctx, edt, integrator, raycast, project, exact, exact_host: ExactBuffers::default(), bits: Vec::new() })
    }

    /// Caps the blocks of the global EDT the exact integration keeps
    /// resident on the device (2 KiB each) at `blocks`, for a device with
    /// little memory to spare; a frame's region always fits, and the
    /// blocks least recently used make way. By default the pool grows to
    /// twice the largest region seen, within the device's buffer limit.
    pub fn limit_resident_blocks(&mut self, blocks: usize) {
        self.exact.limit_pool(blocks);
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

impl GpuBackend {
    /// Recomputes `region` of `map` exactly: on the device with its
    /// resident block pool, only the changed blocks read back; on the host
    /// from the device's batch EDT where the pool cannot encode the cutoff.
    fn recompute(&mut self, map: &mut edtmap_core::EdtMap, obstacles: &edtmap_core::Obstacles<'_>, region: Region, cutoff: edtmap_core::Cutoff) -> Result<IntegrateReport, BackendError> {
        let packing = Packing::new(region, cutoff)?;
        let written = if GpuExact::supports(cutoff.reach) {
            self.exact.run(&mut self.edt, map, obstacles, &packing)?
        } else {
            recompute_exact(&mut self.edt, map, obstacles, &packing, &mut self.exact_host)?
        };
        Ok(written.into_report(region.len(), WaveCounts::default()))
    }
}

impl BatchEdt for GpuEdt {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        self.run(mask, out)
    }
}

impl BatchEdt for GpuBackend {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        self.ctx.set_stage(Stage::BatchEdt);
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
        self.ctx.set_stage(Stage::Occupancy);
        if self.raycast.run(rays, q, obs.volume().dims, &mut self.bits)? {
            obs.load_bits(&self.bits);
        } else {
            cast_fixed(obs, rays, q);
        }
        Ok(())
    }

    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError> {
        self.ctx.set_stage(Stage::Occupancy);
        if self.project.run(job, &mut self.bits)? {
            decide_uncertain(job, &mut self.bits);
            obs.load_bits(&self.bits);
        } else {
            mark_misses(obs, job);
        }
        Ok(())
    }

    fn integrate(&mut self, job: IntegrateJob<'_>) -> Result<IntegrateReport, BackendError> {
        self.ctx.set_stage(Stage::Integrate);
        let IntegrateJob { map, obstacles, cutoff, work } = job;
        match work {
            Integration::Wavefront { window, batch, offsets } => self.integrator.run(map, window, batch, cutoff, offsets),
            Integration::Changes { blocks } => {
                // Exact over every voxel within the cutoff of the changed
                // blocks: the same map as the CPU's line-by-line update.
                let Some(region) = Region::bounding(blocks) else { return Ok(IntegrateReport::default()) };
                self.recompute(map, &obstacles, region.grown(cutoff.reach), cutoff)
            }
            Integration::Recompute { region } => self.recompute(map, &obstacles, region, cutoff),
        }
    }
}
