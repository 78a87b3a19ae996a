//! Fusion of a frame's observations into the global occupancy map, and the
//! read-back of the local volume's states for the batch EDT.

use crate::Observations;
use crate::{BlockKey, CoreError, Grid3, LocalVolume, LogOdds, OccupancyMap, VoxelState, BLOCK_SIDE, OBS_NONE};
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

/// Adds `obs` to `map` with log-odds `lo`. Blocks with observations are
/// taken out of the map, updated in parallel (one task per block, so no
/// locks) and put back.
pub fn fuse(map: &mut OccupancyMap, obs: &Observations, lo: &LogOdds) -> FuseReport {
    let vol = *obs.volume();
    let keys: Vec<BlockKey> =
        vol.blocks().into_par_iter().filter(|&k| obs.block_touched(k) && block_observed(obs, &vol, k)).collect();
    let before = map.len();
    let mut blocks = map.take(&keys);
    let blocks_allocated = keys.len() - (before - map.len());
    let per_block: Vec<(usize, usize, bool)> = blocks
        .par_iter_mut()
        .map(|(key, block)| {
            let (mut updated, mut changed, mut rewritten) = (0, 0, false);
            for_each_voxel(&vol, *key, |i, offset| {
                let o = obs.get(i);
                if o != OBS_NONE {
                    let old = block.log_odds[offset];
                    let new = lo.update(old, o);
                    block.log_odds[offset] = new;
                    updated += 1;
                    changed += usize::from(lo.state(old) != lo.state(new));
                    rewritten |= new.to_bits() != old.to_bits();
                }
            });
            (updated, changed, rewritten)
        })
        .collect();
    let changed_blocks = keys.iter().zip(&per_block).filter(|(_, c)| c.1 > 0).map(|(k, _)| *k).collect();
    map.restore(blocks);
    FuseReport {
        voxels_updated: per_block.iter().map(|c| c.0).sum(),
        voxels_changed: per_block.iter().map(|c| c.1).sum(),
        changed_blocks,
        blocks_allocated,
        rewritten_blocks: per_block.iter().filter(|c| c.2).count(),
    }
}

fn block_observed(obs: &Observations, vol: &LocalVolume, key: BlockKey) -> bool {
    let mut any = false;
    for_each_voxel(vol, key, |i, _| any |= obs.get(i) != OBS_NONE);
    any
}

/// Calls `f(local linear index, offset in block)` for the block's voxels
/// inside the volume.
#[inline]
fn for_each_voxel(vol: &LocalVolume, key: BlockKey, mut f: impl FnMut(usize, usize)) {
    let [xs, ys, zs] = vol.block_span(key);
    let first = key.first_voxel().0;
    for z in zs {
        let bz = (vol.origin.0[2] + z as i32 - first[2]) as usize;
        for y in ys.clone() {
            let by = (vol.origin.0[1] + y as i32 - first[1]) as usize;
            let row = vol.linear([0, y, z]);
            for x in xs.clone() {
                let bx = (vol.origin.0[0] + x as i32 - first[0]) as usize;
                f(row + x, bx + 8 * (by + 8 * bz));
            }
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
                        let base = v.offset_in_block();
                        for (k, s) in row[x..end].iter_mut().enumerate() {
                            *s = lo.state(b.log_odds[base + k]);
                        }
                    }
                }
                x = end;
            }
        }
    });
    Ok(())
}
