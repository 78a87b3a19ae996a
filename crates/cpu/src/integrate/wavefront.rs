//! Wavefront integration (paper §IV-C, Algorithms 2 and 3) on the dense
//! working region: the window `W` grown by the cutoff's reach plus one.
//!
//! 1. *Raise* (frontier A and its in-window twin): every voxel whose nearest
//!    obstacle lies in `W` and is an obstacle no more loses its value. The
//!    whole region is scanned rather than walked from the vanished
//!    obstacles, so a Voronoi cell that is not connected is still raised.
//! 2. *Window*: each voxel of `W` takes the minimum of the batch EDT
//!    (exact for obstacles inside `W`) and its old value if that is still
//!    valid, which keeps obstacles outside `W` that the batch cannot see
//!    (frontier C, the paper's limited observation).
//! 3. *Seeds*: every voxel whose value went down (frontier B: new obstacles,
//!    nearer ones) and every valid neighbour of a voxel whose value went up
//!    (the raised region's border, to re-lower it).
//! 4. *Lower* (Algorithm 3's twin): level-synchronous waves in parallel. A
//!    level reads its frontier's values as they stood when it began and
//!    lowers neighbours with an atomic minimum of packed (distance,
//!    obstacle), so every level — and the result — is the same for any
//!    thread count. Nothing beyond the cutoff is written.

use super::region::{write_back, Packing, Region, WriteBack, FAR};
use edtmap_core::{BlockKey, EdtBlock};
use edtmap_core::{EdtField, EdtMap, LocalVolume, VoxelIndex, BLOCK_SIDE, FAR_DIST_SQ, NO_SITE};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering::Relaxed};

/// Counters of one wavefront integration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WaveCounts {
    /// Voxels whose nearest obstacle vanished (frontier A and inside `W`).
    pub raised: usize,
    /// Window voxels that kept a nearer obstacle from outside the window
    /// (frontier C).
    pub kept_outside: usize,
    /// Voxels the lowering waves started from.
    pub seeds: usize,
    /// Levels the lowering waves took.
    pub levels: usize,
    /// Successful lowerings (a voxel can be lowered more than once).
    pub lowered: usize,
}

/// Reusable buffers of the wavefront.
#[derive(Debug, Default)]
pub struct WaveBuffers {
    old: Vec<u64>,
    cur: Vec<AtomicU64>,
    stamp: Vec<AtomicU32>,
    dirty: Vec<AtomicBool>,
}

/// The region's blocks: which ones a change touched.
struct Dirty<'a> {
    first: [i32; 3],
    dims: [usize; 3],
    origin: [i32; 3],
    flags: &'a [AtomicBool],
}

impl Dirty<'_> {
    #[inline]
    fn mark(&self, c: [usize; 3]) {
        let b = [0, 1, 2].map(|a| ((self.origin[a] + c[a] as i32).div_euclid(BLOCK_SIDE) - self.first[a]) as usize);
        self.flags[b[0] + self.dims[0] * (b[1] + self.dims[1] * b[2])].store(true, Relaxed);
    }

    fn keys(&self) -> Vec<BlockKey> {
        let [bx, by, _] = self.dims;
        (0..self.flags.len())
            .filter(|&i| self.flags[i].load(Relaxed))
            .map(|i| BlockKey([self.first[0] + (i % bx) as i32, self.first[1] + ((i / bx) % by) as i32, self.first[2] + (i / (bx * by)) as i32]))
            .collect()
    }
}

/// Merges the batch EDT of `window` into `map`.
pub fn integrate_wavefront(
    map: &mut EdtMap,
    window: &LocalVolume,
    batch: &EdtField,
    packing: &Packing,
    offsets: &[[i32; 3]],
    buf: &mut WaveBuffers,
) -> (WriteBack, WaveCounts) {
    let r = &packing.region;
    let first = VoxelIndex(r.origin).block().0;
    let last = VoxelIndex([0, 1, 2].map(|a| r.origin[a] + r.dims[a] as i32 - 1)).block().0;
    let bdims = [0, 1, 2].map(|a| (last[a] - first[a] + 1) as usize);
    buf.dirty.resize_with(bdims.iter().product(), || AtomicBool::new(false));
    buf.dirty.truncate(bdims.iter().product());
    buf.dirty.par_iter().for_each(|d| d.store(false, Relaxed));
    buf.stamp.resize_with(r.len(), || AtomicU32::new(0));
    buf.stamp.par_iter().for_each(|s| s.store(0, Relaxed));
    let (mut counts, went_down, went_up) = read_and_merge(map, window, batch, packing, buf);
    let dirty = Dirty { first, dims: bdims, origin: r.origin, flags: &buf.dirty };
    for &i in went_down.iter().chain(&went_up) {
        dirty.mark(r.coords(i as usize));
    }
    let seeds = seed(packing, offsets, &went_down, &went_up, &buf.cur, &buf.stamp);
    counts.seeds = seeds.len();
    (counts.levels, counts.lowered) = lower(packing, offsets, seeds, &buf.cur, &buf.stamp, &dirty);
    let keys = dirty.keys();
    (write_back(map, packing, &keys, &buf.old, &buf.cur), counts)
}

/// Steps 1 and 2, fused with reading the region from the map: raise
/// vanished obstacles' voxels and merge the window. Returns the counters
/// and the voxels whose value went down and up.
fn read_and_merge(map: &EdtMap, window: &LocalVolume, batch: &EdtField, p: &Packing, buf: &mut WaveBuffers) -> (WaveCounts, Vec<u32>, Vec<u32>) {
    let n = p.region.len();
    buf.old.resize(n, FAR);
    if buf.cur.len() < n {
        buf.cur.resize_with(n, || AtomicU64::new(FAR));
    }
    buf.cur.truncate(n);
    let w = Region { origin: window.origin.0, dims: window.dims };
    let (dist, near) = (batch.dist_sq_vox(), batch.nearest());
    let [nx, ny, _] = p.region.dims;
    let side = BLOCK_SIDE as usize;
    let (raised, kept, down, up) = buf
        .old
        .par_chunks_mut(nx * ny)
        .zip(buf.cur.par_chunks(nx * ny))
        .enumerate()
        .map(|(z, (old, cur))| {
            let (mut raised, mut kept, mut down, mut up) = (0, 0, Vec::new(), Vec::new());
            // One hash lookup per block of this plane, not per row.
            let lead = [0, 1].map(|a| p.region.origin[a].rem_euclid(BLOCK_SIDE) as usize);
            let cols = (lead[0] + nx).div_ceil(side);
            let mut blocks: Vec<Option<&EdtBlock>> = Vec::new();
            for y in 0..ny {
                if y == 0 || (y + lead[1]) % side == 0 {
                    blocks = (0..cols).map(|bx| map.get(p.region.world([(bx * side).saturating_sub(lead[0]), y, z]).block())).collect();
                }
                let v0 = p.region.world([0, y, z]);
                let (wy, wz) = (v0.0[1] - w.origin[1], v0.0[2] - w.origin[2]);
                let row_in_window = wy >= 0 && wz >= 0 && (wy as usize) < w.dims[1] && (wz as usize) < w.dims[2];
                let base_yz = v0.offset_in_block() - v0.0[0].rem_euclid(BLOCK_SIDE) as usize;
                for x in 0..nx {
                    let bx = (x + lead[0]) / side;
                    let offset = base_yz + (x + lead[0]) % side;
                    let (value, src_in_window) = match blocks[bx] {
                        Some(b) if b.dist_sq[offset] != FAR_DIST_SQ => (p.pack(b.dist_sq[offset], b.nearest[offset]), w.local(b.nearest[offset]).map(|c| w.linear(c))),
                        _ => (FAR, None),
                    };
                    let vanished = src_in_window.is_some_and(|s| dist[s] != 0);
                    raised += usize::from(vanished);
                    let valid = if vanished { FAR } else { value };
                    let wx = v0.0[0] + x as i32 - w.origin[0];
                    let new = if row_in_window && wx >= 0 && (wx as usize) < w.dims[0] {
                        let l = w.linear([wx as usize, wy as usize, wz as usize]);
                        let b = if near[l] == NO_SITE { FAR } else { p.pack(dist[l], window.world(w.coords(near[l] as usize))) };
                        kept += usize::from(valid < b && src_in_window.is_none());
                        b.min(valid)
                    } else {
                        valid
                    };
                    let i = y * nx + x;
                    old[i] = value;
                    cur[i].store(new, Relaxed);
                    let global = (z * nx * ny + i) as u32;
                    if new < value {
                        down.push(global);
                    } else if new > value {
                        up.push(global);
                    }
                }
            }
            (raised, kept, down, up)
        })
        .reduce(|| (0, 0, Vec::new(), Vec::new()), |mut a, b| {
            a.2.extend(b.2);
            a.3.extend(b.3);
            (a.0 + b.0, a.1 + b.1, a.2, a.3)
        });
    (WaveCounts { raised, kept_outside: kept, ..Default::default() }, down, up)
}

/// Step 3: voxels that went down, and valid neighbours of voxels that went up.
fn seed(p: &Packing, offsets: &[[i32; 3]], down: &[u32], up: &[u32], cur: &[AtomicU64], stamp: &[AtomicU32]) -> Vec<(u32, u64)> {
    let mark = |i: usize| stamp[i].swap(1, Relaxed) != 1;
    let mut ids: Vec<u32> = down.par_iter().copied().filter(|&i| mark(i as usize)).collect();
    let around: Vec<u32> = up
        .par_iter()
        .fold(Vec::new, |mut acc, &i| {
            for_neighbours(&p.region, p.region.coords(i as usize), offsets, |n, _| {
                if cur[n].load(Relaxed) != FAR && mark(n) {
                    acc.push(n as u32);
                }
            });
            acc
        })
        .flatten()
        .collect();
    ids.extend(around);
    ids.into_par_iter().map(|i| (i, cur[i as usize].load(Relaxed))).collect()
}

/// Step 4: lowering waves until no voxel changes; returns (levels, lowerings).
fn lower(p: &Packing, offsets: &[[i32; 3]], mut frontier: Vec<(u32, u64)>, cur: &[AtomicU64], stamp: &[AtomicU32], dirty: &Dirty<'_>) -> (usize, usize) {
    let (mut levels, mut lowered) = (0, 0);
    let max = p.cutoff.max_dist_sq as i64;
    let reach = p.cutoff.reach as i64;
    while !frontier.is_empty() {
        levels += 1;
        let level = levels as u32 + 1;
        let (next, count): (Vec<u32>, usize) = frontier
            .par_iter()
            .fold(
                || (Vec::new(), 0),
                |(mut acc, mut count), &(i, value)| {
                    let src = p.source_coords(value).map(|x| x as i64);
                    for_neighbours(&p.region, p.region.coords(i as usize), offsets, |n, c| {
                        let d: i64 = (0..3).map(|a| (c[a] as i64 + reach - src[a]).pow(2)).sum();
                        if d > max {
                            return;
                        }
                        let cand = ((d as u64) << 32) | (value & 0xffff_ffff);
                        if cand < cur[n].load(Relaxed) && cand < cur[n].fetch_min(cand, Relaxed) {
                            count += 1;
                            if stamp[n].swap(level, Relaxed) != level {
                                dirty.mark(c);
                                acc.push(n as u32);
                            }
                        }
                    });
                    (acc, count)
                },
            )
            .reduce(|| (Vec::new(), 0), |(mut a, x), (b, y)| {
                a.extend(b);
                (a, x + y)
            });
        lowered += count;
        frontier = next.into_par_iter().map(|i| (i, cur[i as usize].load(Relaxed))).collect();
    }
    (levels, lowered)
}

/// Calls `f(linear, coords)` for each neighbour of the voxel at `c` inside `r`.
#[inline]
fn for_neighbours(r: &Region, c: [usize; 3], offsets: &[[i32; 3]], mut f: impl FnMut(usize, [usize; 3])) {
    for o in offsets {
        let n = [0, 1, 2].map(|a| c[a] as i64 + i64::from(o[a]));
        if (0..3).all(|a| n[a] >= 0 && n[a] < r.dims[a] as i64) {
            let n = n.map(|x| x as usize);
            f(r.linear(n), n);
        }
    }
}
