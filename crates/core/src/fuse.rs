//! Fusion of a frame's observations into the global occupancy map, and the
//! read-back of the local volume's states for the batch EDT.

use crate::layers::LAYER_VOXELS;
use crate::Observations;
use crate::{
    BlockKey, CoreError, Grid3, LocalVolume, LogOdds, OccupancyBlock, OccupancyMap, SharedBlock, VoxelState,
    BLOCK_SIDE, OBS_NONE,
};
use rayon::prelude::*;

/// What one fusion changed.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FuseReport {
    /// Voxels that received an observation.
    pub voxels_updated: usize,
    /// Voxels whose state (unknown / free / occupied) changed.
    pub voxels_changed: usize,
    /// Blocks holding a voxel whose state changed, sorted.
    pub changed_blocks: Vec<BlockKey>,
    /// Blocks allocated by this fusion.
    pub blocks_allocated: usize,
    /// Blocks in which some voxel's log-odds changed (what a device that
    /// fuses sends back to the host's map).
    pub rewritten_blocks: usize,
}

/// Adds `obs` to `map` with log-odds `lo`. Blocks that may hold
/// observations are taken out of the map, updated in parallel (one task per
/// block, so no locks; a block is made only where a voxel of it was
/// observed) and put back.
pub fn fuse(map: &mut OccupancyMap, obs: &Observations, lo: &LogOdds) -> FuseReport {
    let vol = *obs.volume();
    let keys: Vec<BlockKey> = vol.blocks().into_par_iter().filter(|&k| obs.block_touched(k)).collect();
    let stored = map.take_shared(&keys);
    let per_block: Vec<(Option<Box<OccupancyBlock>>, Fused)> = keys
        .par_iter()
        .zip(stored)
        .map(|(&key, stored)| {
            let had = stored.is_some();
            let mut block = stored.map(|b| SharedBlock::into_owned(Some(b)));
            let mut fused = Fused::default();
            for_each_row(&vol, key, |i, offset, len| {
                // The row's layer, made only if a voxel of the row was seen.
                let Some(seen) = (0..len).find(|&k| obs.get(i + k) != OBS_NONE) else {
                    return;
                };
                let layer = block.get_or_insert_with(Box::default).log_odds.layer_mut(offset / LAYER_VOXELS);
                let cells = &mut layer[offset % LAYER_VOXELS..offset % LAYER_VOXELS + len];
                for (k, cell) in cells.iter_mut().enumerate().skip(seen) {
                    let o = obs.get(i + k);
                    if o != OBS_NONE {
                        let (old, new) = (*cell, lo.update(*cell, o));
                        *cell = new;
                        fused.updated += 1;
                        fused.changed += usize::from(lo.state(old) != lo.state(new));
                        fused.rewritten |= new.to_bits() != old.to_bits();
                    }
                }
            });
            fused.allocated = !had && block.is_some();
            (block, fused)
        })
        .collect();
    let changed_blocks = keys.iter().zip(&per_block).filter(|(_, (_, f))| f.changed > 0).map(|(k, _)| *k).collect();
    let report = FuseReport {
        voxels_updated: per_block.iter().map(|(_, f)| f.updated).sum(),
        voxels_changed: per_block.iter().map(|(_, f)| f.changed).sum(),
        changed_blocks,
        blocks_allocated: per_block.iter().filter(|(_, f)| f.allocated).count(),
        rewritten_blocks: per_block.iter().filter(|(_, f)| f.rewritten).count(),
    };
    map.restore(keys.into_iter().zip(per_block).filter_map(|(k, (b, _))| b.map(|b| (k, b))).collect());
    report
}

/// What fusion did to one block.
#[derive(Debug, Default)]
struct Fused {
    updated: usize,
    changed: usize,
    rewritten: bool,
    allocated: bool,
}

/// Calls `f(local linear index, offset in block, voxels)` for each row
/// along x of the block's voxels inside the volume.
#[inline]
fn for_each_row(vol: &LocalVolume, key: BlockKey, mut f: impl FnMut(usize, usize, usize)) {
    let [xs, ys, zs] = vol.block_span(key);
    let first = key.first_voxel().0;
    let bx = (vol.origin.0[0] + xs.start as i32 - first[0]) as usize;
    for z in zs {
        let bz = (vol.origin.0[2] + z as i32 - first[2]) as usize;
        for y in ys.clone() {
            let by = (vol.origin.0[1] + y as i32 - first[1]) as usize;
            f(vol.linear([xs.start, y, z]), bx + 8 * (by + 8 * bz), xs.len());
        }
    }
}

/// Fills `out` with the states of `vol`'s voxels from `map`.
pub fn read_states(
    map: &OccupancyMap,
    vol: &LocalVolume,
    lo: &LogOdds,
    out: &mut Grid3<VoxelState>,
) -> Result<(), CoreError> {
    if out.dims() != vol.dims {
        *out = Grid3::from_vec(vol.dims, vec![VoxelState::Unknown; vol.len()])?;
    }
    let [nx, ny, _] = vol.dims;
    out.as_mut_slice().par_chunks_mut(nx * ny).enumerate().for_each(|(z, plane)| {
        for y in 0..ny {
            let row = &mut plane[y * nx..(y + 1) * nx];
            let mut x = 0;
            while x < nx {
                let v = vol.world([x, y, z]);
                let run = (BLOCK_SIDE - v.0[0].rem_euclid(BLOCK_SIDE)) as usize;
                let end = (x + run).min(nx);
                match map.get(v.block()) {
                    None => row[x..end].fill(VoxelState::Unknown),
                    Some(b) => {
                        // A row of a block lies in one layer.
                        let base = v.offset_in_block();
                        let cells = &b.log_odds.layer_or_empty(base / LAYER_VOXELS)[base % LAYER_VOXELS..];
                        for (s, &l) in row[x..end].iter_mut().zip(cells) {
                            *s = lo.state(l);
                        }
                    }
                }
                x = end;
            }
        }
    });
    Ok(())
}
