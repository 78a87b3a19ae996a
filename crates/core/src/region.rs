//! The dense working region of one integration: the blocks of the global
//! EDT a frame can affect, copied into flat arrays, worked on in parallel
//! and written back where they changed.
//!
//! A voxel's value is packed in a `u64`: the squared distance in the high
//! 32 bits and the nearest obstacle's linear index in the *source box*
//! (the region padded by the cutoff's reach, so it holds every obstacle
//! within the cutoff of a region voxel) in the low 32. Comparing packed
//! values orders by distance first, then by obstacle, so an atomic minimum
//! is deterministic. The 32-bit index limits the region, never the map.

use crate::edt_map::offset_dist_sq;
use crate::{
    BlockKey, CoreError, Cutoff, EdtBlock, EdtMap, Grid3, LocalVolume, Obstacles, SharedBlock, VoxelIndex, BLOCK_SIDE,
    BLOCK_VOXELS, FAR_DIST_SQ, NO_OBSTACLE, NO_OFFSET,
};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Packed value of a voxel with no obstacle within the cutoff.
pub const FAR: u64 = u64::MAX;

/// A box of world voxels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Region {
    /// World index of the lowest corner voxel.
    pub origin: [i32; 3],
    /// Voxels along x, y, z.
    pub dims: [usize; 3],
}

impl Region {
    /// The local volume `w` grown by `pad` voxels on every side.
    pub fn around(w: &LocalVolume, pad: i32) -> Region {
        w.region().grown(pad)
    }

    /// This box grown by `pad` voxels on every side.
    pub fn grown(&self, pad: i32) -> Region {
        self.grown_by([pad; 3])
    }

    /// This box grown by `pad[a]` voxels on both sides along each axis `a`.
    pub fn grown_by(&self, pad: [i32; 3]) -> Region {
        Region {
            origin: [0, 1, 2].map(|a| self.origin[a] - pad[a]),
            dims: [0, 1, 2].map(|a| self.dims[a] + 2 * pad[a] as usize),
        }
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// Whether the box holds no voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Linear index of local coordinates `c` (x fastest).
    #[inline]
    pub fn linear(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// Local coordinates of linear index `i`.
    #[inline]
    pub fn coords(&self, i: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [i % nx, (i / nx) % ny, i / (nx * ny)]
    }

    /// Local coordinates of world voxel `v`, if inside.
    #[inline]
    pub fn local(&self, v: VoxelIndex) -> Option<[usize; 3]> {
        let mut c = [0; 3];
        for (a, out) in c.iter_mut().enumerate() {
            let d = i64::from(v.0[a]) - i64::from(self.origin[a]);
            if d < 0 || d >= self.dims[a] as i64 {
                return None;
            }
            *out = d as usize;
        }
        Some(c)
    }

    /// World voxel at local coordinates `c`.
    #[inline]
    pub fn world(&self, c: [usize; 3]) -> VoxelIndex {
        VoxelIndex([0, 1, 2].map(|a| self.origin[a] + c[a] as i32))
    }

    /// The box made of whole blocks from key `lo` to key `hi` inclusive.
    pub fn of_blocks((lo, hi): ([i32; 3], [i32; 3])) -> Region {
        Region {
            origin: lo.map(|b| b * BLOCK_SIDE),
            dims: [0, 1, 2].map(|a| ((hi[a] - lo[a] + 1) * BLOCK_SIDE) as usize),
        }
    }

    /// The smallest box holding every block of `keys`, `None` for none.
    pub fn bounding(keys: &[BlockKey]) -> Option<Region> {
        let first = keys.first()?.0;
        let (lo, hi) = keys.iter().fold((first, first), |(lo, hi), k| {
            ([0, 1, 2].map(|a| lo[a].min(k.0[a])), [0, 1, 2].map(|a| hi[a].max(k.0[a])))
        });
        Some(Region::of_blocks((lo, hi)))
    }

    /// How many blocks [`Self::blocks`] lists, without listing them.
    pub fn block_count(&self) -> usize {
        let last = VoxelIndex([0, 1, 2].map(|a| self.origin[a] + self.dims[a] as i32 - 1)).block().0;
        let first = VoxelIndex(self.origin).block().0;
        (0..3).map(|a| (last[a] - first[a] + 1) as usize).product()
    }

    /// Whether every voxel of block `key` lies in this box.
    pub fn contains_block(&self, key: BlockKey) -> bool {
        let first = key.first_voxel().0;
        (0..3).all(|a| {
            first[a] >= self.origin[a]
                && i64::from(first[a]) + i64::from(BLOCK_SIDE) <= i64::from(self.origin[a]) + self.dims[a] as i64
        })
    }

    /// The blocks this box overlaps.
    pub fn blocks(&self) -> Vec<BlockKey> {
        BlockKey::span(VoxelIndex(self.origin), VoxelIndex([0, 1, 2].map(|a| self.origin[a] + self.dims[a] as i32 - 1)))
    }
}

/// A working region and its source box, with the cutoff.
#[derive(Debug, Clone, Copy)]
pub struct Packing {
    /// The voxels worked on.
    pub region: Region,
    /// The region grown by the cutoff's reach ([`Cutoff::pad`]): where
    /// obstacles may lie.
    pub source: Region,
    /// The cutoff.
    pub cutoff: Cutoff,
}

impl Packing {
    /// The packing for `region`; fails when the source box has more than
    /// 2^32 − 1 voxels.
    pub fn new(region: Region, cutoff: Cutoff) -> Result<Self, CoreError> {
        let source = region.grown_by(cutoff.pad());
        if source.len() >= u32::MAX as usize {
            return Err(CoreError::TooLarge {
                dims: source.dims,
                reason: "integration region beyond 2^32 voxels; lower max_distance_m or the local volume",
            });
        }
        Ok(Packing { region, source, cutoff })
    }

    /// Packs a squared distance and an obstacle's world index.
    #[inline]
    pub fn pack(&self, dist_sq: u32, obstacle: VoxelIndex) -> u64 {
        match self.source.local(obstacle) {
            Some(c) if dist_sq <= self.cutoff.max_dist_sq => (u64::from(dist_sq) << 32) | self.source.linear(c) as u64,
            _ => FAR,
        }
    }

    /// Squared distance and obstacle world index of a packed value.
    #[inline]
    pub fn unpack(&self, value: u64) -> (u32, VoxelIndex) {
        if value == FAR {
            return (FAR_DIST_SQ, NO_OBSTACLE);
        }
        ((value >> 32) as u32, self.source.world(self.source.coords(value as u32 as usize)))
    }

    /// Source-box coordinates of a packed value's obstacle.
    #[inline]
    pub fn source_coords(&self, value: u64) -> [usize; 3] {
        self.source.coords(value as u32 as usize)
    }

    /// Source-box coordinates of region voxel `c`.
    #[inline]
    pub fn region_in_source(&self, c: [usize; 3]) -> [usize; 3] {
        let pad = self.cutoff.pad();
        [0, 1, 2].map(|a| c[a] + pad[a] as usize)
    }
}

/// Fills `old` and `cur` with the packed values of `p.region` from `map`.
pub fn copy_in(map: &EdtMap, p: &Packing, old: &mut Vec<u64>, cur: &mut Vec<AtomicU64>) {
    read_region(map, p, old);
    let n = p.region.len();
    if cur.len() < n {
        cur.resize_with(n, || AtomicU64::new(FAR));
    }
    cur.truncate(n);
    cur.par_iter_mut().zip(old.par_iter()).for_each(|(c, &o)| *c.get_mut() = o);
}

/// Fills `old` with the packed values of `p.region` from `map`.
pub fn read_region(map: &EdtMap, p: &Packing, old: &mut Vec<u64>) {
    read_region_except(map, p, None, old);
}

/// [`read_region`], leaving the voxels inside the world box `keep`
/// untouched (a caller that already holds their values).
pub fn read_region_except(map: &EdtMap, p: &Packing, keep: Option<&Region>, old: &mut Vec<u64>) {
    old.resize(p.region.len(), FAR);
    let [nx, ny, _] = p.region.dims;
    // The x range of each row that `keep` covers, in region coordinates.
    let kept = |y: usize, z: usize| -> std::ops::Range<usize> {
        let Some(k) = keep else { return 0..0 };
        let w = p.region.world([0, y, z]).0;
        let inside = |a: usize| w[a] >= k.origin[a] && w[a] < k.origin[a] + k.dims[a] as i32;
        if !(inside(1) && inside(2)) {
            return 0..0;
        }
        let lo = (i64::from(k.origin[0]) - i64::from(p.region.origin[0])).clamp(0, nx as i64) as usize;
        let hi =
            (i64::from(k.origin[0]) + k.dims[0] as i64 - i64::from(p.region.origin[0])).clamp(0, nx as i64) as usize;
        lo..hi.max(lo)
    };
    old.par_chunks_mut(nx * ny).enumerate().for_each(|(z, old)| {
        for y in 0..ny {
            let skip = kept(y, z);
            let mut x = 0;
            while x < nx {
                if skip.contains(&x) {
                    x = skip.end;
                    continue;
                }
                let v = p.region.world([x, y, z]);
                let mut end = (x + (BLOCK_SIDE - v.0[0].rem_euclid(BLOCK_SIDE)) as usize).min(nx);
                if x < skip.start {
                    end = end.min(skip.start);
                }
                let (key, block) = (v.block(), map.get(v.block()));
                let base = v.offset_in_block();
                for k in 0..end - x {
                    old[y * nx + x + k] = block.map_or(FAR, |b| p.pack(b.dist_sq(base + k), b.nearest(key, base + k)));
                }
                x = end;
            }
        }
    });
}

/// Fills `mask` (resized to `region`) with the obstacles of `region`.
pub fn fill_mask(obstacles: &Obstacles<'_>, region: &Region, mask: &mut Grid3<bool>) -> Result<(), CoreError> {
    if mask.dims() != region.dims {
        *mask = Grid3::from_vec(region.dims, vec![false; Grid3::<bool>::voxel_count(region.dims)?])?;
    }
    let nx = region.dims[0];
    mask.as_mut_slice().par_chunks_mut(nx).enumerate().for_each(|(row, out)| {
        let (y, z) = (row % region.dims[1], row / region.dims[1]);
        obstacles.fill_row(region.world([0, y, z]), out);
    });
    Ok(())
}

/// What writing a region back changed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriteBack {
    /// Voxels whose distance or nearest obstacle changed.
    pub voxels_changed: usize,
    /// Sum over those voxels of |new − old| distance in voxels, distances
    /// truncated at the cutoff (the numerator of the paper's change score).
    pub change_sum_vox: f64,
    /// Blocks holding a changed voxel, sorted.
    pub changed_blocks: Vec<BlockKey>,
}

impl WriteBack {
    /// The integration's report: this write-back over `region_voxels`
    /// voxels, with the wavefront's counters.
    pub fn into_report(self, region_voxels: usize, waves: crate::WaveCounts) -> crate::IntegrationReport {
        crate::IntegrationReport {
            voxels_changed: self.voxels_changed,
            change_sum_vox: self.change_sum_vox,
            changed_blocks: self.changed_blocks,
            region_voxels,
            waves,
            exact: crate::ExactCounts::default(),
        }
    }
}

/// Writes the voxels of `p.region` in the blocks `candidates` whose value
/// differs from `old` into `map`, allocating blocks as needed and dropping
/// blocks left all far.
pub fn write_back(map: &mut EdtMap, p: &Packing, candidates: &[BlockKey], old: &[u64], cur: &[AtomicU64]) -> WriteBack {
    write_back_with(map, p, candidates, old, |i| cur[i].load(Relaxed))
}

/// [`write_back`] with the new values given by `cur(region_linear)`.
pub fn write_back_with(
    map: &mut EdtMap,
    p: &Packing,
    candidates: &[BlockKey],
    old: &[u64],
    cur: impl Fn(usize) -> u64 + Sync,
) -> WriteBack {
    write_back_where(map, p, candidates, |_, i, _| old[i], |_, i, _| cur(i))
}

/// [`write_back`] with the old and new values of each voxel given by
/// `old(k, region_linear, offset_in_block)` and `cur(…)`, `k` the index of
/// its block in `candidates`: for a caller holding them per block.
pub fn write_back_where(
    map: &mut EdtMap,
    p: &Packing,
    candidates: &[BlockKey],
    old: impl Fn(usize, usize, usize) -> u64 + Sync,
    cur: impl Fn(usize, usize, usize) -> u64 + Sync,
) -> WriteBack {
    let truncated = |v: u64| {
        let reach = f64::from(p.cutoff.max_dist_sq).sqrt();
        if v == FAR {
            reach
        } else {
            ((v >> 32) as f64).sqrt().min(reach)
        }
    };
    let per_block: Vec<(usize, usize, f64)> = candidates
        .par_iter()
        .enumerate()
        .map(|(k, &key)| {
            let (mut changed, mut sum) = (0, 0.0);
            for_region_voxels(p, key, |i, offset| {
                let (o, n) = (old(k, i, offset), cur(k, i, offset));
                if o != n {
                    changed += 1;
                    sum += (truncated(n) - truncated(o)).abs();
                }
            });
            (k, changed, sum)
        })
        .filter(|&(_, changed, _)| changed > 0)
        .collect();
    let keys: Vec<BlockKey> = per_block.iter().map(|b| candidates[b.0]).collect();
    let mut taken = map.take(&keys);
    taken.par_iter_mut().zip(per_block.par_iter()).for_each(|((key, block), &(k, _, _))| {
        for_region_voxels(p, *key, |i, offset| {
            let (d, o) = p.unpack(cur(k, i, offset));
            block.put(*key, offset, d, o);
        });
    });
    taken.retain_mut(|(_, b)| !b.trim());
    map.restore(taken);
    WriteBack {
        voxels_changed: per_block.iter().map(|b| b.1).sum(),
        change_sum_vox: per_block.iter().map(|b| b.2).sum(),
        changed_blocks: keys,
    }
}

/// [`write_back_where`] for a caller that has each voxel's new value as
/// the offset to its nearest obstacle, [`crate::NO_OFFSET`] beyond the
/// cutoff: `new(k, values)` fills the offsets of block `candidates[k]`, in
/// block order (those outside the region are not read), every offset
/// within the cutoff. Compares with the map's
/// own offsets (those beyond the cutoff counting as none) and stores the
/// new ones as they are, with no packing, unpacking or check per voxel:
/// the same map and the same report as [`write_back_where`] given the
/// packed values, in a third of the time (a GPU's write-back, where the
/// device's words are offsets already).
pub fn write_back_offsets(
    map: &mut EdtMap,
    p: &Packing,
    candidates: &[BlockKey],
    new: impl Fn(usize, &mut [[i16; 3]; BLOCK_VOXELS]) + Sync,
) -> WriteBack {
    let max = p.cutoff.max_dist_sq;
    let reach = f64::from(max).sqrt();
    let within = |o: [i16; 3]| if offset_dist_sq(o) <= max { o } else { NO_OFFSET };
    let truncated = |o: [i16; 3]| {
        let d = offset_dist_sq(o);
        if d == FAR_DIST_SQ {
            reach
        } else {
            f64::from(d).sqrt().min(reach)
        }
    };
    let stored = map.take_shared(candidates);
    let per_block: Vec<(usize, f64, Option<SharedBlock<EdtBlock>>)> = stored
        .into_par_iter()
        .enumerate()
        .map(|(k, block)| {
            let (mut changed, mut sum) = (0, 0.0);
            let old = |off: usize| block.as_ref().map_or(NO_OFFSET, |b| within(b.get().to_nearest[off]));
            let mut values = [NO_OFFSET; BLOCK_VOXELS];
            new(k, &mut values);
            let mut visit = |off: usize| {
                let (o, n) = (old(off), values[off]);
                if o != n {
                    changed += 1;
                    sum += (truncated(n) - truncated(o)).abs();
                }
            };
            let inside = p.region.contains_block(candidates[k]);
            if inside {
                (0..BLOCK_VOXELS).for_each(&mut visit);
            } else {
                for_region_voxels(p, candidates[k], |_, off| visit(off));
            }
            if changed == 0 {
                return (0, 0.0, block);
            }
            let mut owned = SharedBlock::into_owned(block);
            if inside {
                owned.to_nearest.assign(&values);
            } else {
                for_region_voxels(p, candidates[k], |_, off| owned.to_nearest.set(off, values[off]));
            }
            (changed, sum, (!owned.trim()).then(|| SharedBlock::new(owned)))
        })
        .collect();
    let changed_blocks = candidates.iter().zip(&per_block).filter(|(_, b)| b.0 > 0).map(|(k, _)| *k).collect();
    let voxels_changed = per_block.iter().map(|b| b.0).sum();
    let change_sum_vox = per_block.iter().filter(|b| b.0 > 0).map(|b| b.1).sum();
    map.restore_shared(candidates.iter().zip(per_block).filter_map(|(k, b)| b.2.map(|s| (*k, s))).collect());
    WriteBack { voxels_changed, change_sum_vox, changed_blocks }
}

/// Calls `f(region_linear, offset_in_block)` for every voxel of block
/// `key` inside the region.
fn for_region_voxels(p: &Packing, key: BlockKey, mut f: impl FnMut(usize, usize)) {
    let first = key.first_voxel().0;
    let r = &p.region;
    let span = |a: usize| {
        let lo = (first[a] - r.origin[a]).max(0);
        let hi = (first[a] + BLOCK_SIDE - r.origin[a]).min(r.dims[a] as i32);
        lo..hi
    };
    let (xs, ys, zs) = (span(0), span(1), span(2));
    for z in zs {
        for y in ys.clone() {
            for x in xs.clone() {
                let c = [x as usize, y as usize, z as usize];
                let offset = (x + r.origin[0] - first[0])
                    + 8 * ((y + r.origin[1] - first[1]) + 8 * (z + r.origin[2] - first[2]));
                f(r.linear(c), offset as usize);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_count_counts_the_listed_blocks() {
        for r in [
            Region { origin: [-3, 4, -20], dims: [10, 7, 3] },
            Region { origin: [0, 0, 0], dims: [8, 8, 8] },
            Region { origin: [-1, -9, 7], dims: [1, 17, 2] },
        ] {
            assert_eq!(r.block_count(), r.blocks().len(), "{r:?}");
        }
    }

    #[test]
    fn pack_round_trip_and_order() {
        let cutoff = Cutoff { max_dist_sq: 25, reach: 5, planar: false };
        let p = Packing::new(Region { origin: [-3, 4, -20], dims: [10, 7, 3] }, cutoff).expect("small");
        let o = VoxelIndex([-8, 0, -17]);
        let v = p.pack(16, o);
        assert_eq!(p.unpack(v), (16, o));
        assert!(p.pack(9, VoxelIndex([6, 15, -14])) < v, "nearer sorts first");
        assert_eq!(p.pack(26, o), FAR, "beyond the cutoff");
        assert_eq!(p.pack(4, VoxelIndex([-9, 0, -17])), FAR, "outside the source box");
    }

    #[test]
    fn write_back_then_copy_in_round_trips() {
        let cutoff = Cutoff { max_dist_sq: 100, reach: 10, planar: false };
        let p = Packing::new(Region { origin: [-5, -9, 2], dims: [13, 6, 9] }, cutoff).expect("small");
        let mut map = EdtMap::new();
        let (mut old, mut cur) = (Vec::new(), Vec::new());
        copy_in(&map, &p, &mut old, &mut cur);
        assert!(old.iter().all(|&v| v == FAR));
        let obstacle = VoxelIndex([0, -4, 5]);
        for (i, c) in cur.iter().enumerate() {
            let v = p.region.world(p.region.coords(i));
            let d: i64 = (0..3).map(|a| i64::from(v.0[a] - obstacle.0[a]).pow(2)).sum();
            c.store(p.pack(d as u32, obstacle), Relaxed);
        }
        let wb = write_back(&mut map, &p, &p.region.blocks(), &old, &cur);
        assert_eq!(wb.voxels_changed, p.region.len());
        assert_eq!(map.entry(VoxelIndex([3, -4, 5])), (9, obstacle));
        let (mut again, mut cur2) = (Vec::new(), Vec::new());
        copy_in(&map, &p, &mut again, &mut cur2);
        assert_eq!(again, cur.iter().map(|c| c.load(Relaxed)).collect::<Vec<_>>());
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 64, rng_seed: proptest::test_runner::RngSeed::Fixed(0x0FF5), ..Default::default() })]
        /// The offsets' write-back leaves the map and the report that the
        /// packed one does, from maps with blocks missing, values beyond
        /// the cutoff and voxels outside the region, and new values that
        /// empty whole blocks.
        #[test]
        fn offsets_write_back_is_the_packed_one(
            seed in 0u64..u64::MAX,
            origin in proptest::array::uniform3(-12i32..12),
            dims in proptest::array::uniform3(1usize..20),
            far_share in 0u64..4,
        ) {
            let mut state = seed | 1;
            let mut next = move |n: u64| { state ^= state << 13; state ^= state >> 7; state ^= state << 17; state % n };
            let cutoff = Cutoff { max_dist_sq: 30, reach: 5, planar: false };
            let p = Packing::new(Region { origin, dims }, cutoff).expect("small");
            let keys = p.region.grown(8).blocks();
            let mut map = EdtMap::new();
            for &key in &keys {
                if next(3) == 0 {
                    continue;
                }
                let block = map.get_or_insert(key);
                for o in 0..crate::BLOCK_VOXELS {
                    // Some stored values lie beyond the cutoff.
                    block.to_nearest.set(o, if next(4) < far_share { NO_OFFSET } else { [0, 1, 2].map(|_| next(15) as i16 - 7) });
                }
            }
            let candidates = p.region.blocks();
            let new: Vec<[i16; 3]> = (0..candidates.len() * crate::BLOCK_VOXELS)
                .map(|i| {
                    let o = [0, 1, 2].map(|_| next(11) as i16 - 5);
                    // A third of the blocks go far; a voxel is unchanged now and then.
                    if (i / crate::BLOCK_VOXELS).is_multiple_of(3) || offset_dist_sq(o) > 30 || next(4) == 0 { NO_OFFSET } else { o }
                })
                .collect();
            let (mut a, mut b) = (map.clone(), map);
            let cur = |k: usize, _: usize, off: usize| {
                let key = candidates[k];
                let o = new[k * crate::BLOCK_VOXELS + off];
                let v = key.voxel(off);
                if o == NO_OFFSET { FAR } else { p.pack(offset_dist_sq(o), VoxelIndex([0, 1, 2].map(|a| v.0[a] + i32::from(o[a])))) }
            };
            let packed_old: Vec<Vec<u64>> = candidates.iter().map(|&key| (0..crate::BLOCK_VOXELS).map(|off| a.get(key).map_or(FAR, |blk| p.pack(blk.dist_sq(off), blk.nearest(key, off)))).collect()).collect();
            let want = write_back_where(&mut a, &p, &candidates, |k, _, off| packed_old[k][off], cur);
            let got = write_back_offsets(&mut b, &p, &candidates, |k, out| out.copy_from_slice(&new[k * crate::BLOCK_VOXELS..(k + 1) * crate::BLOCK_VOXELS]));
            proptest::prop_assert_eq!(&got, &want);
            let blocks = |m: &EdtMap| { let mut v: Vec<(BlockKey, EdtBlock)> = m.iter().map(|(k, b)| (k, b.clone())).collect(); v.sort_by_key(|e| e.0); v };
            proptest::prop_assert!(blocks(&a) == blocks(&b), "maps differ");
        }
    }
}
