//! Wavefront integration (paper §IV-C, Algorithms 2 and 3) on the working
//! region, the window `W` grown by the cutoff's reach plus one, loaded
//! lazily block by block ([`super::lazy`]).
//!
//! 1. *Raise* (frontier A and its in-window twin): every voxel whose nearest
//!    obstacle lies in `W` and is an obstacle no more loses its value. Every
//!    block whose cached obstacle bounds meet the vanished obstacles' box is
//!    scanned, rather than walking from the vanished obstacles, so a
//!    Voronoi cell that is not connected is still raised.
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

use super::lazy::{Cover, LazyRegion, SrcBounds};
use edtmap_core::backend::WaveCounts;
use edtmap_core::region::{Packing, WriteBack, FAR};
use edtmap_core::{BlockKey, EdtField, EdtMap, LocalVolume, VoxelIndex, BLOCK_SIDE, BLOCK_VOXELS, NO_SITE};
use rayon::prelude::*;
use std::sync::atomic::Ordering::Relaxed;

/// Reusable buffers of the wavefront.
pub type WaveBuffers = LazyRegion;

/// Frontiers smaller than this are lowered on one thread.
const SERIAL_LEVEL: usize = 1024;

/// What the frame's setup found: voxels that went down and up, and the box
/// of the obstacles that vanished.
struct Changes {
    down: Vec<u32>,
    up: Vec<u32>,
    vanished: Option<SrcBounds>,
    raised: usize,
    kept: usize,
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
    let cover = Cover::of(packing.region);
    buf.begin(&cover);
    let w = window.region();
    let touches_window = |b: usize| {
        let first = cover.key(b).first_voxel().0;
        (0..3).all(|a| first[a] + BLOCK_SIDE > w.origin[a] && first[a] < w.origin[a] + w.dims[a] as i32)
    };
    let window_blocks: Vec<usize> = (0..cover.blocks()).filter(|&b| touches_window(b)).collect();
    let mut ch = scan_blocks(map, window, batch, packing, &cover, buf, &window_blocks, true);
    if let Some((lo, hi)) = ch.vanished {
        // Blocks outside the window that may hold a voxel whose obstacle vanished.
        let mut others = Vec::new();
        for b in (0..cover.blocks()).filter(|&b| !touches_window(b)) {
            if let Some((blo, bhi)) = buf.bounds_of(map, cover.key(b)) {
                if (0..3).all(|a| blo[a] <= hi[a] && bhi[a] >= lo[a]) {
                    others.push(b);
                }
            }
        }
        let more = scan_blocks(map, window, batch, packing, &cover, buf, &others, false);
        ch.down.extend(more.down);
        ch.up.extend(more.up);
        ch.raised += more.raised;
    }
    for &i in ch.down.iter().chain(&ch.up) {
        buf.dirty[i as usize / BLOCK_VOXELS].store(true, Relaxed);
    }
    let mut counts = WaveCounts { raised: ch.raised, kept_outside: ch.kept, ..Default::default() };
    {
        let ctx = Ctx { map, p: packing, cover: &cover, buf, offsets };
        let seeds = ctx.seed(&ch.down, &ch.up);
        counts.seeds = seeds.len();
        (counts.levels, counts.lowered) = ctx.lower(seeds);
    }
    let dirty: Vec<usize> = (0..cover.blocks()).filter(|&b| buf.dirty[b].load(Relaxed)).collect();
    (write_back_blocks(map, packing, &cover, buf, &dirty), counts)
}

/// Steps 1 and 2 on `blocks`: loads them, raises voxels whose obstacle
/// vanished and, with `merge`, merges the window's voxels.
#[allow(clippy::too_many_arguments)]
fn scan_blocks(
    map: &EdtMap,
    window: &LocalVolume,
    batch: &EdtField,
    p: &Packing,
    cover: &Cover,
    buf: &LazyRegion,
    blocks: &[usize],
    merge: bool,
) -> Changes {
    let w = window.region();
    let (dist, near) = (batch.dist_sq_vox(), batch.nearest());
    blocks
        .par_iter()
        .map(|&b| {
            buf.ensure(b, map, p, cover);
            let mut ch = Changes { down: Vec::new(), up: Vec::new(), vanished: None, raised: 0, kept: 0 };
            let key = cover.key(b);
            let Some(stored) = map.get(key) else {
                if merge {
                    // Nothing stored: every old value is far, only the window merges.
                    scan_block_voxels(&mut ch, b, key, cover, buf, |_, v, _| {
                        let l = w.local(v)?;
                        let l = w.linear(l);
                        Some(if near[l] == NO_SITE {
                            FAR
                        } else {
                            p.pack(dist[l], window.world(w.coords(near[l] as usize)))
                        })
                    });
                }
                return ch;
            };
            scan_block_voxels(&mut ch, b, key, cover, buf, |ch, v, offset| {
                let old = buf.old[b * BLOCK_VOXELS + offset].load(Relaxed);
                let src_in_window =
                    (old != FAR).then(|| w.local(stored.nearest(key, offset)).map(|l| w.linear(l))).flatten();
                let vanished = src_in_window.is_some_and(|s| dist[s] != 0);
                ch.raised += usize::from(vanished);
                let valid = if vanished { FAR } else { old };
                match w.local(v).filter(|_| merge) {
                    Some(l) => {
                        let l = w.linear(l);
                        if old != FAR && (old >> 32) == 0 && dist[l] != 0 {
                            grow(&mut ch.vanished, v.0);
                        }
                        let b = if near[l] == NO_SITE {
                            FAR
                        } else if src_in_window == Some(near[l] as usize) && u64::from(dist[l]) == old >> 32 {
                            // The usual case: the batch agrees with the map.
                            old
                        } else {
                            p.pack(dist[l], window.world(w.coords(near[l] as usize)))
                        };
                        ch.kept += usize::from(valid < b && src_in_window.is_none());
                        Some(b.min(valid))
                    }
                    None => Some(valid),
                }
            });
            ch
        })
        .reduce(
            || Changes { down: Vec::new(), up: Vec::new(), vanished: None, raised: 0, kept: 0 },
            |mut a, b| {
                a.down.extend(b.down);
                a.up.extend(b.up);
                if let Some((lo, hi)) = b.vanished {
                    grow(&mut a.vanished, lo);
                    grow(&mut a.vanished, hi);
                }
                a.raised += b.raised;
                a.kept += b.kept;
                a
            },
        )
}

/// Calls `new_value(changes, voxel, offset)` for every voxel of block `b`
/// inside the region; stores the value it returns (none: unchanged) and
/// records whether it went down or up.
fn scan_block_voxels(
    ch: &mut Changes,
    b: usize,
    key: BlockKey,
    cover: &Cover,
    buf: &LazyRegion,
    mut new_value: impl FnMut(&mut Changes, VoxelIndex, usize) -> Option<u64>,
) {
    let first = key.first_voxel().0;
    let r = &cover.region;
    let span = |a: usize| {
        let lo = (r.origin[a] - first[a]).max(0);
        let hi = (r.origin[a] + r.dims[a] as i32 - first[a]).min(BLOCK_SIDE);
        lo..hi
    };
    let (xs, ys, zs) = (span(0), span(1), span(2));
    for z in zs {
        for y in ys.clone() {
            for x in xs.clone() {
                let offset = (x + 8 * (y + 8 * z)) as usize;
                let v = VoxelIndex([first[0] + x, first[1] + y, first[2] + z]);
                let i = b * BLOCK_VOXELS + offset;
                let old = buf.old[i].load(Relaxed);
                let Some(new) = new_value(ch, v, offset) else { continue };
                buf.cur[i].store(new, Relaxed);
                if new < old {
                    ch.down.push(i as u32);
                } else if new > old {
                    ch.up.push(i as u32);
                }
            }
        }
    }
}

fn grow(bounds: &mut Option<SrcBounds>, v: [i32; 3]) {
    let (lo, hi) = bounds.get_or_insert((v, v));
    for a in 0..3 {
        lo[a] = lo[a].min(v[a]);
        hi[a] = hi[a].max(v[a]);
    }
}

/// What the waves read.
struct Ctx<'a> {
    map: &'a EdtMap,
    p: &'a Packing,
    cover: &'a Cover,
    buf: &'a LazyRegion,
    offsets: &'a [[i32; 3]],
}

impl Ctx<'_> {
    /// Calls `f(index, coords)` for each neighbour of `c` in the region,
    /// its block loaded.
    #[inline]
    fn neighbours(&self, c: [usize; 3], f: impl FnMut(usize, [usize; 3])) {
        self.neighbours_where(c, |_| true, f);
    }

    /// [`Self::neighbours`] in the directions `keep` accepts.
    #[inline]
    fn neighbours_where(&self, c: [usize; 3], keep: impl Fn(&[i32; 3]) -> bool, mut f: impl FnMut(usize, [usize; 3])) {
        for o in self.offsets.iter().filter(|o| keep(o)) {
            let n = [0, 1, 2].map(|a| c[a] as i64 + i64::from(o[a]));
            if n.iter().any(|&x| x < 0) {
                continue;
            }
            let n = n.map(|x| x as usize);
            if !(0..3).all(|a| n[a] < self.cover.bdims[a] * 8) || !self.cover.in_region(n) {
                continue;
            }
            let i = self.cover.index(n);
            self.buf.ensure(i / BLOCK_VOXELS, self.map, self.p, self.cover);
            f(i, n);
        }
    }

    /// Step 3: voxels that went down, and valid neighbours of voxels that went up.
    fn seed(&self, down: &[u32], up: &[u32]) -> Vec<(u32, u64)> {
        let tag = u64::from(self.buf.epoch()) << 32;
        let mark = |i: usize| self.buf.stamp[i].swap(tag | 1, Relaxed) != tag | 1;
        let mut ids: Vec<u32> = down.par_iter().copied().filter(|&i| mark(i as usize)).collect();
        let around: Vec<u32> = up
            .par_iter()
            .fold(Vec::new, |mut acc, &i| {
                self.neighbours(self.cover.coords(i as usize), |n, _| {
                    if self.buf.cur[n].load(Relaxed) != FAR && mark(n) {
                        acc.push(n as u32);
                    }
                });
                acc
            })
            .flatten()
            .collect();
        ids.extend(around);
        ids.into_par_iter().map(|i| (i, self.buf.cur[i as usize].load(Relaxed))).collect()
    }

    /// Step 4: lowering waves until no voxel changes; returns (levels, lowerings).
    fn lower(&self, mut frontier: Vec<(u32, u64)>) -> (usize, usize) {
        let (mut levels, mut lowered) = (0, 0);
        let max = self.p.cutoff.max_dist_sq as i64;
        // Cover coordinates plus `shift` are source-box coordinates.
        let shift = [0, 1, 2].map(|a| i64::from(self.cover.origin[a] - self.p.source.origin[a]));
        let tag = u64::from(self.buf.epoch()) << 32;
        while !frontier.is_empty() {
            levels += 1;
            let stamp = tag | (levels as u64 + 1);
            let relax = |(mut acc, mut count): (Vec<u32>, usize), &(i, value): &(u32, u64)| {
                let src = self.p.source_coords(value).map(|x| x as i64);
                let cv = self.cover.coords(i as usize);
                // Lower only away from the obstacle (or across): a neighbour nearer
                // to it is reached from the obstacle's side, as in DynamicEDT3D.
                let away = [0, 1, 2].map(|a| cv[a] as i64 + shift[a] - src[a]);
                let outward = |o: &[i32; 3]| (0..3).map(|a| i64::from(o[a]) * away[a]).sum::<i64>() >= 0;
                self.neighbours_where(cv, outward, |n, c| {
                    let d: i64 = (0..3).map(|a| (c[a] as i64 + shift[a] - src[a]).pow(2)).sum();
                    if d > max {
                        return;
                    }
                    let cand = ((d as u64) << 32) | (value & 0xffff_ffff);
                    let cur = &self.buf.cur[n];
                    if cand < cur.load(Relaxed) && cand < cur.fetch_min(cand, Relaxed) {
                        count += 1;
                        if self.buf.stamp[n].swap(stamp, Relaxed) != stamp {
                            self.buf.dirty[n / BLOCK_VOXELS].store(true, Relaxed);
                            acc.push(n as u32);
                        }
                    }
                });
                (acc, count)
            };
            // The paper's hierarchical frontiers on a CPU: a small level runs on
            // one thread, a large one is split across all of them. Either way a
            // level reads the values its frontier had when it began.
            let (next, count): (Vec<u32>, usize) = if frontier.len() < SERIAL_LEVEL {
                frontier.iter().fold((Vec::new(), 0), relax)
            } else {
                frontier.par_iter().fold(|| (Vec::new(), 0), relax).reduce(
                    || (Vec::new(), 0),
                    |(mut a, x), (b, y)| {
                        a.extend(b);
                        (a, x + y)
                    },
                )
            };
            lowered += count;
            frontier = next.iter().map(|&i| (i, self.buf.cur[i as usize].load(Relaxed))).collect();
        }
        (levels, lowered)
    }
}

/// Writes the changed voxels of the `dirty` blocks into `map`, drops
/// blocks left all far and refreshes their cached bounds.
fn write_back_blocks(map: &mut EdtMap, p: &Packing, cover: &Cover, buf: &mut LazyRegion, dirty: &[usize]) -> WriteBack {
    let reach = f64::from(p.cutoff.max_dist_sq).sqrt();
    let truncated = |v: u64| if v == FAR { reach } else { ((v >> 32) as f64).sqrt().min(reach) };
    let keys: Vec<BlockKey> = dirty.iter().map(|&b| cover.key(b)).collect();
    let mut taken = map.take(&keys);
    let (old, cur) = (&buf.old, &buf.cur);
    let per_block: Vec<(usize, f64)> = taken
        .par_iter_mut()
        .zip(dirty)
        .map(|((key, block), &b)| {
            let (mut changed, mut sum) = (0, 0.0);
            for offset in 0..BLOCK_VOXELS {
                let i = b * BLOCK_VOXELS + offset;
                let (o, n) = (old[i].load(Relaxed), cur[i].load(Relaxed));
                if o != n && cover.in_region(cover.coords(i)) {
                    changed += 1;
                    sum += (truncated(n) - truncated(o)).abs();
                    let (d, src) = p.unpack(n);
                    block.put(*key, offset, d, src);
                }
            }
            (changed, sum)
        })
        .collect();
    let mut changed_blocks = Vec::new();
    for ((key, _), &(changed, _)) in taken.iter().zip(&per_block) {
        buf.bounds.remove(key);
        if changed > 0 {
            changed_blocks.push(*key);
        }
    }
    taken.retain_mut(|(_, b)| !b.trim());
    map.restore(taken);
    changed_blocks.sort_unstable();
    WriteBack {
        voxels_changed: per_block.iter().map(|b| b.0).sum(),
        change_sum_vox: per_block.iter().map(|b| b.1).sum(),
        changed_blocks,
    }
}
