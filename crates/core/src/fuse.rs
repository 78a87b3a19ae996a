//! Fusion of a frame's observations into the global occupancy map, and the
//! read-back of the local volume's states for the batch EDT.

use std::ops::ControlFlow;

use crate::layers::{Cell, LAYER_VOXELS};
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

/// Adds `obs` to `map` with log-odds `lo`. The touched blocks are first
/// read where they lie: a block none of whose observed voxels changes its
/// log-odds (each is clamped, or the observation leaves it as it is) is
/// left in the map untouched, neither taken out nor copied from a clone
/// of the map that shares it. The others are taken out of the map,
/// updated in parallel (one task per block, so no locks; a block is made
/// only where a voxel of it was observed) and put back.
pub fn fuse(map: &mut OccupancyMap, obs: &Observations, lo: &LogOdds) -> FuseReport {
    let vol = *obs.volume();
    let view: &OccupancyMap = map;
    // Each touched block with an observed voxel: its key, and how many
    // voxels it saw where fusing them writes nothing, `None` where it
    // writes the block (found at the first voxel that changes; the update
    // below counts those blocks' voxels).
    let seen: Vec<(BlockKey, Option<usize>)> = vol
        .blocks()
        .into_par_iter()
        .filter(|&k| obs.block_touched(k))
        .filter_map(|key| {
            let block = view.get(key);
            let mut updated = 0;
            let writes = for_each_seen_row(&vol, key, obs, |i, offset, len, seen| {
                let layer = block.map_or(f32::EMPTY_LAYER, |b| b.log_odds.layer_or_empty(offset / LAYER_VOXELS));
                let cells = &layer[offset % LAYER_VOXELS..offset % LAYER_VOXELS + len];
                for (k, &old) in cells.iter().enumerate().skip(seen) {
                    let o = obs.get(i + k);
                    if o != OBS_NONE {
                        updated += 1;
                        if lo.update(old, o).to_bits() != old.to_bits() {
                            return ControlFlow::Break(());
                        }
                    }
                }
                ControlFlow::Continue(())
            })
            .is_break();
            match (writes, updated) {
                (true, _) => Some((key, None)),
                (false, 0) => None,
                (false, n) => Some((key, Some(n))),
            }
        })
        .collect();
    // (A frame that writes no block leaves the map, and its stamp, as
    // they are.)
    let keys: Vec<BlockKey> = seen.iter().filter(|s| s.1.is_none()).map(|s| s.0).collect();
    let stored = if keys.is_empty() { Vec::new() } else { map.take_shared(&keys) };
    let per_block: Vec<(Option<Box<OccupancyBlock>>, Fused)> = keys
        .par_iter()
        .zip(stored)
        .map(|(&key, stored)| {
            let had = stored.is_some();
            let mut block = stored.map(|b| SharedBlock::into_owned(Some(b)));
            let mut fused = Fused::default();
            // Every row: the update never breaks.
            let _ = for_each_seen_row(&vol, key, obs, |i, offset, len, seen| {
                // The row's layer, made only if a voxel of the row was seen.
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
                ControlFlow::Continue(())
            });
            fused.allocated = !had && block.is_some();
            (block, fused)
        })
        .collect();
    let changed_blocks = keys.iter().zip(&per_block).filter(|(_, (_, f))| f.changed > 0).map(|(k, _)| *k).collect();
    let report = FuseReport {
        voxels_updated: seen.iter().filter_map(|s| s.1).sum::<usize>()
            + per_block.iter().map(|(_, f)| f.updated).sum::<usize>(),
        voxels_changed: per_block.iter().map(|(_, f)| f.changed).sum(),
        changed_blocks,
        blocks_allocated: per_block.iter().filter(|(_, f)| f.allocated).count(),
        rewritten_blocks: per_block.iter().filter(|(_, f)| f.rewritten).count(),
    };
    if !keys.is_empty() {
        map.restore(keys.into_iter().zip(per_block).filter_map(|(k, (b, _))| b.map(|b| (k, b))).collect());
    }
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
/// along x of the block's voxels inside the volume, until `f` breaks.
#[inline]
fn for_each_row(
    vol: &LocalVolume,
    key: BlockKey,
    mut f: impl FnMut(usize, usize, usize) -> ControlFlow<()>,
) -> ControlFlow<()> {
    let [xs, ys, zs] = vol.block_span(key);
    let first = key.first_voxel().0;
    let bx = (vol.origin.0[0] + xs.start as i32 - first[0]) as usize;
    for z in zs {
        let bz = (vol.origin.0[2] + z as i32 - first[2]) as usize;
        for y in ys.clone() {
            let by = (vol.origin.0[1] + y as i32 - first[1]) as usize;
            f(vol.linear([xs.start, y, z]), bx + 8 * (by + 8 * bz), xs.len())?;
        }
    }
    ControlFlow::Continue(())
}

/// [`for_each_row`] of the rows with an observed voxel, with the first
/// such voxel's place in the row: `f(local linear index, offset in block,
/// voxels, first observed)`, until `f` breaks. A row's log-odds are read
/// only when it has one.
#[inline]
fn for_each_seen_row(
    vol: &LocalVolume,
    key: BlockKey,
    obs: &Observations,
    mut f: impl FnMut(usize, usize, usize, usize) -> ControlFlow<()>,
) -> ControlFlow<()> {
    for_each_row(vol, key, |i, offset, len| match (0..len).find(|&k| obs.get(i + k) != OBS_NONE) {
        Some(seen) => f(i, offset, len, seen),
        None => ControlFlow::Continue(()),
    })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{OccupancyParams, VoxelIndex, VoxelState, OBS_HIT, OBS_MISS, UNOBSERVED};
    use std::collections::HashMap;

    /// Frames of seeded random observations over a volume that drifts, most
    /// voxels seen again and again (so most of them reach their clamps):
    /// after each frame every voxel's log-odds is the voxel-by-voxel
    /// update's, the report counts what that update counts, and a block
    /// whose observed voxels all kept their log-odds is the very block a
    /// clone of the map still holds (not taken out, not copied).
    #[test]
    fn fusion_is_the_voxel_by_voxel_update_and_leaves_unchanged_blocks_shared() {
        let lo = OccupancyParams::default().log_odds().expect("defaults");
        let mut map = OccupancyMap::new();
        let mut oracle: HashMap<VoxelIndex, f32> = HashMap::new();
        // A fixed pseudo-random draw per voxel, frame and purpose, below `n`
        // (splitmix64's finaliser over the packed coordinates).
        let draw = |w: VoxelIndex, frame: i32, purpose: u64, n: u64| {
            let packed = [w.0[0], w.0[1], w.0[2], frame].iter().fold(0, |h, &v| (h << 16) ^ (v as u16 as u64));
            let mut z = packed.wrapping_add(0x9E37_79B9_7F4A_7C15u64.wrapping_mul(purpose));
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            (z ^ (z >> 31)) % n
        };
        let mut kept = 0;
        for frame in 0..60 {
            let vol = LocalVolume {
                origin: VoxelIndex([(frame % 5) - 3, -4 + (frame % 2), 1]),
                dims: [21, 19, 11],
                voxel_size_m: 0.1,
            };
            let obs = Observations::new(vol);
            // A wall of hits at world x = 12, free space before it, a voxel
            // in twenty unseen and a rare flicker.
            let voxels = || (0..11).flat_map(|z| (0..19).flat_map(move |y| (0..21).map(move |x| [x, y, z])));
            for c in voxels() {
                let w = vol.world(c);
                let o = match (w.0[0], draw(w, frame, 1, 20), draw(w, frame, 2, 2000)) {
                    (_, _, 0) => OBS_HIT,
                    (_, 0, _) => OBS_NONE,
                    (12, _, _) => OBS_HIT,
                    (x, _, _) if x < 12 => OBS_MISS,
                    _ => OBS_NONE,
                };
                if o != OBS_NONE {
                    obs.mark(c, vol.linear(c), o);
                }
            }
            let before = map.clone();
            let report = fuse(&mut map, &obs, &lo);
            let (mut updated, mut changed, mut changed_blocks) = (0, 0, Vec::new());
            let mut written = std::collections::HashSet::new();
            for c in voxels() {
                let w = vol.world(c);
                let o = obs.get(vol.linear(c));
                if o == OBS_NONE {
                    continue;
                }
                let old = *oracle.get(&w).unwrap_or(&UNOBSERVED);
                let new = lo.update(old, o);
                oracle.insert(w, new);
                updated += 1;
                if lo.state(old) != lo.state(new) {
                    changed += 1;
                    changed_blocks.push(w.block());
                }
                if new.to_bits() != old.to_bits() {
                    written.insert(w.block());
                }
            }
            changed_blocks.sort();
            changed_blocks.dedup();
            let mut reported = report.changed_blocks.clone();
            reported.sort();
            assert_eq!((report.voxels_updated, report.voxels_changed), (updated, changed), "frame {frame}");
            assert_eq!(reported, changed_blocks, "frame {frame}");
            assert_eq!(report.rewritten_blocks, written.len(), "frame {frame}");
            for (&w, &l) in &oracle {
                assert_eq!(map.log_odds(w).to_bits(), l.to_bits(), "frame {frame}, voxel {w:?}");
            }
            for key in vol.blocks() {
                if before.get(key).is_some() && !written.contains(&key) {
                    let (was, now) = (before.shared(key), map.shared(key));
                    assert!(SharedBlock::same(was.as_ref(), now.as_ref()), "frame {frame}, block {key:?} was copied");
                    kept += 1;
                }
            }
            if frame > 3 {
                assert_eq!(lo.state(map.log_odds(VoxelIndex([12, 0, 4]))), VoxelState::Occupied, "frame {frame}");
                assert_eq!(lo.state(map.log_odds(VoxelIndex([5, 0, 4]))), VoxelState::Free, "frame {frame}");
            }
        }
        // Most blocks stop changing once their voxels are clamped.
        assert!(kept > 100, "{kept} blocks left as they were");
    }
}
