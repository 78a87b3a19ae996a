//! Wavefront integration on the GPU (`integrate.wgsl`), bit-identical to
//! the CPU backend's.
//!
//! The region a frame can change (the window grown by the cutoff's reach
//! plus one) is read from the host's block map with the shared packing
//! and region code (`edtmap_core::region`), worked on in device memory,
//! and written back where it changed, so the host map (which queries read)
//! is the same as the CPU backend's after every frame. The region stays
//! resident on the device between frames while the map's stamp says
//! nothing else changed it. The waves run level by level on the
//! device; the host only reads the frontier's size after every
//! `LEVELS_PER_SUBMIT` levels to know when they are done. Frontier sizes
//! drive the dispatches through indirect arguments the device writes
//! itself, so an empty level costs almost nothing.

use crate::context::GpuContext;
use crate::dispatch::{groups_1d, storage_entry, uniform_entry, Kernel};
use edtmap_core::region::{read_region_except, write_back_offsets, Packing, Region, WriteBack, FAR};
use edtmap_core::{
    BackendError, BlockKey, Cutoff, EdtField, EdtMap, IntegrationReport, LocalVolume, MapStamp, WaveCounts, NO_OFFSET,
};

/// Levels encoded per submission before the host checks for the end.
const LEVELS_PER_SUBMIT: usize = 4;

/// Frontiers of at most this many voxels are lowered by `lower_local`,
/// in workgroup memory (`LOCAL_CAP` in the shader).
const LOCAL_CAP: u32 = 1024;

/// Words of the control buffer (`C_*` in the shader).
const CTRL_WORDS: usize = 16;
const C_FRONT: usize = 3;
const C_STAMP: usize = 4;
const C_LEVELS: usize = 5;
const C_RAISED: usize = 6;
const C_KEPT: usize = 7;
const C_SEEDS: usize = 8;
const C_LOWERED: usize = 9;
const C_DIRTY: usize = 10;

/// Indirect argument offsets, bytes (`A_*` in the shader, times 4).
const A_DOWN: u64 = 0;
const A_UP: u64 = 12;
const A_FRONT: u64 = 24;
const A_NEXT: u64 = 36;
const A_GATHER: u64 = 48;

/// Uniform parameters (`IntegrateParams` in the shader).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct IntegrateParams {
    region: [u32; 4],
    window: [u32; 4],
    source: [u32; 4],
    win_in_region: u32,
    shift: u32,
    max_dist_sq: u32,
    n_offsets: u32,
    delta: [i32; 4],
    blocks: [u32; 4],
    o8: [u32; 4],
    fresh: [u32; 4],
    offsets: [[i32; 4]; 26],
}

/// One frame's region and the kernels' parameters for it.
struct FrameJob {
    packing: Packing,
    params: IntegrateParams,
    /// Whether the device already held the previous region.
    resident: bool,
    /// Blocks of the region per axis, the lowest block key, and all blocks.
    nb3: [u32; 3],
    key_lo: [i32; 3],
    nb: usize,
}

/// The integration kernels and their buffers, reused across frames.
#[derive(Debug)]
pub struct GpuIntegrator {
    ctx: GpuContext,
    k: Kernels,
    layout: wgpu::BindGroupLayout,
    args_group: wgpu::BindGroup,
    params: wgpu::Buffer,
    args: wgpu::Buffer,
    ctrl: wgpu::Buffer,
    ctrl_staging: wgpu::Buffer,
    bufs: Option<Buffers>,
    /// The next frontier stamp (stamps only grow, so `mark` is never cleared).
    stamp: u32,
    /// The region's packed values as read from the map, region order (only
    /// the newly covered ones when the region is resident), to upload.
    old: Vec<u64>,
    /// The region whose values the device holds in `cur`, equal to the
    /// host map's there while the map's stamp is `seen`.
    resident: Option<Region>,
    /// The map's stamp after this integrator last wrote it.
    seen: Option<MapStamp>,
    /// The newly covered voxels' (index, S, D, 0), uploaded when resident.
    fresh: Vec<[u32; 4]>,
    /// A host batch EDT's pairs, as uploaded.
    pairs_up: Vec<u32>,
    /// The changed blocks (indices in the region's blocks) and their
    /// voxels' (old S, old D, new S, new D), as read back.
    changed_list: Vec<u32>,
    changed_pairs: Vec<u32>,
}

/// Where the window's batch EDT comes from.
#[derive(Debug, Clone, Copy)]
enum WindowBatch<'a> {
    /// The host's field, uploaded as pairs.
    Host(&'a EdtField),
    /// A device buffer of pairs.
    Device(&'a wgpu::Buffer),
}

#[derive(Debug)]
struct Kernels {
    merge: Kernel,
    prep_seeds: Kernel,
    seed_down: Kernel,
    seed_up: Kernel,
    prep_next: Kernel,
    snapshot: Kernel,
    advance_seeds: Kernel,
    advance: Kernel,
    lower_dist: Kernel,
    reset_source: Kernel,
    lower_source: Kernel,
    lower_local: Kernel,
    shift: Kernel,
    scatter: Kernel,
    diff: Kernel,
    compact: Kernel,
    prep_gather: Kernel,
    gather: Kernel,
}

/// Device buffers for regions of up to `region` voxels and windows of up
/// to `window` voxels.
#[derive(Debug)]
struct Buffers {
    region: usize,
    window: usize,
    blocks: usize,
    old: wgpu::Buffer,
    batch: wgpu::Buffer,
    blk: wgpu::Buffer,
    pairs: wgpu::Buffer,
    fresh: wgpu::Buffer,
    staging: wgpu::Buffer,
    group: wgpu::BindGroup,
}

impl GpuIntegrator {
    /// Compiles the kernels once for `ctx`.
    pub fn new(ctx: &GpuContext) -> Result<Self, BackendError> {
        ctx.scoped(|| {
            let dev = &ctx.device;
            let module = dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("integrate.wgsl"),
                source: wgpu::ShaderSource::Wgsl(include_str!("integrate.wgsl").into()),
            });
            let mut entries = vec![uniform_entry(0, false)];
            entries.extend((1..=10).map(|b| storage_entry(b, b == 3 || b == 10)));
            let layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("integrate"),
                entries: &entries,
            });
            let args_layout = dev.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("integrate args"),
                entries: &[storage_entry(0, false)],
            });
            let buffer = |label, size, usage| ctx.buffer(label, size, usage);
            let params = buffer(
                "integrate params",
                std::mem::size_of::<IntegrateParams>() as u64,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            );
            let args = buffer("integrate args", 60, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT);
            let ctrl_bytes = 4 * CTRL_WORDS as u64;
            let ctrl = buffer(
                "integrate ctrl",
                ctrl_bytes,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            );
            let ctrl_staging = buffer(
                "integrate ctrl staging",
                ctrl_bytes,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            );
            let args_group = ctx.bind_group("integrate args", &args_layout, &[args.as_entire_binding()]);
            let plain = |entry| Kernel::new(ctx, &module, &layout, entry);
            let prep = |entry| Kernel::with_layouts(ctx, &module, &[&layout, &args_layout], entry);
            let k = Kernels {
                merge: plain("merge"),
                prep_seeds: prep("prep_seeds"),
                seed_down: plain("seed_down"),
                seed_up: plain("seed_up"),
                prep_next: prep("prep_next"),
                snapshot: plain("snapshot"),
                advance_seeds: prep("advance_seeds"),
                advance: prep("advance"),
                lower_dist: plain("lower_dist"),
                reset_source: plain("reset_source"),
                lower_source: plain("lower_source"),
                lower_local: prep("lower_local"),
                shift: plain("shift"),
                scatter: plain("scatter"),
                diff: plain("diff"),
                compact: plain("compact"),
                prep_gather: prep("prep_gather"),
                gather: plain("gather"),
            };
            GpuIntegrator {
                ctx: ctx.clone(),
                k,
                layout,
                args_group,
                params,
                args,
                ctrl,
                ctrl_staging,
                bufs: None,
                stamp: 1,
                old: Vec::new(),
                resident: None,
                seen: None,
                fresh: Vec::new(),
                pairs_up: Vec::new(),
                changed_list: Vec::new(),
                changed_pairs: Vec::new(),
            }
        })
    }

    /// Merges `batch`, the batch EDT of `window`, into `map` (see the
    /// module docs).
    pub fn run(
        &mut self,
        map: &mut EdtMap,
        window: &LocalVolume,
        batch: &EdtField,
        cutoff: Cutoff,
        offsets: &[[i32; 3]],
    ) -> Result<IntegrationReport, BackendError> {
        if batch.dims() != window.dims {
            return Err(BackendError::Device(format!(
                "batch EDT of {:?} voxels for a window of {:?}",
                batch.dims(),
                window.dims
            )));
        }
        self.merge(map, window, WindowBatch::Host(batch), cutoff, offsets)
    }

    /// [`Self::run`] with the window's batch EDT in `pairs`, a device
    /// buffer of (squared distance, nearest) pairs in the window's voxel
    /// order, as [`crate::GpuEdt`] leaves it: copied on the device, never
    /// read back.
    pub(crate) fn run_resident(
        &mut self,
        map: &mut EdtMap,
        window: &LocalVolume,
        pairs: &wgpu::Buffer,
        cutoff: Cutoff,
        offsets: &[[i32; 3]],
    ) -> Result<IntegrationReport, BackendError> {
        self.merge(map, window, WindowBatch::Device(pairs), cutoff, offsets)
    }

    fn merge(
        &mut self,
        map: &mut EdtMap,
        window: &LocalVolume,
        batch: WindowBatch<'_>,
        cutoff: Cutoff,
        offsets: &[[i32; 3]],
    ) -> Result<IntegrationReport, BackendError> {
        if self.seen != Some(map.stamp()) {
            // Changed by other means (another backend, fixed obstacles
            // laid down, another map): what the device holds is stale.
            self.resident = None;
        }
        if offsets.len() > 26 {
            return Err(BackendError::Device(format!("{} neighbour offsets, at most 26", offsets.len())));
        }
        let job = self.prepare(map, window, cutoff, offsets)?;
        self.merge_and_seed(&job, window.len(), batch)?;
        self.lower()?;
        let counts = self.read_changes(&job)?;
        let mut written = self.write_changes(map, &job, counts[C_DIRTY] as usize);
        written.changed_blocks.sort_unstable();
        self.resident = Some(job.packing.region);
        self.seen = Some(map.stamp());
        let waves = WaveCounts {
            raised: counts[C_RAISED] as usize,
            kept_outside: counts[C_KEPT] as usize,
            seeds: counts[C_SEEDS] as usize,
            levels: counts[C_LEVELS] as usize,
            lowered: counts[C_LOWERED] as usize,
        };
        Ok(written.into_report(job.packing.region.len(), waves))
    }

    /// Sizes the buffers for the frame's region, reads the region's values
    /// from `map` (only the newly covered voxels when it is resident) and
    /// sets the kernels' parameters.
    fn prepare(
        &mut self,
        map: &EdtMap,
        window: &LocalVolume,
        cutoff: Cutoff,
        offsets: &[[i32; 3]],
    ) -> Result<FrameJob, BackendError> {
        let packing = Packing::new(Region::around(window, cutoff.reach + 1), cutoff)?;
        let region = packing.region;
        let (r, w) = (region.len(), window.len());
        let key_lo = region.origin.map(|o| o.div_euclid(8));
        let key_hi = [0, 1, 2].map(|a| (region.origin[a] + region.dims[a] as i32 - 1).div_euclid(8));
        let nb3 = [0, 1, 2].map(|a| (key_hi[a] - key_lo[a] + 1) as u32);
        let nb = nb3.iter().map(|&n| n as usize).product::<usize>();
        // Until this frame is written back, the device holds nothing valid.
        let resident = self.resident.take().filter(|prev| prev.dims == region.dims);
        let resident = if self.ensure_buffers(r, w, nb)? { None } else { resident };
        read_region_except(map, &packing, resident.as_ref(), &mut self.old);
        // With the region resident, only the newly covered voxels go up.
        self.fresh.clear();
        if let Some(prev) = &resident {
            for_fresh(&region, prev, |i| {
                self.fresh.push([i as u32, self.old[i] as u32, (self.old[i] >> 32) as u32, 0])
            });
        }
        let delta = match resident {
            Some(prev) => [
                region.origin[0] - prev.origin[0],
                region.origin[1] - prev.origin[1],
                region.origin[2] - prev.origin[2],
                1,
            ],
            None => [0; 4],
        };
        let mut params = IntegrateParams {
            region: dims4(region.dims, r),
            window: dims4(window.dims, w),
            source: dims4(packing.source.dims, packing.source.len()),
            win_in_region: (cutoff.reach + 1) as u32,
            shift: cutoff.reach as u32,
            max_dist_sq: cutoff.max_dist_sq,
            n_offsets: offsets.len() as u32,
            delta,
            blocks: [nb3[0], nb3[1], nb3[2], nb as u32],
            fresh: [self.fresh.len() as u32, 0, 0, 0],
            o8: [0, 1, 2, 3].map(|a| if a < 3 { (region.origin[a] - key_lo[a] * 8) as u32 } else { 0 }),
            offsets: [[0; 4]; 26],
        };
        for (slot, o) in params.offsets.iter_mut().zip(offsets) {
            *slot = [o[0], o[1], o[2], 0];
        }
        Ok(FrameJob { packing, params, resident: resident.is_some(), nb3, key_lo, nb })
    }

    /// Uploads the frame and runs the merge and the seeding of the waves.
    fn merge_and_seed(&mut self, job: &FrameJob, w: usize, batch: WindowBatch<'_>) -> Result<(), BackendError> {
        let FrameJob { params, nb, .. } = job;
        let (r, nb) = (job.packing.region.len(), *nb);
        if let WindowBatch::Host(field) = batch {
            self.pairs_up.clear();
            self.pairs_up.extend(field.dist_sq_vox().iter().zip(field.nearest()).flat_map(|(&d, &s)| [d, s]));
        }
        let mut ctrl = [0u32; CTRL_WORDS];
        ctrl[C_STAMP] = self.stamp;
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        let k = &self.k;
        let one = [&bufs.group];
        let with_args = [&bufs.group, &self.args_group];
        self.ctx.scoped(|| {
            let q = &self.ctx.queue;
            q.write_buffer(&self.params, 0, bytemuck::bytes_of(params));
            q.write_buffer(&self.ctrl, 0, bytemuck::cast_slice(&ctrl));
            if job.resident {
                if !self.fresh.is_empty() {
                    q.write_buffer(&bufs.fresh, 0, bytemuck::cast_slice(&self.fresh));
                }
            } else {
                q.write_buffer(&bufs.old, 0, bytemuck::cast_slice(&self.old));
            }
            let mut enc =
                self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("integrate") });
            match batch {
                WindowBatch::Host(_) => q.write_buffer(&bufs.batch, 0, bytemuck::cast_slice(&self.pairs_up)),
                WindowBatch::Device(pairs) => enc.copy_buffer_to_buffer(pairs, 0, &bufs.batch, 0, 8 * w as u64),
            }
            enc.clear_buffer(&bufs.blk, 0, Some(8 * nb as u64));
            {
                let mut pass = self.ctx.pass(&mut enc, "merge and seed");
                if job.resident {
                    k.shift.dispatch(&mut pass, &one, groups_1d(r as u64));
                    if !self.fresh.is_empty() {
                        k.scatter.dispatch(&mut pass, &one, groups_1d(self.fresh.len() as u64));
                    }
                }
                k.merge.dispatch(&mut pass, &one, groups_1d(r as u64));
                k.prep_seeds.dispatch(&mut pass, &with_args, [1, 1, 1]);
                k.seed_down.dispatch_indirect(&mut pass, &one, &self.args, A_DOWN);
                k.seed_up.dispatch_indirect(&mut pass, &one, &self.args, A_UP);
                self.encode_advance(&mut pass, bufs, &k.advance_seeds);
            }
            q.submit([enc.finish()]);
        })?;
        Ok(())
    }

    /// Lowers level after level until the frontier is empty.
    fn lower(&mut self) -> Result<(), BackendError> {
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        let k = &self.k;
        let one = [&bufs.group];
        let with_args = [&bufs.group, &self.args_group];
        let mut counts = self.read_ctrl()?;
        while counts[C_FRONT] > 0 {
            self.ctx.scoped(|| {
                let mut enc =
                    self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("lower") });
                {
                    let mut pass = self.ctx.pass(&mut enc, "lower");
                    // A small frontier goes to one workgroup, which runs
                    // levels until the waves end or a frontier outgrows its
                    // memory; a large one runs level by level across the
                    // device, then hands back to the workgroup.
                    if counts[C_FRONT] <= LOCAL_CAP {
                        k.lower_local.dispatch(&mut pass, &with_args, [1, 1, 1]);
                    } else {
                        for _ in 0..LEVELS_PER_SUBMIT {
                            k.lower_dist.dispatch_indirect(&mut pass, &one, &self.args, A_FRONT);
                            k.prep_next.dispatch(&mut pass, &with_args, [1, 1, 1]);
                            k.reset_source.dispatch_indirect(&mut pass, &one, &self.args, A_NEXT);
                            k.lower_source.dispatch_indirect(&mut pass, &one, &self.args, A_FRONT);
                            self.encode_advance(&mut pass, bufs, &k.advance);
                        }
                        k.lower_local.dispatch(&mut pass, &with_args, [1, 1, 1]);
                    }
                }
                self.ctx.queue.submit([enc.finish()]);
            })?;
            counts = self.read_ctrl()?;
        }
        self.stamp = counts[C_STAMP];
        Ok(())
    }

    /// Lists the blocks holding a changed voxel and reads their `(old,
    /// new)` pairs back; returns the control words (counters).
    fn read_changes(&mut self, job: &FrameJob) -> Result<[u32; CTRL_WORDS], BackendError> {
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        let k = &self.k;
        let one = [&bufs.group];
        let with_args = [&bufs.group, &self.args_group];
        let (r, nb) = (job.packing.region.len(), job.nb);
        self.ctx.scoped(|| {
            let mut enc =
                self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("changes") });
            {
                let mut pass = self.ctx.pass(&mut enc, "changes");
                k.diff.dispatch(&mut pass, &one, groups_1d(r as u64));
                k.compact.dispatch(&mut pass, &one, groups_1d(nb as u64));
                k.prep_gather.dispatch(&mut pass, &with_args, [1, 1, 1]);
                k.gather.dispatch_indirect(&mut pass, &one, &self.args, A_GATHER);
            }
            self.ctx.queue.submit([enc.finish()]);
        })?;
        let counts = self.read_ctrl()?;
        let dirty = counts[C_DIRTY] as usize;
        let (list_bytes, pairs_at) = (4 * dirty as u64, pairs_offset(nb));
        let pair_bytes = 8 * 512 * dirty as u64;
        let (list, pairs) = (&mut self.changed_list, &mut self.changed_pairs);
        list.resize(dirty, 0);
        pairs.resize(2 * 512 * dirty, 0);
        if dirty > 0 {
            self.ctx.scoped(|| {
                let mut enc = self
                    .ctx
                    .device
                    .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("read changes") });
                enc.copy_buffer_to_buffer(&bufs.blk, 4 * nb as u64, &bufs.staging, 0, list_bytes);
                enc.copy_buffer_to_buffer(&bufs.pairs, 0, &bufs.staging, pairs_at, pair_bytes);
                self.ctx.queue.submit([enc.finish()]);
            })?;
            self.ctx.read_back(&bufs.staging, pairs_at + pair_bytes, |b| {
                crate::edt::copy_words(&b[..list_bytes as usize], list);
                crate::edt::copy_words(&b[pairs_at as usize..], pairs);
            })?;
        }
        Ok(counts)
    }

    /// Writes the changed blocks' new pairs back into `map` with the shared
    /// write-back, against the old values the map holds.
    fn write_changes(&mut self, map: &mut EdtMap, job: &FrameJob, dirty: usize) -> WriteBack {
        let FrameJob { packing, nb3, key_lo, .. } = job;
        let keys: Vec<BlockKey> = self.changed_list[..dirty]
            .iter()
            .map(|&b| {
                let b = b as usize;
                let bc = [b % nb3[0] as usize, (b / nb3[0] as usize) % nb3[1] as usize, b / (nb3[0] * nb3[1]) as usize];
                BlockKey([0, 1, 2].map(|a| key_lo[a] + bc[a] as i32))
            })
            .collect();
        let pairs = &self.changed_pairs;
        let source = &packing.source;
        let new = |k: usize, out: &mut [[i16; 3]; edtmap_core::BLOCK_VOXELS]| {
            for (off, o) in out.iter_mut().enumerate() {
                let at = 2 * (k * edtmap_core::BLOCK_VOXELS + off);
                *o = if (u64::from(pairs[at + 1]) << 32) | u64::from(pairs[at]) == FAR {
                    NO_OFFSET
                } else {
                    let (v, obstacle) = (keys[k].voxel(off), source.world(source.coords(pairs[at] as usize)));
                    let c = [0, 1, 2].map(|a| i16::try_from(obstacle.0[a] - v.0[a]).ok().filter(|&c| c != i16::MIN));
                    // As `EdtBlock::put` stores a value out of an offset's range.
                    match c {
                        [Some(x), Some(y), Some(z)] => [x, y, z],
                        _ => NO_OFFSET,
                    }
                };
            }
        };
        write_back_offsets(map, packing, &keys, new)
    }

    fn encode_advance(&self, pass: &mut wgpu::ComputePass<'_>, bufs: &Buffers, advance: &Kernel) {
        self.k.prep_next.dispatch(pass, &[&bufs.group, &self.args_group], [1, 1, 1]);
        self.k.snapshot.dispatch_indirect(pass, &[&bufs.group], &self.args, A_NEXT);
        advance.dispatch(pass, &[&bufs.group, &self.args_group], [1, 1, 1]);
    }

    /// The control words, once the device is done with them.
    fn read_ctrl(&self) -> Result<[u32; CTRL_WORDS], BackendError> {
        let bytes = 4 * CTRL_WORDS as u64;
        self.ctx.scoped(|| {
            let mut enc =
                self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("ctrl") });
            enc.copy_buffer_to_buffer(&self.ctrl, 0, &self.ctrl_staging, 0, bytes);
            self.ctx.queue.submit([enc.finish()]);
        })?;
        let mut out = [0u32; CTRL_WORDS];
        self.ctx.read_back(&self.ctrl_staging, bytes, |b| crate::edt::copy_words(b, &mut out))?;
        Ok(out)
    }

    /// Allocates buffers for a region of `r` voxels in `nb` blocks and a
    /// window of `w` voxels unless those in place are large enough;
    /// returns whether it allocated (the device then holds no region).
    fn ensure_buffers(&mut self, r: usize, w: usize, nb: usize) -> Result<bool, BackendError> {
        if self.bufs.as_ref().is_some_and(|b| b.region >= r && b.window >= w && b.blocks >= nb) {
            return Ok(false);
        }
        // Grow each to at least what it was, so alternating sizes do not
        // reallocate every frame.
        let (r, w, nb) =
            self.bufs.as_ref().map_or((r, w, nb), |b| (b.region.max(r), b.window.max(w), b.blocks.max(nb)));
        self.bufs = None;
        let (r64, w64, nb64) = (r as u64, w as u64, nb as u64);
        let limits = [
            ("the integration's frontier", 16 * r64),
            ("the integration's queues", 12 * r64),
            ("the batch EDT upload", 8 * w64),
            ("the changed blocks' values", 8 * 512 * nb64),
        ];
        for (what, bytes) in limits {
            self.ctx.check_buffer(what, bytes)?;
        }
        let bufs = self.ctx.scoped(|| {
            let buffer = |label, size, usage| self.ctx.buffer(label, size, usage);
            let storage = wgpu::BufferUsages::STORAGE;
            let (copy_dst, copy_src) = (wgpu::BufferUsages::COPY_DST, wgpu::BufferUsages::COPY_SRC);
            let old = buffer("integrate old", 8 * r64, storage | copy_dst);
            let cur = buffer("integrate cur", 8 * r64, storage);
            let batch = buffer("integrate batch", 8 * w64, storage | copy_dst);
            // Zeroed at creation: no stamp is 0.
            let mark = buffer("integrate mark", 4 * r64, storage);
            let queues = buffer("integrate queues", 12 * r64, storage);
            let front = buffer("integrate front", 16 * r64, storage);
            let blk = buffer("integrate blocks", 8 * nb64, storage | copy_dst | copy_src);
            let pairs = buffer("integrate pairs", 8 * 512 * nb64, storage | copy_src);
            let staging =
                buffer("integrate staging", pairs_offset(nb) + 8 * 512 * nb64, wgpu::BufferUsages::MAP_READ | copy_dst);
            let fresh = buffer("integrate fresh", 16 * r64, storage | copy_dst);
            let list = [&self.params, &old, &cur, &batch, &mark, &queues, &front, &self.ctrl, &blk, &pairs, &fresh];
            let group = self.ctx.bind_group("integrate", &self.layout, &list.map(|b| b.as_entire_binding()));
            Buffers { region: r, window: w, blocks: nb, old, batch, blk, pairs, fresh, staging, group }
        })?;
        self.bufs = Some(bufs);
        Ok(true)
    }
}

/// Calls `f(linear)` for every voxel of `region` outside the world box
/// `prev`, row by row.
fn for_fresh(region: &Region, prev: &Region, mut f: impl FnMut(usize)) {
    let [nx, ny, nz] = region.dims;
    let lo = [0, 1, 2]
        .map(|a| (i64::from(prev.origin[a]) - i64::from(region.origin[a])).clamp(0, region.dims[a] as i64) as usize);
    let hi = [0, 1, 2].map(|a| {
        (i64::from(prev.origin[a]) + prev.dims[a] as i64 - i64::from(region.origin[a])).clamp(0, region.dims[a] as i64)
            as usize
    });
    for z in 0..nz {
        for y in 0..ny {
            let row = nx * (y + ny * z);
            if (lo[1]..hi[1]).contains(&y) && (lo[2]..hi[2]).contains(&z) {
                (0..lo[0]).chain(hi[0].max(lo[0])..nx).for_each(|x| f(row + x));
            } else {
                (0..nx).for_each(|x| f(row + x));
            }
        }
    }
}

/// Where the pairs start in the staging buffer, after the list of up to
/// `nb` changed blocks (16-byte aligned).
fn pairs_offset(nb: usize) -> u64 {
    (4 * nb as u64).div_ceil(16) * 16
}

fn dims4(d: [usize; 3], len: usize) -> [u32; 4] {
    [d[0] as u32, d[1] as u32, d[2] as u32, len as u32]
}
