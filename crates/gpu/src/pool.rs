//! A pool of map blocks resident on the device: a buffer of fixed-size
//! slots, which block each slot holds and when it was last used, so that
//! a frame uploads only the blocks the device does not hold yet. The exact
//! integration keeps the global EDT's blocks in one (`exact.rs`) and the
//! obstacles of its source boxes in another (`obstacles.rs`).

use std::collections::HashMap;

use crate::context::GpuContext;
use edtmap_core::{BackendError, BlockKey};

/// The resident blocks: `slots` blocks of `block_bytes` on the device and
/// which map block each holds.
#[derive(Debug)]
pub(crate) struct Pool {
    pub(crate) buffer: wgpu::Buffer,
    pub(crate) slots: usize,
    block_bytes: u64,
    pub(crate) table: HashMap<BlockKey, u32>,
    /// Per slot: the block it holds and the frame it was last used in.
    pub(crate) owner: Vec<Option<(BlockKey, u64)>>,
    pub(crate) free: Vec<u32>,
}

impl Pool {
    /// An empty pool of `slots` slots of `block_bytes`, refused with the
    /// numbers when its buffer is over the device's limit.
    pub(crate) fn new(
        ctx: &GpuContext,
        what: &'static str,
        slots: usize,
        block_bytes: u64,
    ) -> Result<Self, BackendError> {
        let bytes = slots as u64 * block_bytes;
        ctx.check_buffer(what, bytes)?;
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC;
        let buffer = ctx.scoped(|| ctx.buffer(what, bytes, usage))?;
        Ok(Pool {
            buffer,
            slots,
            block_bytes,
            table: HashMap::new(),
            owner: vec![None; slots],
            free: (0..slots as u32).rev().collect(),
        })
    }

    /// Forgets every resident block.
    pub(crate) fn clear(&mut self) {
        self.table.clear();
        self.owner.iter_mut().for_each(|o| *o = None);
        self.free = (0..self.slots as u32).rev().collect();
    }

    /// Frees at least `n` slots not used in `frame`, least recently used
    /// first.
    fn evict(&mut self, n: usize, frame: u64) {
        let mut used: Vec<(u64, u32)> = self
            .owner
            .iter()
            .enumerate()
            .filter_map(|(s, o)| o.filter(|o| o.1 < frame).map(|o| (o.1, s as u32)))
            .collect();
        used.sort_unstable();
        for &(_, slot) in used.iter().take(n) {
            if let Some((key, _)) = self.owner[slot as usize].take() {
                self.table.remove(&key);
            }
            self.free.push(slot);
        }
    }

    /// The slot holding `key`, marked used in `frame`; `None` when the
    /// pool does not hold it.
    pub(crate) fn touch(&mut self, key: BlockKey, frame: u64) -> Option<u32> {
        let slot = *self.table.get(&key)?;
        self.owner[slot as usize] = Some((key, frame));
        Some(slot)
    }

    /// Frees slots (least recently used first) until `n` are free.
    pub(crate) fn make_room(&mut self, n: usize, frame: u64) {
        if n > self.free.len() {
            self.evict(n - self.free.len(), frame);
        }
    }

    /// Takes a free slot for `key`, used in `frame`.
    pub(crate) fn take(&mut self, key: BlockKey, frame: u64) -> Result<u32, BackendError> {
        let slot = self.free.pop().ok_or_else(|| BackendError::Device("pool slots exhausted".into()))?;
        self.table.insert(key, slot);
        self.owner[slot as usize] = Some((key, frame));
        Ok(slot)
    }

    /// Uploads blocks into their slots: `fresh` holds (slot, item) sorted
    /// by slot, `fill` appends an item's words; runs of consecutive slots
    /// go up in one write, through `scratch`.
    pub(crate) fn write<T: Copy>(
        &self,
        ctx: &GpuContext,
        fresh: &[(u32, T)],
        scratch: &mut Vec<u32>,
        mut fill: impl FnMut(T, &mut Vec<u32>),
    ) {
        let slots: Vec<u32> = fresh.iter().map(|f| f.0).collect();
        let mut at = 0;
        for (first, len) in runs(&slots) {
            scratch.clear();
            for &(_, item) in &fresh[at..at + len as usize] {
                fill(item, scratch);
            }
            ctx.queue.write_buffer(&self.buffer, u64::from(first) * self.block_bytes, bytemuck::cast_slice(scratch));
            at += len as usize;
        }
    }
}

impl Pool {
    /// Records copies of the blocks in `slots`, in that order, into
    /// `staging` one after the other: a copy command per run of
    /// consecutive slots (no dispatch).
    pub(crate) fn copy_out(&self, enc: &mut wgpu::CommandEncoder, slots: &[u32], staging: &wgpu::Buffer) {
        let mut k = 0;
        while k < slots.len() {
            let mut end = k + 1;
            while end < slots.len() && slots[end] == slots[k] + (end - k) as u32 {
                end += 1;
            }
            let bytes = self.block_bytes;
            enc.copy_buffer_to_buffer(
                &self.buffer,
                u64::from(slots[k]) * bytes,
                staging,
                k as u64 * bytes,
                (end - k) as u64 * bytes,
            );
            k = end;
        }
    }
}

/// The runs of consecutive values of sorted `slots`: (first, length).
pub(crate) fn runs(slots: &[u32]) -> impl Iterator<Item = (u32, u32)> + '_ {
    let mut at = 0;
    std::iter::from_fn(move || {
        let first = *slots.get(at)?;
        let mut len = 1;
        while slots.get(at + len as usize) == Some(&(first + len)) {
            len += 1;
        }
        at += len as usize;
        Some((first, len))
    })
}

#[cfg(test)]
mod tests {
    use super::runs;

    #[test]
    fn runs_of_consecutive_slots() {
        assert_eq!(runs(&[]).count(), 0);
        assert_eq!(runs(&[3, 4, 5, 9, 11, 12]).collect::<Vec<_>>(), [(3, 3), (9, 1), (11, 2)]);
    }
}
