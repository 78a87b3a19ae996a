//! The GPU backend of edtmap: the pipeline's kernels as wgpu compute
//! shaders in WGSL (each `.wgsl` file beside the module that dispatches
//! it), on Vulkan, Metal or DX12, and on Mesa's lavapipe (software Vulkan)
//! where there is no GPU. Every result is an integer bit-identical to the
//! CPU backend's; the conformance suite (`edtmap-conformance`) checks both.
//!
//! [`GpuBackend::new`] fails with [`BackendError::NoAdapter`] when no
//! adapter exists; a lost device is [`BackendError::DeviceLost`] on the
//! next call, never a hang (every wait has a timeout) or a partial result.
#![warn(missing_docs)]

mod context;
mod dispatch;
mod edt;
mod exact;
mod fuse;
mod integrate;
mod obstacles;
mod pool;
mod project;
mod raycast;

pub use context::GpuContext;
use context::Stage;
pub use edt::GpuEdt;
use exact::GpuExact;
use fuse::GpuFusion;
pub use integrate::GpuIntegrator;
pub use project::GpuProject;
use project::Kept;
pub use raycast::GpuRaycast;

use edtmap_core::exact::{recompute_exact, ExactBuffers};
use edtmap_core::fixed_ray::{cast_fixed, FixedRay};
use edtmap_core::region::{Packing, Region};
use edtmap_core::{
    decide_uncertain, mark_misses, Backend, BackendError, BatchEdt, EdtField, FuseReport, Grid3, IntegrationJob,
    IntegrationReport, IntegrationWork, LocalVolume, LogOdds, Observations, OccupancyMap, ProjectJob, OBS_MISS,
    OBS_NONE,
};
use rayon::prelude::*;

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
    fusion: GpuFusion,
    /// Whether the occupancy stage leaves its codes on the device
    /// ([`Backend::set_deferred_observations`]).
    defer: bool,
    /// The codes the last occupancy stage left on the device, for `fuse`.
    pending: Option<Pending>,
    /// The host-side exact integration, for cutoffs the device's pool
    /// cannot encode.
    exact_host: ExactBuffers,
    /// Observation bytes read back from the device.
    bits: Vec<u8>,
    /// The most voxels one batch EDT of the exact integration may have.
    max_tile_voxels: u64,
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
        let fusion = GpuFusion::new(&ctx)?;
        Ok(GpuBackend {
            ctx,
            edt,
            integrator,
            raycast,
            project,
            exact,
            fusion,
            defer: false,
            pending: None,
            exact_host: ExactBuffers::default(),
            bits: Vec::new(),
            max_tile_voxels: u64::MAX,
        })
    }

    /// Caps the blocks of the global EDT the exact integration keeps
    /// resident on the device (2 KiB each) at `blocks`, and its obstacle
    /// blocks (64 bytes each) too, for a device with little memory to
    /// spare; a frame's region always fits, and the blocks least recently
    /// used make way. By default each pool grows to twice the largest
    /// region (or source box) seen, within the device's buffer limit.
    pub fn limit_resident_blocks(&mut self, blocks: usize) {
        self.exact.limit_pool(blocks);
    }

    /// Caps the voxels of one batch EDT of the exact integration (its
    /// region grown by the cutoff's reach twice) at `voxels`, below the
    /// device's buffer limit, which is the default: larger regions go in
    /// tiles, each exact, so the map is the same.
    pub fn limit_tile_voxels(&mut self, voxels: u64) {
        self.max_tile_voxels = voxels;
    }

    /// Caps the voxels a projection's list of uncertain voxels holds (by
    /// default a sixteenth of the volume, a quarter byte a voxel as the
    /// codes) at `voxels`: a frame with more uncertain voxels reads every
    /// code back and is fused on the host, with the same map. For tests
    /// and devices with little memory.
    pub fn limit_uncertain_list(&mut self, voxels: usize) {
        self.project.limit_list(voxels);
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

/// Observation codes an occupancy stage left on the device.
#[derive(Debug)]
struct Pending {
    volume: LocalVolume,
    /// Where: the ray casting's buffer (true) or the projection's.
    cast: bool,
    /// The voxels the projection left uncertain (the host decided them).
    uncertain: Vec<u32>,
}

impl GpuBackend {
    /// Recomputes `region` of `map` exactly: on the device with its
    /// resident block pool, only the changed blocks read back; on the host
    /// from the device's batch EDT where the pool cannot encode the cutoff.
    /// A region whose source box (grown by the reach) is over the device's
    /// buffer limit goes in tiles that fit, each exact on its own.
    fn recompute(
        &mut self,
        map: &mut edtmap_core::EdtMap,
        obstacles: &edtmap_core::Obstacles<'_>,
        region: Region,
        cutoff: edtmap_core::Cutoff,
    ) -> Result<IntegrationReport, BackendError> {
        let limits = self.ctx.limits();
        // The batch EDT's largest buffers hold 8 bytes per source voxel.
        let max_voxels =
            (limits.max_buffer_size.min(limits.max_storage_buffer_binding_size) / 8).min(self.max_tile_voxels);
        let tile = tile_dims(region.dims, cutoff.reach, max_voxels).ok_or(BackendError::OverLimit {
            what: "the exact integration's batch EDT (even an 8³ tile grown by the cutoff's reach)",
            needed: 8 * (8 + 2 * cutoff.reach as u64).pow(3),
            limit: 8 * max_voxels,
        })?;
        self.exact.reserve(region.block_count());
        let mut total = IntegrationReport::default();
        for z in (0..region.dims[2]).step_by(tile[2]) {
            for y in (0..region.dims[1]).step_by(tile[1]) {
                for x in (0..region.dims[0]).step_by(tile[0]) {
                    let c = [x, y, z];
                    let part = Region {
                        origin: [0, 1, 2].map(|a| region.origin[a] + c[a] as i32),
                        dims: [0, 1, 2].map(|a| tile[a].min(region.dims[a] - c[a])),
                    };
                    let packing = Packing::new(part, cutoff)?;
                    let written = if GpuExact::supports(cutoff.reach) {
                        self.exact.run(&mut self.edt, map, obstacles, &packing)?
                    } else {
                        recompute_exact(&mut self.edt, map, obstacles, &packing, &mut self.exact_host)?
                    };
                    total.voxels_changed += written.voxels_changed;
                    total.change_sum_vox += written.change_sum_vox;
                    total.changed_blocks.extend(written.changed_blocks);
                }
            }
        }
        total.changed_blocks.sort_unstable();
        total.changed_blocks.dedup();
        total.region_voxels = region.len();
        Ok(total)
    }
}

/// Tile dims for a region of `dims` whose tiles, grown by `reach` on every
/// side, hold at most `max_voxels`: the region whole if it fits, else its
/// longest side halved (to whole blocks) until it does; `None` when even
/// an 8³ tile does not fit.
fn tile_dims(dims: [usize; 3], reach: i32, max_voxels: u64) -> Option<[usize; 3]> {
    let grown = |t: [usize; 3]| t.iter().map(|&d| d as u64 + 2 * reach.max(0) as u64).product::<u64>();
    let mut tile = dims;
    while grown(tile) > max_voxels {
        let a = (0..3).max_by_key(|&a| tile[a])?;
        if tile[a] <= 8 {
            return None;
        }
        tile[a] = (tile[a].div_ceil(2)).div_ceil(8) * 8;
    }
    Some(tile)
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

    fn batch_stays_on_device(&self) -> bool {
        true
    }

    fn cast_rays(&mut self, rays: &[FixedRay], q: u32, obs: &Observations) -> Result<(), BackendError> {
        self.ctx.set_stage(Stage::Occupancy);
        self.pending = None;
        if self.defer && self.fusion.fits(obs.volume()) {
            if self.raycast.run_kept(rays, q, obs.volume().dims)? {
                self.pending = Some(Pending { volume: *obs.volume(), cast: true, uncertain: Vec::new() });
            } else {
                cast_fixed(obs, rays, q);
            }
            return Ok(());
        }
        if self.raycast.run(rays, q, obs.volume().dims, &mut self.bits)? {
            obs.load_bits(&self.bits);
        } else {
            cast_fixed(obs, rays, q);
        }
        Ok(())
    }

    fn project_volume(&mut self, job: &ProjectJob<'_>, obs: &Observations) -> Result<(), BackendError> {
        self.ctx.set_stage(Stage::Occupancy);
        self.pending = None;
        if self.defer && self.fusion.fits(&job.volume) {
            match self.project.run_kept(job, &mut self.bits)? {
                Some(Kept::Codes) => {
                    // Too many uncertain voxels to list: fused on the host.
                    decide_uncertain(job, &mut self.bits);
                    obs.load_bits(&self.bits);
                }
                Some(Kept::Uncertain(uncertain)) => {
                    // The host decides the uncertain voxels, as
                    // `decide_uncertain` does, and marks the misses.
                    let geom = job.voxel_to_sensor();
                    let [nx, ny, _] = job.volume.dims;
                    uncertain.par_iter().for_each(|&i| {
                        let i = i as usize;
                        let c = [i % nx, (i / nx) % ny, i / (nx * ny)];
                        if job.is_miss(&geom, c) {
                            obs.mark(c, i, OBS_MISS);
                        }
                    });
                    self.pending = Some(Pending { volume: job.volume, cast: false, uncertain });
                }
                None => mark_misses(obs, job),
            }
            return Ok(());
        }
        if self.project.run(job, &mut self.bits)? {
            decide_uncertain(job, &mut self.bits);
            obs.load_bits(&self.bits);
        } else {
            mark_misses(obs, job);
        }
        Ok(())
    }

    fn set_deferred_observations(&mut self, defer: bool) {
        self.defer = defer;
        self.pending = None;
    }

    fn fuse(&mut self, map: &mut OccupancyMap, obs: &Observations, lo: &LogOdds) -> Result<FuseReport, BackendError> {
        let Some(pending) = self.pending.take() else { return Ok(edtmap_core::fuse(map, obs, lo)) };
        if pending.volume != *obs.volume() {
            return Err(BackendError::Device(format!(
                "observations of {:?} to fuse, the device's are of {:?}",
                obs.volume(),
                pending.volume
            )));
        }
        self.ctx.set_stage(Stage::Occupancy);
        let codes = if pending.cast { self.raycast.codes() } else { self.project.codes() };
        let codes = codes.ok_or_else(|| BackendError::Device("observation codes missing".into()))?;
        // What the host marked (a projection's hits, the uncertain voxels
        // it found missed), then the uncertain voxels it left unobserved.
        let mut fixes: Vec<u32> =
            obs.observed().into_iter().map(|(i, code)| ((i as u32) << 2) | u32::from(code)).collect();
        fixes.extend(pending.uncertain.iter().filter(|&&i| obs.get(i as usize) == OBS_NONE).map(|&i| i << 2));
        self.fusion.run(codes, &fixes, map, obs.volume(), lo)
    }

    fn integrates_planar(&self) -> bool {
        false
    }

    fn integrate(&mut self, job: IntegrationJob<'_>) -> Result<IntegrationReport, BackendError> {
        self.ctx.set_stage(Stage::Integrate);
        let IntegrationJob { map, obstacles, cutoff, work } = job;
        if cutoff.planar {
            // The device's passes measure distances in three dimensions.
            return Err(BackendError::Core(edtmap_core::CoreError::Unsupported(
                "a planar map ([global] planar = true) on the GPU backend; map it with --backend cpu".to_string(),
            )));
        }
        match work {
            IntegrationWork::Wavefront { window, batch, offsets } => {
                self.integrator.run(map, window, batch, cutoff, offsets)
            }
            IntegrationWork::WavefrontMask { window, mask, offsets } => {
                if mask.dims() != window.dims {
                    return Err(BackendError::Device(format!(
                        "obstacle mask of {:?} voxels for a window of {:?}",
                        mask.dims(),
                        window.dims
                    )));
                }
                // The window's batch EDT stays on the device, where the
                // merge copies it from.
                self.ctx.set_stage(Stage::BatchEdt);
                let mut enc = self
                    .ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("window edt") });
                self.edt.encode(mask, &mut enc)?;
                self.ctx.scoped(|| self.ctx.queue.submit([enc.finish()]))?;
                self.ctx.set_stage(Stage::Integrate);
                let pairs = self.edt.output().ok_or_else(|| BackendError::Device("EDT buffers missing".into()))?;
                self.integrator.run_resident(map, window, pairs, cutoff, offsets)
            }
            IntegrationWork::Changes { blocks } => {
                // Exact over every voxel within the cutoff of the changed
                // blocks: the same map as the CPU's line-by-line update.
                let Some(region) = Region::bounding(blocks) else { return Ok(IntegrationReport::default()) };
                self.recompute(map, &obstacles, region.grown(cutoff.reach), cutoff)
            }
            IntegrationWork::Recompute { region } => self.recompute(map, &obstacles, region, cutoff),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::tile_dims;

    #[test]
    fn tiles_fit_and_cover_in_whole_blocks() {
        assert_eq!(tile_dims([100, 50, 20], 5, u64::MAX), Some([100, 50, 20]));
        let t = tile_dims([360, 360, 220], 40, 16 << 20).expect("fits");
        assert!(t.iter().map(|&d| d as u64 + 80).product::<u64>() <= 16 << 20, "{t:?}");
        assert!(t.iter().all(|&d| d % 8 == 0), "{t:?}");
        assert_eq!(tile_dims([64, 64, 64], 40, 1000), None);
    }
}
