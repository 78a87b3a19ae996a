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

use edtmap_core::fixed_ray::FixedRay;
use edtmap_core::{Backend, BackendError, BatchEdt, EdtField, Grid3, IntegrateReport, ProjectJob, WavefrontJob};

/// The GPU as a [`Backend`] of the mapper: one device, kernels compiled
/// once, buffers reused across frames.
#[derive(Debug)]
pub struct GpuBackend {
    ctx: GpuContext,
    edt: GpuEdt,
    integrator: GpuIntegrator,
    raycast: GpuRaycast,
    project: GpuProject,
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
        Ok(GpuBackend { ctx, edt, integrator, raycast, project })
    }

    /// The device in use.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
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

    fn integrate_wavefront(&mut self, job: WavefrontJob<'_>) -> Result<Option<IntegrateReport>, BackendError> {
        self.integrator.run(job).map(Some)
    }

    fn map_changed(&mut self) {
        self.integrator.map_changed();
    }

    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, dims: [usize; 3], bits: &mut Vec<u8>) -> Result<bool, BackendError> {
        self.raycast.run(rays, q, dims, bits)
    }

    fn project_volume(&mut self, job: ProjectJob<'_>, bits: &mut Vec<u8>) -> Result<bool, BackendError> {
        self.project.run(&job, bits)
    }
}
