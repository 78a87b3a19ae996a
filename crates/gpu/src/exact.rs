//! Exact integration on the GPU (`exact.wgsl`), bit-identical to the CPU's
//! [`edtmap_core::exact::recompute_exact`].
//!
//! The device keeps a pool of the global EDT's blocks, resident between
//! frames while the map's stamp says nothing else changed it. A frame
//! uploads the source box's obstacle blocks the device does not hold with
//! their current bits (`obstacles.rs`; before, a bit per source voxel
//! every frame), the blocks of its region the pool does not hold yet and
//! tables of their slots; the batch EDT, the comparison with the old values and the list
//! of changed blocks stay on the device, and only the changed blocks come
//! back (2 KiB each), for the host to write into its map. Before, the
//! whole source box's EDT came back, 8 bytes per voxel.
//!
//! The pool evicts the blocks least recently used when a region needs more
//! slots than are free, and grows (starting over) while the device allows.
//! A frame is one dispatch after the batch EDT's and two round trips: the
//! list of changed blocks, then their values.

use crate::context::GpuContext;
use crate::dispatch::{groups_1d, storage_entry, uniform_entry, Kernel, GROUP};
use crate::edt::{as_words, copy_words, GpuEdt, Mask};
use crate::obstacles::ResidentObstacles;
use crate::pool::{runs, Pool};
use edtmap_core::region::{write_back_offsets, Packing, WriteBack};
use edtmap_core::{
    BackendError, BlockKey, EdtMap, MapStamp, Obstacles, VoxelIndex, BLOCK_VOXELS, NO_OBSTACLE, NO_OFFSET,
};

/// The largest reach, voxels, a value's 10-bit offsets hold.
const MAX_REACH: i32 = 511;

/// A voxel with no obstacle within the cutoff (`FAR` in the shader): 0,
/// which no offset's word is (each axis's biased offset is 1 to 1023), so
/// that a block the map lacks is cleared on the device, not uploaded.
const ENC_FAR: u32 = 0;

/// A host value the encoding cannot hold (its distance is not its offset's
/// length): never equal to a new value, so the voxel is rewritten.
const ENC_INVALID: u32 = u32::MAX - 1;

/// Bytes of one pool block.
const BLOCK_BYTES: u64 = 4 * BLOCK_VOXELS as u64;

/// The fewest pool slots allocated.
const MIN_SLOTS: usize = 1024;

/// Uniform parameters (`ExactParams` in the shader).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ExactParams {
    source: [u32; 4],
    region: [u32; 4],
    o8: [u32; 4],
    blocks: [u32; 4],
}

/// The exact integration's kernels, its block pool and its buffers.
#[derive(Debug)]
pub(crate) struct GpuExact {
    ctx: GpuContext,
    compare: Kernel,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    ctrl: wgpu::Buffer,
    pool: Option<Pool>,
    frame_bufs: Option<FrameBuffers>,
    /// The source boxes' obstacles, resident.
    obstacles: ResidentObstacles,
    /// The map's stamp after this integration last wrote it.
    seen: Option<MapStamp>,
    /// Frames run, for the pool's least-recently-used order.
    frame: u64,
    /// The most blocks the pool may hold.
    max_slots: usize,
    /// Blocks the current job covers in all (its tiles together).
    job_blocks: usize,
    /// Values of the blocks being uploaded, and the region's slot table.
    upload: Vec<u32>,
    slot_table: Vec<u32>,
    /// Slots given this frame to blocks the map lacks, to clear, sorted.
    cleared: Vec<u32>,
}

/// Per-frame buffers, sized for regions of up to `blocks` blocks.
#[derive(Debug)]
struct FrameBuffers {
    blocks: usize,
    slots: wgpu::Buffer,
    list: wgpu::Buffer,
    list_staging: wgpu::Buffer,
    staging: wgpu::Buffer,
}

impl GpuExact {
    /// Compiles the kernels once for `ctx`.
    pub(crate) fn new(ctx: &GpuContext) -> Result<Self, BackendError> {
        ctx.scoped(|| {
            let dev = &ctx.device;
            let module = dev.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("exact.wgsl"),
                source: wgpu::ShaderSource::Wgsl(include_str!("exact.wgsl").into()),
            });
            let mut entries = vec![uniform_entry(0, false)];
            entries.extend((1..=5).map(|b| storage_entry(b, b <= 2)));
            let layout = dev
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("exact"), entries: &entries });
            let compare = Kernel::new(ctx, &module, &layout, "compare");
            let params = ctx.buffer(
                "exact params",
                std::mem::size_of::<ExactParams>() as u64,
                wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            );
            let ctrl = ctx.buffer(
                "exact ctrl",
                16,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            );
            GpuExact {
                ctx: ctx.clone(),
                compare,
                layout,
                params,
                ctrl,
                pool: None,
                frame_bufs: None,
                obstacles: ResidentObstacles::new(ctx),
                seen: None,
                frame: 0,
                max_slots: usize::MAX,
                job_blocks: 0,
                upload: Vec::new(),
                slot_table: Vec::new(),
                cleared: Vec::new(),
            }
        })
    }

    /// Caps the pool at `blocks` blocks (at least a region's), dropping
    /// what it holds.
    pub(crate) fn limit_pool(&mut self, blocks: usize) {
        self.max_slots = blocks.max(1);
        self.obstacles.limit(blocks);
        self.pool = None;
        self.seen = None;
    }

    /// Sizes the pool for a job of `blocks` blocks that comes in tiles,
    /// so that one tile does not evict the blocks of the next frame's.
    pub(crate) fn reserve(&mut self, blocks: usize) {
        self.job_blocks = blocks;
    }

    /// Whether [`Self::run`] can take a cutoff of `reach` voxels.
    pub(crate) fn supports(reach: i32) -> bool {
        reach <= MAX_REACH
    }

    /// Recomputes `packing.region` of `map` exactly from `obstacles`, with
    /// the batch EDT of `edt`, writing back the voxels that changed. On a
    /// failure the pool is dropped (the device may hold values the host
    /// map does not) and the map is untouched.
    pub(crate) fn run(
        &mut self,
        edt: &mut GpuEdt,
        map: &mut EdtMap,
        obstacles: &Obstacles<'_>,
        packing: &Packing,
    ) -> Result<WriteBack, BackendError> {
        let result = self.frame(edt, map, obstacles, packing);
        match &result {
            Ok(_) => self.seen = Some(map.stamp()),
            Err(_) => {
                self.pool = None;
                self.obstacles.forget();
                self.seen = None;
            }
        }
        result
    }

    fn frame(
        &mut self,
        edt: &mut GpuEdt,
        map: &mut EdtMap,
        obstacles: &Obstacles<'_>,
        p: &Packing,
    ) -> Result<WriteBack, BackendError> {
        if !Self::supports(p.cutoff.reach) {
            return Err(BackendError::Device(format!(
                "a cutoff reach of {} voxels is beyond the pool's {MAX_REACH}",
                p.cutoff.reach
            )));
        }
        self.frame += 1;
        let keys = p.region.blocks();
        let nb = keys.len();
        if nb == 0 {
            return Ok(WriteBack::default());
        }
        if self.seen != Some(map.stamp()) {
            if let Some(pool) = &mut self.pool {
                pool.clear();
            }
        }
        self.ensure_buffers(nb)?;
        self.assign_slots(map, &keys, p)?;
        let placed = self.obstacles.place(obstacles, &p.source, self.frame)?;

        let first = keys[0].first_voxel().0;
        let o8 = [0, 1, 2].map(|a| (p.region.origin[a] - first[a]) as u32);
        let nb3 = [0, 1, 2].map(|a| (o8[a] + p.region.dims[a] as u32).div_ceil(8));
        let params = ExactParams {
            source: [p.source.dims[0] as u32, p.source.dims[1] as u32, p.source.dims[2] as u32, p.cutoff.reach as u32],
            region: [p.region.dims[0] as u32, p.region.dims[1] as u32, p.region.dims[2] as u32, p.region.len() as u32],
            o8: [o8[0], o8[1], o8[2], p.cutoff.max_dist_sq],
            blocks: [nb3[0], nb3[1], nb3[2], nb as u32],
        };
        let mut enc = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("exact") });
        if let Some(pool) = &self.pool {
            for (first, len) in runs(&self.cleared) {
                enc.clear_buffer(&pool.buffer, u64::from(first) * BLOCK_BYTES, Some(u64::from(len) * BLOCK_BYTES));
            }
        }
        let (obstacle_pool, obstacle_slots) =
            self.obstacles.buffers().ok_or_else(|| BackendError::Device("obstacle blocks missing".into()))?;
        edt.encode_mask(
            Mask::Blocks {
                dims: p.source.dims,
                o8: placed.o8,
                nb: placed.nb,
                pool: obstacle_pool,
                slots: obstacle_slots,
            },
            &mut enc,
        )?;
        let pairs = edt.output().ok_or_else(|| BackendError::Device("EDT buffers missing".into()))?;
        let pool = self.pool.as_ref().ok_or_else(|| BackendError::Device("pool missing".into()))?;
        let bufs = self.frame_bufs.as_ref().ok_or_else(|| BackendError::Device("buffers missing".into()))?;
        let list_bytes = 4 * nb as u64;
        self.ctx.scoped(|| {
            let resources =
                [&self.params, pairs, &bufs.slots, &pool.buffer, &bufs.list, &self.ctrl].map(|b| b.as_entire_binding());
            let group = self.ctx.bind_group("exact", &self.layout, &resources);
            let q = &self.ctx.queue;
            q.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
            q.write_buffer(&bufs.slots, 0, bytemuck::cast_slice(&self.slot_table));
            enc.clear_buffer(&self.ctrl, 0, None);
            {
                let mut pass = self.ctx.pass(&mut enc, "exact compare");
                // One workgroup per block.
                self.compare.dispatch(&mut pass, &[&group], groups_1d(nb as u64 * GROUP));
            }
            enc.copy_buffer_to_buffer(&self.ctrl, 0, &bufs.list_staging, 0, 16);
            enc.copy_buffer_to_buffer(&bufs.list, 0, &bufs.list_staging, 16, list_bytes);
            q.submit([enc.finish()]);
        })?;
        let mut listed = Vec::new();
        self.ctx.read_back(&bufs.list_staging, 16 + list_bytes, |bytes| {
            let (ctrl, list) = bytes.split_at(16);
            let count = u32::from_ne_bytes([ctrl[0], ctrl[1], ctrl[2], ctrl[3]]) as usize;
            listed = vec![u32::MAX; count.min(nb)];
            copy_words(&list[..4 * listed.len()], &mut listed);
        })?;
        listed.sort_unstable();
        if listed.last().is_some_and(|&b| b as usize >= nb) || listed.windows(2).any(|w| w[0] == w[1]) {
            return Err(BackendError::Device("the device listed a block twice or out of the region".into()));
        }
        // In key order, as the CPU lists them.
        listed.sort_unstable_by_key(|&b| keys[b as usize]);
        let count = listed.len();
        if count == 0 {
            return Ok(WriteBack::default());
        }

        // The changed blocks' values, copied out of the pool (runs of
        // consecutive slots in one copy).
        let values_bytes = count as u64 * BLOCK_BYTES;
        let slots: Vec<u32> = listed.iter().map(|&b| self.slot_table[b as usize]).collect();
        self.ctx.scoped(|| {
            let mut enc =
                self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("exact read") });
            pool.copy_out(&mut enc, &slots, &bufs.staging);
            self.ctx.queue.submit([enc.finish()]);
        })?;
        // Written into the map straight from the mapped words, which are
        // offsets already.
        let candidates: Vec<BlockKey> = listed.iter().map(|&b| keys[b as usize]).collect();
        let mut written = WriteBack::default();
        self.ctx.read_back(&bufs.staging, values_bytes, |bytes| {
            let words = as_words(bytes);
            written = write_back_offsets(map, p, &candidates, |k, out| {
                for (o, &w) in out.iter_mut().zip(&words[k * BLOCK_VOXELS..(k + 1) * BLOCK_VOXELS]) {
                    *o = word_offset(w);
                }
            });
        })?;
        Ok(written)
    }

    /// Gives every block of `keys` a pool slot, uploading those not
    /// resident, and fills the slot table.
    fn assign_slots(&mut self, map: &EdtMap, keys: &[BlockKey], p: &Packing) -> Result<(), BackendError> {
        let pool = self.pool.as_mut().ok_or_else(|| BackendError::Device("pool missing".into()))?;
        let frame = self.frame;
        let mut missing = Vec::new();
        self.slot_table.clear();
        for (i, &key) in keys.iter().enumerate() {
            let slot = pool.touch(key, frame);
            if slot.is_none() {
                missing.push(i);
            }
            self.slot_table.push(slot.unwrap_or(u32::MAX));
        }
        pool.make_room(missing.len(), frame);
        // Blocks the map holds go up; those it lacks (every voxel FAR) are
        // cleared on the device when the frame is recorded.
        let mut fresh: Vec<(u32, BlockKey)> = Vec::with_capacity(missing.len());
        self.cleared.clear();
        for i in missing {
            let slot = pool.take(keys[i], frame)?;
            self.slot_table[i] = slot;
            if map.get(keys[i]).is_some() {
                fresh.push((slot, keys[i]));
            } else {
                self.cleared.push(slot);
            }
        }
        fresh.sort_unstable_by_key(|f| f.0);
        self.cleared.sort_unstable();
        let (reach, max) = (p.cutoff.reach, p.cutoff.max_dist_sq);
        pool.write(&self.ctx, &fresh, &mut self.upload, |key, out| {
            if let Some(b) = map.get(key) {
                out.extend(
                    (0..BLOCK_VOXELS)
                        .map(|off| encode(key.voxel(off), b.dist_sq(off), b.nearest(key, off), max, reach)),
                );
            }
        });
        Ok(())
    }

    /// Sizes the pool and the per-frame buffers for regions of `nb` blocks.
    fn ensure_buffers(&mut self, nb: usize) -> Result<(), BackendError> {
        let want = nb.max(self.job_blocks);
        if self.pool.as_ref().is_none_or(|pool| pool.slots < want) {
            let slots = (2 * want).max(MIN_SLOTS);
            let max = self.ctx.limits().max_storage_buffer_binding_size.min(self.ctx.limits().max_buffer_size);
            let slots = slots.min((max / BLOCK_BYTES) as usize).min(self.max_slots).max(nb);
            self.pool = None;
            self.pool = Some(Pool::new(&self.ctx, "the exact integration's block pool", slots, BLOCK_BYTES)?);
        }
        if self.frame_bufs.as_ref().is_none_or(|f| f.blocks < nb) {
            self.frame_bufs = None;
            let blocks = nb.next_power_of_two();
            let n = blocks as u64;
            self.ctx.check_buffer("the exact integration's changed blocks", n * BLOCK_BYTES)?;
            let bufs = self.ctx.scoped(|| {
                let storage = wgpu::BufferUsages::STORAGE;
                let buffer = |label, size, usage| self.ctx.buffer(label, size, usage);
                FrameBuffers {
                    blocks,
                    slots: buffer("exact slots", 4 * n, storage | wgpu::BufferUsages::COPY_DST),
                    list: buffer("exact list", 4 * n, storage | wgpu::BufferUsages::COPY_SRC),
                    list_staging: buffer(
                        "exact list staging",
                        16 + 4 * n,
                        wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    ),
                    staging: buffer(
                        "exact staging",
                        n * BLOCK_BYTES,
                        wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    ),
                }
            })?;
            self.frame_bufs = Some(bufs);
        }
        Ok(())
    }
}

/// The pool's word for the host value (`dist_sq`, `nearest`) of voxel `v`.
fn encode(v: VoxelIndex, dist_sq: u32, nearest: VoxelIndex, max_dist_sq: u32, reach: i32) -> u32 {
    if dist_sq > max_dist_sq || nearest == NO_OBSTACLE {
        return ENC_FAR;
    }
    let off = [0, 1, 2].map(|a| i64::from(nearest.0[a]) - i64::from(v.0[a]));
    let len_sq: i64 = off.iter().map(|o| o * o).sum();
    if off.iter().any(|o| o.abs() > i64::from(reach)) || len_sq != i64::from(dist_sq) {
        return ENC_INVALID;
    }
    let b = off.map(|o| (o + 512) as u32);
    b[0] | (b[1] << 10) | (b[2] << 20)
}

/// The offset to the nearest obstacle that the device word `word` holds.
fn word_offset(word: u32) -> [i16; 3] {
    if word == ENC_FAR {
        return NO_OFFSET;
    }
    [0, 10, 20].map(|s| ((word >> s) & 0x3ff) as i16 - 512)
}

#[cfg(test)]
mod tests {
    use super::*;
    use edtmap_core::region::Region;
    use edtmap_core::{Cutoff, FAR_DIST_SQ};

    #[test]
    fn encoding_round_trips_through_the_packing() {
        let cutoff = Cutoff { max_dist_sq: 400, reach: 20, planar: false };
        let p = Packing::new(Region { origin: [-5, 3, 0], dims: [10, 10, 10] }, cutoff).expect("small");
        let v = VoxelIndex([0, 5, 2]);
        for (n, d) in [(VoxelIndex([3, -4, 2]), 9 + 81), (v, 0), (VoxelIndex([-20, 5, 2]), 400)] {
            let word = encode(v, d, n, cutoff.max_dist_sq, cutoff.reach);
            let o = word_offset(word);
            assert_eq!(
                p.pack(
                    o.iter().map(|&c| (i32::from(c) * i32::from(c)) as u32).sum(),
                    VoxelIndex([0, 1, 2].map(|a| v.0[a] + i32::from(o[a])))
                ),
                p.pack(d, n)
            );
        }
        assert_eq!(word_offset(ENC_FAR), NO_OFFSET);
        assert_eq!(encode(v, 401, VoxelIndex([-21, 5, 2]), 400, 20), ENC_FAR);
        assert_eq!(encode(v, FAR_DIST_SQ, NO_OBSTACLE, 400, 20), ENC_FAR);
        assert_eq!(encode(v, 5, VoxelIndex([1, 5, 2]), 400, 20), ENC_INVALID, "distance not the offset's");
    }
}
