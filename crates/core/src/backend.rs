//! What a backend (the CPU with rayon, a GPU with wgpu) provides to the
//! pipeline: one trait, [`Backend`], with a method per device stage, that
//! every backend implements in full.
//!
//! Every backend gives the same integer answers: the conformance suite
//! (`edtmap-conformance`) checks each one against the same oracles, bit for bit.
//!
//! # The batch EDT's tie rule
//! A voxel can have several nearest obstacles. Every backend picks the same
//! one: the separable scans run along x, then y, then z, and each scan keeps
//! the candidate at the lowest position along its axis among those at the
//! smallest value. `edtmap_conformance::separable_oracle` computes it
//! by brute force.

use crate::fixed_ray::FixedRay;
use crate::projection::ProjectJob;
use crate::{
    BlockKey, CoreError, Cutoff, EdtField, EdtMap, FuseReport, Grid3, LocalVolume, LogOdds, Observations, Obstacles,
    OccupancyMap, Region,
};

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

/// A backend the mapper can run on: every stage of the pipeline that runs
/// on a device. Each backend implements each method itself; what is
/// shared (ray set-up, the projection's definition, regions, fusion) is
/// host code in this crate that every backend calls.
///
/// # Caches
/// A backend may keep what it learnt of the global EDT between jobs (the
/// CPU: where each block's nearest obstacles lie; a GPU: the working
/// region, resident on the device). It keys what it keeps on
/// [`EdtMap::stamp`], which moves on with every change of the map, and
/// which no two maps share (clones included): a map changed by anything
/// else (another backend, fixed obstacles laid down, a loaded file) is
/// seen as changed and the cache dropped. Callers never tell a backend
/// about changes.
///
/// # Failures
/// A method that fails with a device error ([`BackendError::DeviceLost`],
/// [`BackendError::Device`], [`BackendError::OverLimit`]) has left its
/// output unspecified but the map whole: an integration writes the map only
/// after the device finished. The caller may redo the job on another
/// backend (the mapper finishes the frame on the CPU).
pub trait Backend: BatchEdt {
    /// What it runs on, for reports and logs: `cpu (N threads)`, or the
    /// GPU's name and API.
    fn name(&self) -> String;

    /// What crossed between the host and the device, and how much work
    /// was launched there, since the backend was made; `None` for a
    /// backend without a device (the CPU). Callers take differences.
    fn device_counters(&self) -> Option<DeviceCounters> {
        None
    }

    /// Whether the wavefront integration should be given the window's
    /// obstacles ([`IntegrationWork::WavefrontMask`]) rather than its batch
    /// EDT: true for a device, which computes the EDT where the
    /// integration reads it instead of sending it to the host and back.
    fn batch_stays_on_device(&self) -> bool {
        false
    }

    /// Whether [`Backend::integrate`] integrates planar maps
    /// ([`crate::GlobalParams::planar`]); a mapper refuses a planar map on
    /// a backend that does not.
    fn integrates_planar(&self) -> bool {
        true
    }

    /// Ray casting (paper §IV-A): walks `rays`, set up at scale `q` for
    /// `obs`'s volume ([`crate::fixed_ray::prepare_rays`]), into `obs`
    /// (freshly reset): [`crate::OBS_MISS`] for every voxel a walk visits,
    /// [`crate::OBS_HIT`] for every hit, exactly as
    /// [`crate::fixed_ray::walk`] defines them.
    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, obs: &Observations) -> Result<(), BackendError>;

    /// Volumetric projection (paper §IV-A): marks every voxel of
    /// `job.volume` for which [`ProjectJob::is_miss`] holds as
    /// [`crate::OBS_MISS`] in `obs` (freshly reset), and no other. Hits
    /// are left to the host ([`crate::construction::scatter_returns`]).
    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError>;

    /// Lets [`Backend::cast_rays`] and [`Backend::project_volume`] keep
    /// the observations they make on the device, for [`Backend::fuse`] to
    /// fuse there (`defer`), or makes them write every observation into
    /// `obs` again. While deferred, `obs` holds only what the host marks
    /// itself (a projection's hits, the uncertain voxels it decides): give
    /// it to [`Backend::fuse`] before the next frame's occupancy, and read
    /// the fused map, not `obs`. The mapper defers; a backend without a
    /// device ignores it.
    fn set_deferred_observations(&mut self, defer: bool) {
        let _ = defer;
    }

    /// Fusion (paper §IV-A): adds the frame's observations (`obs`, with
    /// what the device kept of them) to `map` with log-odds `lo`, as
    /// [`crate::fuse::fuse`] defines it, which is what a backend without a
    /// device runs. Every backend gives the same map and report, bit for
    /// bit. On a device failure the map is as it was.
    fn fuse(&mut self, map: &mut OccupancyMap, obs: &Observations, lo: &LogOdds) -> Result<FuseReport, BackendError> {
        Ok(crate::fuse::fuse(map, obs, lo))
    }

    /// Global integration (paper §IV-C): one [`IntegrationJob`] into
    /// `job.map`, writing back only the voxels that changed. Every
    /// backend gives the same map, bit for bit.
    fn integrate(&mut self, job: IntegrationJob<'_>) -> Result<IntegrationReport, BackendError>;
}

/// One integration, as [`Backend::integrate`] receives it.
#[derive(Debug)]
pub struct IntegrationJob<'a> {
    /// The global EDT.
    pub map: &'a mut EdtMap,
    /// The obstacles the EDT is that of (the other layers of the map).
    pub obstacles: Obstacles<'a>,
    /// The cutoff in voxels.
    pub cutoff: Cutoff,
    /// What to do.
    pub work: IntegrationWork<'a>,
}

/// The kinds of integration ([`crate::IntegrationMode`]).
#[derive(Debug, Clone, Copy)]
pub enum IntegrationWork<'a> {
    /// The paper's wavefronts (Algorithms 2 and 3): merges `batch`, the
    /// exact EDT of `window`'s obstacles (unknown voxels free), into the
    /// map, over the window grown by the cutoff's reach plus one.
    Wavefront {
        /// The frame's window.
        window: &'a LocalVolume,
        /// Exact EDT of the window's obstacles.
        batch: &'a EdtField,
        /// Neighbour offsets the waves move along (6, 18 or 26).
        offsets: &'a [[i32; 3]],
    },
    /// [`IntegrationWork::Wavefront`] with the batch EDT still to compute, of
    /// `mask` (the window's obstacles, unknown voxels free), by the
    /// backend itself: a device keeps it where the integration reads it,
    /// and nothing of it crosses to the host
    /// ([`Backend::batch_stays_on_device`]).
    WavefrontMask {
        /// The frame's window.
        window: &'a LocalVolume,
        /// The window's obstacles, `window.dims` voxels.
        mask: &'a Grid3<bool>,
        /// Neighbour offsets the waves move along (6, 18 or 26).
        offsets: &'a [[i32; 3]],
    },
    /// Exact update after the obstacles changed inside `blocks` (a frame's
    /// fused blocks whose states changed): the map, the exact EDT of the
    /// obstacles it was integrated with, becomes the exact EDT of
    /// `obstacles`, nearest obstacles by the batch EDT's tie rule. The
    /// exact mode's per-frame job.
    Changes {
        /// Blocks in which some voxel's obstacle state may have changed.
        blocks: &'a [BlockKey],
    },
    /// Exact recomputation of every voxel of `region` from the obstacles
    /// (a frame in exact mode: its window grown by the reach; fixed
    /// obstacles laid down: tiles of their box).
    Recompute {
        /// The voxels recomputed.
        region: Region,
    },
}

/// What one integration did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IntegrationReport {
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
    /// Counters of the separable passes (all zero in wavefront mode and
    /// on a GPU).
    pub exact: ExactCounts,
}

/// Counters of one exact integration on the CPU, by pass (x, y, z: the
/// separable EDT's `g1`, `g2` and the global EDT itself): what changed and
/// what the passes read to find it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExactCounts {
    /// Voxels that became obstacles (distance 0) in the global EDT.
    pub obstacles_added: usize,
    /// Of those, the ones that had no obstacle among their 26 neighbours
    /// before (squared distance above 3 voxels²): new islands, whose
    /// nearest-obstacle region reaches further than a surface's new edge.
    pub obstacles_added_apart: usize,
    /// Voxels that stopped being obstacles.
    pub obstacles_removed: usize,
    /// Entries each pass changed (pass z: the global EDT's changed voxels).
    pub changed: [usize; 3],
    /// Of those, entries whose nearest obstacle alone changed, at the
    /// same squared distance.
    pub nearest_only: [usize; 3],
    /// Outputs each pass recomputed from all their inputs (rescans).
    pub rescanned: [usize; 3],
    /// Outputs each pass read: the rescanned ones, those the lowering
    /// walks and the bisections read.
    pub visited: [usize; 3],
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

    fn device_counters(&self) -> Option<DeviceCounters> {
        (**self).device_counters()
    }

    fn batch_stays_on_device(&self) -> bool {
        (**self).batch_stays_on_device()
    }

    fn integrates_planar(&self) -> bool {
        (**self).integrates_planar()
    }

    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, obs: &Observations) -> Result<(), BackendError> {
        (**self).cast_rays(rays, q, obs)
    }

    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError> {
        (**self).project_volume(job, obs)
    }

    fn set_deferred_observations(&mut self, defer: bool) {
        (**self).set_deferred_observations(defer)
    }

    fn fuse(&mut self, map: &mut OccupancyMap, obs: &Observations, lo: &LogOdds) -> Result<FuseReport, BackendError> {
        (**self).fuse(map, obs, lo)
    }

    fn integrate(&mut self, job: IntegrationJob<'_>) -> Result<IntegrationReport, BackendError> {
        (**self).integrate(job)
    }
}

/// Running totals of a device backend's traffic and work
/// ([`Backend::device_counters`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct DeviceCounters {
    /// Bytes written from the host into device buffers.
    pub uploaded_bytes: u64,
    /// Bytes read back from the device.
    pub downloaded_bytes: u64,
    /// Compute dispatches (direct and indirect).
    pub dispatches: u64,
    /// Command buffer submissions.
    pub submissions: u64,
    /// Device memory the backend's buffers hold now, bytes (a level, not a
    /// running total); 0 where the driver does not report it (Metal).
    pub memory_bytes: u64,
    /// Device time of the occupancy stage's compute passes (ray casting,
    /// projection), nanoseconds, by timestamp queries; 0 where the adapter
    /// has none.
    pub occupancy_ns: u64,
    /// Device time of the batch EDT's passes, nanoseconds.
    pub batch_edt_ns: u64,
    /// Device time of the integration's passes (its own batch EDT
    /// included), nanoseconds.
    pub integrate_ns: u64,
    /// Wall time the host spent waiting for the device, nanoseconds: in
    /// submissions (a software device such as lavapipe runs much of the
    /// work inside them) and before reading results back. The rest of a
    /// frame's time is the host's own share, which a faster device does
    /// not shorten.
    pub wait_ns: u64,
}

impl DeviceCounters {
    /// What happened between `earlier` and `self`, with `self`'s memory.
    pub fn since(self, earlier: DeviceCounters) -> DeviceCounters {
        DeviceCounters {
            uploaded_bytes: self.uploaded_bytes.saturating_sub(earlier.uploaded_bytes),
            downloaded_bytes: self.downloaded_bytes.saturating_sub(earlier.downloaded_bytes),
            dispatches: self.dispatches.saturating_sub(earlier.dispatches),
            submissions: self.submissions.saturating_sub(earlier.submissions),
            memory_bytes: self.memory_bytes,
            occupancy_ns: self.occupancy_ns.saturating_sub(earlier.occupancy_ns),
            batch_edt_ns: self.batch_edt_ns.saturating_sub(earlier.batch_edt_ns),
            integrate_ns: self.integrate_ns.saturating_sub(earlier.integrate_ns),
            wait_ns: self.wait_ns.saturating_sub(earlier.wait_ns),
        }
    }
}

impl BackendError {
    /// Whether the device failed (lost, refused, erred), as opposed to the
    /// input being invalid: the job can be redone on another backend.
    pub fn is_device_failure(&self) -> bool {
        !matches!(self, BackendError::Core(_))
    }
}
