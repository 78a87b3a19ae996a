//! What a backend (the CPU with rayon, a GPU with wgpu) provides to the
//! pipeline, as capability traits the mapper is generic over.
//!
//! Every backend gives the same integer answers: the conformance suite in
//! `edtmap-sim` checks each one against the same oracles, bit for bit.
//!
//! # The batch EDT's tie rule
//! A voxel can have several nearest obstacles. Every backend picks the same
//! one: the separable scans run along x, then y, then z, and each scan keeps
//! the candidate at the lowest position along its axis among those at the
//! smallest value. `edtmap_sim::conformance::separable_oracle` computes it
//! by brute force.

use crate::fixed_ray::FixedRay;
use crate::projection::ProjectJob;
use crate::{BlockKey, CoreError, Cutoff, EdtField, EdtMap, Grid3, LocalVolume};

/// Errors a backend can raise besides those of the data it is given.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum BackendError {
    /// No usable GPU adapter (and no software one either).
    #[error("no GPU adapter found: {0}; use --backend cpu (or auto), or install a Vulkan driver such as Mesa's lavapipe (Debian: mesa-vulkan-drivers)")]
    NoAdapter(String),
    /// The GPU device was lost (driver reset, hang, unplugged): the frame
    /// was not applied.
    #[error("GPU device lost: {0}")]
    DeviceLost(String),
    /// The device refused a buffer or a dispatch as too large.
    #[error("{what} needs {needed} bytes, more than the device's limit of {limit} bytes")]
    OverLimit {
        /// What was being allocated.
        what: &'static str,
        /// Bytes needed.
        needed: u64,
        /// The device's limit, bytes.
        limit: u64,
    },
    /// Any other error the device reported (validation, out of memory).
    #[error("GPU error: {0}")]
    Device(String),
    /// The input itself is invalid.
    #[error(transparent)]
    Core(#[from] CoreError),
}

/// Exact batch EDT of a dense grid (paper §IV-B, Algorithm 1).
pub trait BatchEdt {
    /// The EDT of `mask` (true = obstacle) into `out`, reusing its
    /// buffers: squared distances in voxels² and nearest obstacles as
    /// linear indices, with the tie rule of this module's docs.
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError>;
}

/// A backend the mapper can run on.
pub trait Backend: BatchEdt {
    /// What it runs on, for reports and logs: `cpu (N threads)`, or the
    /// GPU's name and API.
    fn name(&self) -> String;

    /// Ray casting (paper §IV-A): walks `rays`, set up at scale `q` for a
    /// volume of `dims` ([`crate::fixed_ray`]), into `bits`: one byte per
    /// voxel, `OBS_MISS` for every voxel a walk visits, `OBS_HIT` for every
    /// hit, both where both happen. `Ok(false)` leaves it to the CPU (the
    /// default).
    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, dims: [usize; 3], bits: &mut Vec<u8>) -> Result<bool, BackendError> {
        let _ = (rays, q, dims, bits);
        Ok(false)
    }

    /// Tells the backend that the global EDT was changed by other means
    /// (the CPU's integrator, fixed obstacles laid down, another map), so
    /// whatever it holds of it is stale.
    fn map_changed(&mut self) {}

    /// Volumetric projection (paper §IV-A) of every voxel of `job.volume`
    /// into `bits`, one byte per voxel (linear order): [`crate::PROJ_MISS`]
    /// where [`ProjectJob::is_miss`] holds, [`crate::PROJ_NOT_MISS`] where
    /// it does not, [`crate::PROJ_UNCERTAIN`] where the backend cannot be
    /// sure (the host then decides). Hits are left to the host. `Ok(false)`
    /// leaves the whole projection to the CPU (the default).
    fn project_volume(&mut self, job: ProjectJob<'_>, bits: &mut Vec<u8>) -> Result<bool, BackendError> {
        let _ = (job, bits);
        Ok(false)
    }

    /// The wavefront integration of one frame (paper §IV-C, Algorithms 2
    /// and 3): merges `batch`, the batch EDT of `window`, into `map`.
    /// `Ok(None)` leaves it to the CPU's integrator (the default); a
    /// backend that does it must give the CPU's map, bit for bit.
    fn integrate_wavefront(&mut self, job: WavefrontJob<'_>) -> Result<Option<IntegrateReport>, BackendError> {
        let _ = job;
        Ok(None)
    }
}

/// One frame's wavefront integration, as [`Backend::integrate_wavefront`]
/// receives it.
#[derive(Debug)]
pub struct WavefrontJob<'a> {
    /// The global EDT.
    pub map: &'a mut EdtMap,
    /// The frame's window.
    pub window: &'a LocalVolume,
    /// Exact EDT of the window's obstacles (unknown voxels free).
    pub batch: &'a EdtField,
    /// The cutoff in voxels.
    pub cutoff: Cutoff,
    /// Neighbour offsets the waves move along (6, 18 or 26).
    pub offsets: &'a [[i32; 3]],
}

/// What one integration did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IntegrateReport {
    /// Voxels whose distance or nearest obstacle changed.
    pub voxels_changed: usize,
    /// Sum of |new − old| distance over those voxels, voxels, distances
    /// truncated at the cutoff.
    pub change_sum_vox: f64,
    /// Blocks of the global EDT holding a changed voxel, sorted.
    pub changed_blocks: Vec<BlockKey>,
    /// Voxels in the working region.
    pub region_voxels: usize,
    /// Wavefront counters (all zero in exact mode).
    pub waves: WaveCounts,
}

/// Counters of one wavefront integration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WaveCounts {
    /// Voxels whose nearest obstacle vanished (frontier A and inside `W`).
    pub raised: usize,
    /// Window voxels that kept a nearer obstacle from outside the window
    /// (frontier C).
    pub kept_outside: usize,
    /// Voxels the lowering waves started from.
    pub seeds: usize,
    /// Levels the lowering waves took.
    pub levels: usize,
    /// Successful lowerings (a voxel can be lowered more than once).
    pub lowered: usize,
}



impl<B: BatchEdt + ?Sized> BatchEdt for Box<B> {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        (**self).batch_edt(mask, out)
    }
}

impl<B: Backend + ?Sized> Backend for Box<B> {
    fn name(&self) -> String {
        (**self).name()
    }

    fn integrate_wavefront(&mut self, job: WavefrontJob<'_>) -> Result<Option<IntegrateReport>, BackendError> {
        (**self).integrate_wavefront(job)
    }

    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, dims: [usize; 3], bits: &mut Vec<u8>) -> Result<bool, BackendError> {
        (**self).cast_rays(rays, q, dims, bits)
    }

    fn map_changed(&mut self) {
        (**self).map_changed()
    }

    fn project_volume(&mut self, job: ProjectJob<'_>, bits: &mut Vec<u8>) -> Result<bool, BackendError> {
        (**self).project_volume(job, bits)
    }
}
