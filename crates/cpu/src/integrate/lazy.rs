//! The wavefront's working region, loaded lazily one 8³ block at a time.
//!
//! The region (the window grown by the cutoff's reach plus one) is covered
//! by whole blocks, stored block after block (512 voxels each) in flat
//! arrays that live across frames. A block is copied out of the map only
//! when the frame needs it (the window's blocks, blocks that may hold a
//! raised voxel, blocks a wave reaches), claimed with an atomic per-block
//! state tagged with the frame's epoch, so nothing is reset or read in
//! full each frame and the cost follows the change.

use edtmap_core::region::{Packing, Region, FAR};
use edtmap_core::{BlockKey, EdtMap, VoxelIndex, BLOCK_SIDE, BLOCK_VOXELS, NO_OFFSET};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering::Acquire, Ordering::Relaxed, Ordering::Release};

/// Where a block's nearest obstacles lie: the box of their world indices.
pub type SrcBounds = ([i32; 3], [i32; 3]);

/// The block grid covering a region.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cover {
    /// World index of the first voxel of block (0, 0, 0): a multiple of 8.
    pub origin: [i32; 3],
    /// Blocks along x, y, z.
    pub bdims: [usize; 3],
    /// The region itself.
    pub region: Region,
}

impl Cover {
    /// The blocks covering `region`.
    pub fn of(region: Region) -> Cover {
        let first = VoxelIndex(region.origin).block().0;
        let last = VoxelIndex([0, 1, 2].map(|a| region.origin[a] + region.dims[a] as i32 - 1)).block().0;
        Cover {
            origin: first.map(|b| b * BLOCK_SIDE),
            bdims: [0, 1, 2].map(|a| (last[a] - first[a] + 1) as usize),
            region,
        }
    }

    /// Number of blocks.
    pub fn blocks(&self) -> usize {
        self.bdims.iter().product()
    }

    /// Index of the voxel at cover coordinates `c` (world − origin).
    #[inline]
    pub fn index(&self, c: [usize; 3]) -> usize {
        let b = (c[0] >> 3) + self.bdims[0] * ((c[1] >> 3) + self.bdims[1] * (c[2] >> 3));
        b * BLOCK_VOXELS + (c[0] & 7) + 8 * ((c[1] & 7) + 8 * (c[2] & 7))
    }

    /// Cover coordinates of voxel index `i`.
    #[inline]
    pub fn coords(&self, i: usize) -> [usize; 3] {
        let (b, o) = (i / BLOCK_VOXELS, i % BLOCK_VOXELS);
        let bc = [b % self.bdims[0], (b / self.bdims[0]) % self.bdims[1], b / (self.bdims[0] * self.bdims[1])];
        let oc = [o & 7, (o >> 3) & 7, o >> 6];
        [0, 1, 2].map(|a| bc[a] * 8 + oc[a])
    }

    /// Whether cover coordinates `c` lie in the region.
    #[inline]
    pub fn in_region(&self, c: [usize; 3]) -> bool {
        (0..3).all(|a| {
            let w = self.origin[a] + c[a] as i32;
            w >= self.region.origin[a] && w < self.region.origin[a] + self.region.dims[a] as i32
        })
    }

    /// World key of block number `b`.
    pub fn key(&self, b: usize) -> BlockKey {
        let bc = [b % self.bdims[0], (b / self.bdims[0]) % self.bdims[1], b / (self.bdims[0] * self.bdims[1])];
        BlockKey([0, 1, 2].map(|a| self.origin[a] / BLOCK_SIDE + bc[a] as i32))
    }

    /// Cover coordinates of world voxel `v`, if inside the cover.
    #[inline]
    pub fn local(&self, v: VoxelIndex) -> Option<[usize; 3]> {
        let mut c = [0; 3];
        for (a, out) in c.iter_mut().enumerate() {
            let d = v.0[a] - self.origin[a];
            if d < 0 || d as usize >= self.bdims[a] * 8 {
                return None;
            }
            *out = d as usize;
        }
        Some(c)
    }
}

/// Per-voxel and per-block state of the lazily loaded region.
#[derive(Debug, Default)]
pub struct LazyRegion {
    /// Packed values before the frame.
    pub old: Vec<AtomicU64>,
    /// Packed values being worked on.
    pub cur: Vec<AtomicU64>,
    /// Per voxel: (epoch << 32) | level of the last frontier it joined.
    pub stamp: Vec<AtomicU64>,
    state: Vec<AtomicU32>,
    /// Per block: whether a voxel changed this frame.
    pub dirty: Vec<AtomicBool>,
    epoch: u32,
    bdims: [usize; 3],
    /// Cached bounds of the nearest obstacles of map blocks.
    pub bounds: HashMap<BlockKey, SrcBounds>,
}

impl LazyRegion {
    /// Starts a frame on `cover`: no block loaded, none dirty.
    pub fn begin(&mut self, cover: &Cover) {
        let blocks = cover.blocks();
        if self.bdims != cover.bdims || self.epoch >= u32::MAX / 2 - 1 {
            let voxels = blocks * BLOCK_VOXELS;
            self.old = (0..voxels).map(|_| AtomicU64::new(FAR)).collect();
            self.cur = (0..voxels).map(|_| AtomicU64::new(FAR)).collect();
            self.stamp = (0..voxels).map(|_| AtomicU64::new(0)).collect();
            self.state = (0..blocks).map(|_| AtomicU32::new(0)).collect();
            self.dirty = (0..blocks).map(|_| AtomicBool::new(false)).collect();
            self.bdims = cover.bdims;
            self.epoch = 0;
        }
        self.epoch += 1;
        self.dirty.par_iter().for_each(|d| d.store(false, Relaxed));
    }

    /// The frame's epoch (stamps from earlier frames differ in their high bits).
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    /// Makes sure block `b` holds the map's values this frame.
    #[inline]
    pub fn ensure(&self, b: usize, map: &EdtMap, p: &Packing, cover: &Cover) {
        let (loading, loaded) = (2 * self.epoch - 1, 2 * self.epoch);
        let s = self.state[b].load(Acquire);
        if s == loaded {
            return;
        }
        if s != loading && self.state[b].compare_exchange(s, loading, Acquire, Relaxed).is_ok() {
            self.load(b, map, p, cover);
            self.state[b].store(loaded, Release);
            return;
        }
        while self.state[b].load(Acquire) != loaded {
            std::hint::spin_loop();
        }
    }

    fn load(&self, b: usize, map: &EdtMap, p: &Packing, cover: &Cover) {
        let key = cover.key(b);
        let block = map.get(key);
        let first = key.first_voxel().0;
        for offset in 0..BLOCK_VOXELS {
            let v = VoxelIndex([
                first[0] + (offset & 7) as i32,
                first[1] + ((offset >> 3) & 7) as i32,
                first[2] + (offset >> 6) as i32,
            ]);
            let value = match block {
                Some(bl) if bl.to_nearest[offset] != NO_OFFSET && p.region.local(v).is_some() => {
                    p.pack(bl.dist_sq(offset), bl.nearest(key, offset))
                }
                _ => FAR,
            };
            let i = b * BLOCK_VOXELS + offset;
            self.old[i].store(value, Relaxed);
            self.cur[i].store(value, Relaxed);
        }
    }

    /// Bounds of map block `key`'s nearest obstacles, computed once and
    /// cached; `None` for a missing or all-far block.
    pub fn bounds_of(&mut self, map: &EdtMap, key: BlockKey) -> Option<SrcBounds> {
        if let Some(b) = self.bounds.get(&key) {
            return Some(*b);
        }
        let computed = block_bounds(map, key)?;
        self.bounds.insert(key, computed);
        Some(computed)
    }

    /// Forgets every cached bound (the map was changed by other means).
    pub fn forget_all(&mut self) {
        self.bounds.clear();
    }

    /// Forgets the cached bounds of `keys` (their blocks were rewritten).
    pub fn forget(&mut self, keys: &[BlockKey]) {
        for k in keys {
            self.bounds.remove(k);
        }
    }
}

/// Bounds of the nearest obstacles held in map block `key`.
pub fn block_bounds(map: &EdtMap, key: BlockKey) -> Option<SrcBounds> {
    let block = map.get(key)?;
    let mut out: Option<SrcBounds> = None;
    for (offset, o) in block.to_nearest.iter_stored() {
        if o == NO_OFFSET {
            continue;
        }
        let n = block.nearest(key, offset);
        let (lo, hi) = out.get_or_insert((n.0, n.0));
        for a in 0..3 {
            lo[a] = lo[a].min(n.0[a]);
            hi[a] = hi[a].max(n.0[a]);
        }
    }
    out
}
