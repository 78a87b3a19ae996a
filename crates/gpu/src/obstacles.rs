//! The obstacles of the exact integration's source boxes, resident on the
//! device: one bit per voxel in a pool of 8³ blocks (64 bytes each), which
//! the batch EDT's scan along x reads in place of an uploaded mask
//! (`edt.wgsl`, `obstacle`). A frame computes each source block's bits on
//! the host, as the mask was, and uploads only the blocks the pool does not
//! hold with those bits, plus a slot per source block (4 bytes per 512
//! voxels, where the mask took 64): a robot that stays in a place sends
//! the blocks whose obstacles changed, not its surroundings again.
//!
//! A block with no obstacle or with nothing else takes no slot: its table
//! entry is [`EMPTY`] or [`FULL`]. The pool keeps, per slot, the bits it
//! uploaded, so it never needs to know what changed the map: a block whose
//! bits differ from the device's goes up again.

use crate::context::GpuContext;
use crate::pool::Pool;
use edtmap_core::region::Region;
use edtmap_core::{BackendError, Obstacles};
use rayon::prelude::*;

/// A table entry: a block with no obstacle.
const EMPTY: u32 = u32::MAX;
/// A table entry: a block of obstacles only.
const FULL: u32 = u32::MAX - 1;

/// Words of one block (512 bits).
const WORDS: usize = 16;

/// Bytes of one pool block.
const BLOCK_BYTES: u64 = 4 * WORDS as u64;

/// The fewest pool slots allocated (256 KiB).
const MIN_SLOTS: usize = 4096;

/// One block's obstacle bits as the device reads them: voxel `o` at bit
/// `o % 32` of word `o / 32`.
type Bits = [u32; WORDS];

/// A source box's obstacles on the device, for [`crate::edt::Mask::Blocks`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Placed {
    /// The box's first voxel within its first block.
    pub(crate) o8: [u32; 3],
    /// The box's blocks per axis.
    pub(crate) nb: [u32; 3],
}

/// The pool, its slots' bits as uploaded, and the slot table of the
/// current source box.
#[derive(Debug)]
pub(crate) struct ResidentObstacles {
    ctx: GpuContext,
    pool: Option<Pool>,
    /// Per slot: the bits the device holds.
    held: Vec<Bits>,
    /// The most slots the pool may have.
    max_slots: usize,
    /// The slot table on the device, and its capacity in blocks.
    table_buffer: Option<(wgpu::Buffer, usize)>,
    /// Per block of the current source box: its bits, then its table entry.
    bits: Vec<Bits>,
    table: Vec<u32>,
    scratch: Vec<u32>,
}

impl ResidentObstacles {
    pub(crate) fn new(ctx: &GpuContext) -> Self {
        ResidentObstacles {
            ctx: ctx.clone(),
            pool: None,
            held: Vec::new(),
            max_slots: usize::MAX,
            table_buffer: None,
            bits: Vec::new(),
            table: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// Caps the pool at `slots` blocks (at least a source box's), dropping
    /// what it holds.
    pub(crate) fn limit(&mut self, slots: usize) {
        self.max_slots = slots.max(1);
        self.forget();
    }

    /// Drops what the device holds (after a failure, the device's blocks
    /// may not be the ones recorded).
    pub(crate) fn forget(&mut self) {
        self.pool = None;
        self.held.clear();
    }

    /// The pool buffer and the slot table buffer, once [`Self::place`] ran.
    pub(crate) fn buffers(&self) -> Option<(&wgpu::Buffer, &wgpu::Buffer)> {
        Some((&self.pool.as_ref()?.buffer, &self.table_buffer.as_ref()?.0))
    }

    /// Puts the obstacles of `source` on the device, uploading the blocks
    /// the pool does not hold with these bits (used in `frame`, for the
    /// least-recently-used order), and the box's slot table.
    pub(crate) fn place(
        &mut self,
        obstacles: &Obstacles<'_>,
        source: &Region,
        frame: u64,
    ) -> Result<Placed, BackendError> {
        let keys = source.blocks();
        let (first, last) = match (keys.first(), keys.last()) {
            (Some(f), Some(l)) => (*f, *l),
            _ => return Err(BackendError::Device("an empty source box".into())),
        };
        let nb = [0, 1, 2].map(|a| (last.0[a] - first.0[a] + 1) as u32);
        let o8 = [0, 1, 2].map(|a| (source.origin[a] - first.first_voxel().0[a]) as u32);
        // Two hash look-ups a block, tens of thousands of blocks: on every core.
        keys.par_iter().map(|&k| to_words(obstacles.block_bits(k))).collect_into_vec(&mut self.bits);
        let mixed = self.bits.iter().filter(|b| entry_for(b).is_none()).count();
        self.ensure_pool(mixed)?;
        let pool = self.pool.as_mut().ok_or_else(|| BackendError::Device("obstacle pool missing".into()))?;

        // Blocks held with the same bits keep their slot; those held with
        // other bits go up again into it; the rest need a slot.
        self.table.clear();
        let mut fresh: Vec<(u32, usize)> = Vec::new();
        let mut missing = Vec::new();
        for (i, (&key, bits)) in keys.iter().zip(&self.bits).enumerate() {
            if let Some(entry) = entry_for(bits) {
                self.table.push(entry);
                continue;
            }
            match pool.touch(key, frame) {
                Some(slot) => {
                    if self.held[slot as usize] != *bits {
                        fresh.push((slot, i));
                    }
                    self.table.push(slot);
                }
                None => {
                    missing.push(i);
                    self.table.push(EMPTY);
                }
            }
        }
        pool.make_room(missing.len(), frame);
        for i in missing {
            let slot = pool.take(keys[i], frame)?;
            self.table[i] = slot;
            fresh.push((slot, i));
        }
        fresh.sort_unstable_by_key(|f| f.0);
        for &(slot, i) in &fresh {
            self.held[slot as usize] = self.bits[i];
        }
        let bits = &self.bits;
        pool.write(&self.ctx, &fresh, &mut self.scratch, |i, out| out.extend_from_slice(&bits[i]));

        if self.table_buffer.as_ref().is_none_or(|t| t.1 < keys.len()) {
            self.table_buffer = None;
            let blocks = keys.len().next_power_of_two();
            self.ctx.check_buffer("the obstacle blocks' slot table", 4 * blocks as u64)?;
            let buffer = self.ctx.scoped(|| {
                self.ctx.buffer(
                    "obstacle slots",
                    4 * blocks as u64,
                    wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                )
            })?;
            self.table_buffer = Some((buffer, blocks));
        }
        if let Some((buffer, _)) = &self.table_buffer {
            self.ctx.queue.write_buffer(buffer, 0, bytemuck::cast_slice(&self.table));
        }
        Ok(Placed { o8, nb })
    }

    /// A pool with room for `mixed` blocks at once: twice that (at least
    /// [`MIN_SLOTS`]) within the cap and the device's limit, made anew
    /// (empty) when the one in place is smaller than `mixed`.
    fn ensure_pool(&mut self, mixed: usize) -> Result<(), BackendError> {
        if self.pool.as_ref().is_some_and(|p| p.slots >= mixed.max(1)) {
            return Ok(());
        }
        self.forget();
        let limits = self.ctx.limits();
        let max = (limits.max_storage_buffer_binding_size.min(limits.max_buffer_size) / BLOCK_BYTES) as usize;
        let slots = (2 * mixed).max(MIN_SLOTS).min(max).min(self.max_slots).max(mixed).max(1);
        self.pool = Some(Pool::new(&self.ctx, "the exact integration's obstacle blocks", slots, BLOCK_BYTES)?);
        self.held = vec![[0; WORDS]; slots];
        Ok(())
    }
}

/// The table entry of a block that needs no slot.
fn entry_for(bits: &Bits) -> Option<u32> {
    if bits.iter().all(|&w| w == 0) {
        Some(EMPTY)
    } else if bits.iter().all(|&w| w == u32::MAX) {
        Some(FULL)
    } else {
        None
    }
}

/// [`Obstacles::block_bits`]' 64-bit words as the device's 32-bit ones.
fn to_words(bits: [u64; 8]) -> Bits {
    let mut out = [0; WORDS];
    for (k, w) in bits.iter().enumerate() {
        out[2 * k] = *w as u32;
        out[2 * k + 1] = (w >> 32) as u32;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_keep_the_voxel_order() {
        let mut bits = [0u64; 8];
        for o in [0usize, 31, 32, 63, 64, 300, 511] {
            bits[o / 64] |= 1 << (o % 64);
        }
        let words = to_words(bits);
        let set: Vec<usize> = (0..512).filter(|&o| words[o / 32] >> (o % 32) & 1 == 1).collect();
        assert_eq!(set, [0, 31, 32, 63, 64, 300, 511]);
        assert_eq!(entry_for(&[0; WORDS]), Some(EMPTY));
        assert_eq!(entry_for(&[u32::MAX; WORDS]), Some(FULL));
        assert_eq!(entry_for(&words), None);
    }
}
