//! Fusion on the GPU (`fuse.wgsl`), bit-identical to the CPU's
//! [`edtmap_core::fuse`].
//!
//! The device keeps the log-odds of the window's blocks in a pool (2 KiB a
//! block), from frame to frame: as the window scrolls, only blocks it newly
//! covers go up, and only those the map holds (a block the map lacks is
//! cleared on the device). Each slot remembers which version of the map's
//! block it holds ([`edtmap_core::BlockMap::shared`]): a block the host changed by other
//! means (a fusion on the CPU, a loaded map, a cleared region) goes up
//! again, so the pool cannot go stale.
//!
//! A frame's observation codes stay where ray casting or the projection
//! left them; the host's corrections (a projection's hits and the uncertain
//! voxels it decided) go up grouped by block. One dispatch fuses, taking a
//! voxel's correction in place of its code, and the blocks whose values
//! changed come back for the host's map: two round trips, every volume
//! block's counts, then the changed blocks' values.

use crate::context::GpuContext;
use crate::dispatch::{groups_1d, storage_entry, uniform_entry, Kernel, GROUP};
use crate::edt::as_words;
use crate::pool::{runs, Pool};
use edtmap_core::{
    BackendError, BlockKey, FuseReport, LocalVolume, LogOdds, OccupancyBlock, OccupancyMap, SharedBlock, BLOCK_VOXELS,
    UNOBSERVED,
};

/// A pool word's bits are the log-odds' bits XOR this (the bits of
/// [`UNOBSERVED`]): a word of 0 is a voxel never observed.
const UNOBSERVED_BITS: u32 = 0xff80_0000;
const _: () = assert!(UNOBSERVED.to_bits() == UNOBSERVED_BITS);

/// Bytes of one pool block.
const BLOCK_BYTES: u64 = 4 * BLOCK_VOXELS as u64;

/// The fewest pool slots allocated.
const MIN_SLOTS: usize = 1024;

/// Volumes from this many voxels on are fused on the host: a correction
/// holds a voxel's index times four.
pub(crate) const MAX_VOXELS: usize = 1 << 30;

/// Uniform parameters (`FuseParams` in the shader).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FuseParams {
    dims: [u32; 4],
    o8: [u32; 4],
    blocks: [u32; 4],
    lo: [f32; 4],
    occupied: [u32; 4],
}

/// The fusion's kernels, its block pool and its buffers.
#[derive(Debug)]
pub(crate) struct GpuFusion {
    ctx: GpuContext,
    fuse: Kernel,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    pool: Option<Pool>,
    /// Per slot: the version of the map's block the device holds (`None`:
    /// a block the map lacked, all unobserved).
    held: Vec<Option<SharedBlock<OccupancyBlock>>>,
    bufs: Option<Buffers>,
    /// Frames run, for the pool's least-recently-used order.
    frame: u64,
    upload: Vec<u32>,
    slot_table: Vec<u32>,
    cleared: Vec<u32>,
    /// The corrections grouped by block, as the shader reads them.
    fixes: Vec<u32>,
}

/// Per-frame buffers, for volumes of up to `blocks` blocks and
/// `corrections` corrections.
#[derive(Debug)]
struct Buffers {
    blocks: usize,
    corrections: usize,
    slots: wgpu::Buffer,
    fixes: wgpu::Buffer,
    counts: wgpu::Buffer,
    counts_staging: wgpu::Buffer,
    staging: wgpu::Buffer,
}

impl GpuFusion {
    /// Compiles the kernels once for `ctx`.
    pub(crate) fn new(ctx: &GpuContext) -> Result<Self, BackendError> {
        ctx.scoped(|| {
            let dev = &ctx.device;
            let module = dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("fuse.wgsl"),
                source: wgpu::ShaderSource::Wgsl(include_str!("fuse.wgsl").into()),
            });
            let mut entries = vec![uniform_entry(0, false)];
            entries.extend((1..=5).map(|b| storage_entry(b, b <= 3)));
            let layout = dev
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("fuse"), entries: &entries });
            GpuFusion {
                ctx: ctx.clone(),
                fuse: Kernel::new(ctx, &module, &layout, "fuse"),
                params: ctx.buffer(
                    "fuse params",
                    std::mem::size_of::<FuseParams>() as u64,
                    wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                ),
                layout,
                pool: None,
                held: Vec::new(),
                bufs: None,
                frame: 0,
                upload: Vec::new(),
                slot_table: Vec::new(),
                cleared: Vec::new(),
                fixes: Vec::new(),
            }
        })
    }

    /// Fuses the codes in `codes` (two bits per voxel of `vol`), those of
    /// the voxels in `corrections` (voxel index × 4 + code, each voxel
    /// once) replaced, into `map` with `lo`. On a failure the pool is dropped and
    /// the map is as it was.
    pub(crate) fn run(
        &mut self,
        codes: &wgpu::Buffer,
        corrections: &[u32],
        map: &mut OccupancyMap,
        vol: &LocalVolume,
        lo: &LogOdds,
    ) -> Result<FuseReport, BackendError> {
        let result = self.frame(codes, corrections, map, vol, lo);
        if result.is_err() {
            self.forget();
        }
        result
    }

    /// Whether the device can fuse `vol`: its blocks fit one pool, its
    /// voxels a correction.
    pub(crate) fn fits(&self, vol: &LocalVolume) -> bool {
        let limits = self.ctx.limits();
        let max = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        vol.len() < MAX_VOXELS && (vol.region().block_count() as u64).next_power_of_two() * BLOCK_BYTES <= max
    }

    /// Drops every resident block.
    pub(crate) fn forget(&mut self) {
        if let Some(pool) = &mut self.pool {
            pool.clear();
        }
        self.held.iter_mut().for_each(|h| *h = None);
    }

    fn frame(
        &mut self,
        codes: &wgpu::Buffer,
        corrections: &[u32],
        map: &mut OccupancyMap,
        vol: &LocalVolume,
        lo: &LogOdds,
    ) -> Result<FuseReport, BackendError> {
        if vol.len() >= MAX_VOXELS {
            return Err(BackendError::Device(format!("a volume of {} voxels for the device's fusion", vol.len())));
        }
        self.frame += 1;
        let keys = vol.blocks();
        let nb = keys.len();
        if nb == 0 {
            return Ok(FuseReport::default());
        }
        let first = keys[0].first_voxel().0;
        let o8 = [0, 1, 2].map(|a| (vol.origin.0[a] - first[a]) as u32);
        let nb3 = [0, 1, 2].map(|a| (o8[a] + vol.dims[a] as u32).div_ceil(8));
        self.group_fixes(corrections, vol, o8, nb3, nb)?;
        self.ensure_buffers(nb, self.fixes.len())?;
        self.assign_slots(map, &keys)?;
        let key = |bits: u32| if bits & 0x8000_0000 != 0 { !bits } else { bits | 0x8000_0000 };
        let params = FuseParams {
            dims: [vol.dims[0] as u32, vol.dims[1] as u32, vol.dims[2] as u32, vol.len() as u32],
            o8: [o8[0], o8[1], o8[2], 0],
            blocks: [nb3[0], nb3[1], nb3[2], nb as u32],
            lo: [lo.hit, lo.miss, lo.min, lo.max],
            occupied: [key(lo.occupied.to_bits()), 0, 0, 0],
        };
        let pool = self.pool.as_ref().ok_or_else(|| BackendError::Device("fusion pool missing".into()))?;
        let bufs = self.bufs.as_ref().ok_or_else(|| BackendError::Device("fusion buffers missing".into()))?;
        let counts_bytes = 4 * nb as u64;
        self.ctx.scoped(|| {
            let resources = [&self.params, codes, &bufs.fixes, &bufs.slots, &pool.buffer, &bufs.counts]
                .map(|b| b.as_entire_binding());
            let group = self.ctx.bind_group("fuse", &self.layout, &resources);
            let q = &self.ctx.queue;
            q.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
            q.write_buffer(&bufs.slots, 0, bytemuck::cast_slice(&self.slot_table));
            q.write_buffer(&bufs.fixes, 0, bytemuck::cast_slice(&self.fixes));
            let mut enc =
                self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("fuse") });
            for (first, len) in runs(&self.cleared) {
                enc.clear_buffer(&pool.buffer, u64::from(first) * BLOCK_BYTES, Some(u64::from(len) * BLOCK_BYTES));
            }
            enc.clear_buffer(&bufs.counts, 0, Some(counts_bytes));
            {
                let mut pass = self.ctx.pass(&mut enc, "fuse");
                // One workgroup per block.
                self.fuse.dispatch(&mut pass, &[&group], groups_1d(nb as u64 * GROUP));
            }
            enc.copy_buffer_to_buffer(&bufs.counts, 0, &bufs.counts_staging, 0, counts_bytes);
            q.submit([enc.finish()]);
        })?;

        // The observed blocks, in the volume's block order as the CPU
        // lists them, with their counts.
        let mut listed: Vec<(u32, u32)> = Vec::new();
        self.ctx.read_back(&bufs.counts_staging, counts_bytes, |bytes| {
            listed = as_words(bytes).iter().enumerate().map(|(b, &e)| (b as u32, e)).filter(|l| l.1 != 0).collect();
        })?;
        if listed.iter().any(|l| l.1 & 0x3ff == 0 || l.1 >> 21 != 0) {
            return Err(BackendError::Device("the device's fusion counts are inconsistent".into()));
        }
        let counts = |e: u32| ((e & 0x3ff) as usize, ((e >> 10) & 0x3ff) as usize, e >> 20 != 0);
        let mut report = FuseReport::default();
        let mut rewritten: Vec<usize> = Vec::new();
        for &(b, e) in &listed {
            let (observed, flipped, changed) = counts(e);
            report.voxels_updated += observed;
            report.voxels_changed += flipped;
            if flipped > 0 {
                report.changed_blocks.push(keys[b as usize]);
            }
            if map.get(keys[b as usize]).is_none() {
                report.blocks_allocated += 1;
            }
            if changed {
                rewritten.push(b as usize);
            }
        }
        report.rewritten_blocks = rewritten.len();
        if rewritten.is_empty() {
            return Ok(report);
        }

        // The changed blocks' values, copied out of the pool (runs of
        // consecutive slots in one copy).
        let count = rewritten.len();
        let slots: Vec<u32> = rewritten.iter().map(|&b| self.slot_table[b]).collect();
        self.ctx.scoped(|| {
            let mut enc =
                self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("fuse read") });
            pool.copy_out(&mut enc, &slots, &bufs.staging);
            self.ctx.queue.submit([enc.finish()]);
        })?;
        let mut blocks: Vec<(BlockKey, Box<OccupancyBlock>)> = Vec::with_capacity(count);
        self.ctx.read_back(&bufs.staging, count as u64 * BLOCK_BYTES, |bytes| {
            let words = as_words(bytes);
            let items: Vec<(usize, usize)> = rewritten.iter().copied().enumerate().collect();
            blocks = edtmap_core::par_fill(items, |(k, b)| {
                let mut values = [UNOBSERVED; BLOCK_VOXELS];
                for (v, &w) in values.iter_mut().zip(&words[k * BLOCK_VOXELS..(k + 1) * BLOCK_VOXELS]) {
                    *v = f32::from_bits(w ^ UNOBSERVED_BITS);
                }
                let mut block = Box::new(OccupancyBlock::default());
                block.log_odds.assign(&values);
                (keys[b], block)
            });
        })?;
        // Into the map (replacing the blocks there), and the pool told which
        // versions it holds.
        map.restore_shared(blocks.into_iter().map(|(k, b)| (k, SharedBlock::new(b))).collect());
        for &b in &rewritten {
            self.held[self.slot_table[b] as usize] = map.shared(keys[b]);
        }
        Ok(report)
    }

    /// Groups `corrections` (voxel index × 4 + code) by the block of `vol`
    /// (`nb` blocks, `nb3` per axis, the volume's origin at `o8` in the
    /// first) into `self.fixes`: `nb + 1` bounds, then per block its
    /// voxels' offsets + 512 × code (a counting sort).
    fn group_fixes(
        &mut self,
        corrections: &[u32],
        vol: &LocalVolume,
        o8: [u32; 3],
        nb3: [u32; 3],
        nb: usize,
    ) -> Result<(), BackendError> {
        let [nx, ny, _] = vol.dims;
        let place = |e: u32| {
            let i = (e >> 2) as usize;
            let c = [i % nx, (i / nx) % ny, i / (nx * ny)];
            let w = [0, 1, 2].map(|a| c[a] as u32 + o8[a]);
            let b = (w[0] / 8 + nb3[0] * (w[1] / 8 + nb3[1] * (w[2] / 8))) as usize;
            (b, (w[0] % 8 + 8 * (w[1] % 8 + 8 * (w[2] % 8))) | ((e & 3) << 9))
        };
        if corrections.iter().any(|&e| (e >> 2) as usize >= vol.len()) {
            return Err(BackendError::Device("a correction outside the volume".into()));
        }
        let head = nb + 1;
        self.fixes.clear();
        self.fixes.resize(head + corrections.len(), 0);
        for &e in corrections {
            self.fixes[place(e).0 + 1] += 1;
        }
        let mut at = head as u32;
        // fixes[b + 1] holds block b's count: the running sum is block b's
        // end, and block b + 1's start.
        for bound in &mut self.fixes[..head] {
            at += *bound;
            *bound = at;
        }
        let mut next: Vec<u32> = self.fixes[..nb].to_vec();
        for &e in corrections {
            let (b, entry) = place(e);
            self.fixes[next[b] as usize] = entry;
            next[b] += 1;
        }
        Ok(())
    }

    /// Gives every block of `keys` a pool slot holding the map's current
    /// version of it: uploaded, or cleared where the map lacks it.
    fn assign_slots(&mut self, map: &OccupancyMap, keys: &[BlockKey]) -> Result<(), BackendError> {
        let pool = self.pool.as_mut().ok_or_else(|| BackendError::Device("fusion pool missing".into()))?;
        let frame = self.frame;
        let mut missing = Vec::new();
        let mut stale: Vec<(u32, usize)> = Vec::new();
        self.slot_table.clear();
        let current: Vec<Option<SharedBlock<OccupancyBlock>>> = keys.iter().map(|&k| map.shared(k)).collect();
        for (i, &key) in keys.iter().enumerate() {
            match pool.touch(key, frame) {
                Some(slot) => {
                    if !SharedBlock::same(self.held[slot as usize].as_ref(), current[i].as_ref()) {
                        stale.push((slot, i));
                    }
                    self.slot_table.push(slot);
                }
                None => {
                    missing.push(i);
                    self.slot_table.push(u32::MAX);
                }
            }
        }
        pool.make_room(missing.len(), frame);
        for i in missing {
            let slot = pool.take(keys[i], frame)?;
            self.slot_table[i] = slot;
            stale.push((slot, i));
        }
        stale.sort_unstable_by_key(|s| s.0);
        self.cleared.clear();
        let mut fresh: Vec<(u32, usize)> = Vec::with_capacity(stale.len());
        for (slot, i) in stale {
            if current[i].is_some() {
                fresh.push((slot, i));
            } else {
                self.cleared.push(slot);
            }
        }
        pool.write(&self.ctx, &fresh, &mut self.upload, |i, out| {
            if let Some(b) = &current[i] {
                out.extend(b.get().log_odds.iter().map(|l| l.to_bits() ^ UNOBSERVED_BITS));
            }
        });
        for (i, c) in current.into_iter().enumerate() {
            self.held[self.slot_table[i] as usize] = c;
        }
        Ok(())
    }

    /// Sizes the pool and the per-frame buffers for volumes of `nb` blocks
    /// and `corrections` corrections.
    fn ensure_buffers(&mut self, nb: usize, corrections: usize) -> Result<(), BackendError> {
        if self.pool.as_ref().is_none_or(|pool| pool.slots < nb) {
            let max = self.ctx.limits().max_storage_buffer_binding_size.min(self.ctx.limits().max_buffer_size);
            let slots = (2 * nb).max(MIN_SLOTS).min((max / BLOCK_BYTES) as usize).max(nb);
            self.pool = None;
            self.pool = Some(Pool::new(&self.ctx, "the fusion's block pool", slots, BLOCK_BYTES)?);
            self.held = (0..slots).map(|_| None).collect();
        }
        if self.bufs.as_ref().is_none_or(|f| f.blocks < nb || f.corrections < corrections) {
            let blocks = self.bufs.as_ref().map_or(0, |f| f.blocks).max(nb).next_power_of_two();
            let fixes = self.bufs.as_ref().map_or(0, |f| f.corrections).max(corrections).max(1).next_power_of_two();
            self.bufs = None;
            let n = blocks as u64;
            self.ctx.check_buffer("the fusion's changed blocks", n * BLOCK_BYTES)?;
            self.ctx.check_buffer("the fusion's corrections", 4 * fixes as u64)?;
            let bufs = self.ctx.scoped(|| {
                let storage = wgpu::BufferUsages::STORAGE;
                let read = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
                let buffer = |label, size, usage| self.ctx.buffer(label, size, usage);
                Buffers {
                    blocks,
                    corrections: fixes,
                    slots: buffer("fuse slots", 4 * n, storage | wgpu::BufferUsages::COPY_DST),
                    fixes: buffer("fuse corrections", 4 * fixes as u64, storage | wgpu::BufferUsages::COPY_DST),
                    counts: buffer(
                        "fuse counts",
                        4 * n,
                        storage | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                    ),
                    counts_staging: buffer("fuse counts staging", 4 * n, read),
                    staging: buffer("fuse staging", n * BLOCK_BYTES, read),
                }
            })?;
            self.bufs = Some(bufs);
        }
        Ok(())
    }
}
