//! Exact integration whose cost follows what changed: the separable EDT
//! (x, then y, then z), kept up to date line by line.
//!
//! The batch EDT of §IV-B is three passes of one-dimensional scans: along
//! x, the distance to the nearest obstacle of the row (`g1`); along y, the
//! nearest of the slice (`g2 = min_y' g1 + (y - y')²`); along z, the
//! nearest of the volume (`d = min_z' g2 + (z - z')²`). With the cutoff,
//! every value beyond it is as good as none, so an entry depends only on
//! the entries of the previous pass within the reach along its line. This
//! backend keeps `g1` and `g2` of the whole map between frames, as offsets
//! to the nearest obstacle, next to the global EDT (the last pass). When
//! obstacles appear or vanish, only the rows through them are scanned
//! again (over their changes grown by the reach); then only the columns
//! through the `g1` entries that changed, and only the lines through the
//! `g2` entries that changed, are brought up to date. A changed entry of
//! value `f` (the smaller of its old and new) can matter only `sqrt(max -
//! f)` along the next pass. The work follows the changed entries of each
//! pass, however large the window.
//!
//! **Lowered and raised entries.** In passes y and z each changed entry is
//! either lowered (its value fell) or not. An output whose nearest entry
//! (its site, the position it was computed from) did not rise can only
//! fall, and only to a lowered entry: its new value is the smaller of its
//! old one and the lower envelope of the lowered entries alone, which
//! needs neither the unchanged inputs nor a scan of them. Over each piece
//! of that envelope (one entry's parabola), the old outputs capped past
//! the cutoff, less the parabola, are concave along the line (a minimum of
//! linear functions), so the outputs it beats are one run, walked out
//! from the entry's own position (or from the peak, found by bisection,
//! when the piece does not beat the old output there), not read over the
//! entry's whole reach.
//! Only the outputs whose site rose or changed without falling are
//! rescanned from all their inputs, as DynamicEDT3D's raise waves are.
//! Sites never decrease along a line, so the outputs fed by each such
//! entry are one run too, found by bisecting on the sites. When obstacles
//! only appear, no input is read but the lowered entries themselves.
//!
//! **Exact, and the batch EDT's answer.** A rescanned line is scanned by
//! the batch EDT's own kernels (`sweep_row`, Meijster's `envelope`) from
//! inputs that are all current, over its outputs grown by the reach. Ties
//! go to the lowest position along each axis, as in the batch EDT: each
//! output is the least (value, site position) over its inputs, so a
//! lowered output is the least of its old (value, site) and the lowered
//! envelope's, the same answer. The map equals an exact batch EDT of the
//! obstacles, the nearest obstacles included (what the GPU's exact mode
//! computes), bit for bit.
//!
//! **The cache.** `g1` and `g2` are functions of the obstacles the global
//! EDT holds (its voxels at distance 0). They are kept for the map whose
//! [`MapStamp`] this backend last wrote; for any other map (changed by
//! something else, loaded from a file) they are rebuilt from its obstacles
//! before the frame, in the same passes.

use crate::awake::{awake, share_out};
use crate::edt::envelope::{envelope, sweep_row, EnvelopeScratch, Line};
use edtmap_core::layers::prefetch;
use edtmap_core::{
    BlockKey, BlockMap, Cutoff, EdtBlock, EdtMap, ExactCounts, IntegrationReport, MapStamp, Obstacles, SharedBlock,
    VoxelIndex, WaveCounts, BLOCK_SIDE, BLOCK_VOXELS, FAR_DIST_SQ, NO_OFFSET, NO_SITE, UNREACHABLE_DIST_SQ,
};
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use std::ops::Range;

/// No obstacle within the cutoff.
const NONE: i16 = i16::MIN;
/// No obstacle within the cutoff, for `g2`.
const NONE2: [i16; 2] = [NONE, NONE];

/// `g1` of one block: offset along x to the row's nearest obstacle.
type G1Block = [i16; BLOCK_VOXELS];
/// `g2` of one block: offsets along x and y to the slice's nearest obstacle.
type G2Block = [[i16; 2]; BLOCK_VOXELS];
/// An entry of the global EDT (pass z's output): squared distance and the
/// offset to the nearest obstacle, as [`EdtBlock`] holds them.
type Out = (u32, [i16; 3]);

/// The first two passes of the separable EDT of the global map, kept
/// between frames.
#[derive(Debug, Default)]
pub struct SeparableCache {
    g1: FxHashMap<BlockKey, Box<G1Block>>,
    g2: FxHashMap<BlockKey, Box<G2Block>>,
    /// The map and cutoff `g1` and `g2` belong to.
    valid_for: Option<(MapStamp, Cutoff)>,
    /// Square roots up to the last cutoff's squared distance.
    roots: Option<Roots>,
}

impl SeparableCache {
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        let per = |n: usize, b: usize| n * (b + std::mem::size_of::<BlockKey>() + 16);
        per(self.g1.len(), std::mem::size_of::<G1Block>()) + per(self.g2.len(), std::mem::size_of::<G2Block>())
    }

    /// Forgets everything (the next update rebuilds from the map).
    pub fn forget(&mut self) {
        self.g1.clear();
        self.g2.clear();
        self.valid_for = None;
    }
}

/// Brings `map`, the exact EDT of the obstacles it held, up to date with
/// `obstacles`, whose changes lie in `blocks`; returns what changed.
///
/// Runs on a thread of rayon's pool: its parallel loops, most of them one
/// task on a small frame, then run inline, where each started from another
/// thread would hand its work to the pool and wait for a thread to wake.
/// The pool's other threads are kept [`awake`] meanwhile: between its ten
/// or so loops they fell asleep, and each loop then waited for a wake-up
/// (3dmatch-seq01 at 2 m: 8.93 → 8.60 ms a frame).
pub fn update_exact(
    map: &mut EdtMap,
    obstacles: &Obstacles<'_>,
    blocks: &[BlockKey],
    cutoff: Cutoff,
    cache: &mut SeparableCache,
) -> IntegrationReport {
    awake(|| update_in_pool(map, obstacles, blocks, cutoff, cache))
}

fn update_in_pool(
    map: &mut EdtMap,
    obstacles: &Obstacles<'_>,
    blocks: &[BlockKey],
    cutoff: Cutoff,
    cache: &mut SeparableCache,
) -> IntegrationReport {
    let roots = match cache.roots.take() {
        Some(r) if r.max == cutoff.max_dist_sq => r,
        _ => Roots::new(cutoff.max_dist_sq),
    };
    let pass = Pass { reach: cutoff.reach, max: cutoff.max_dist_sq, planar: cutoff.planar, roots: &roots };
    if cache.valid_for != Some((map.stamp(), cutoff)) {
        rebuild(map, &pass, cache);
    }
    // Obstacles that appeared or vanished: the map's against `obstacles`,
    // one mask per block. The map's obstacles are its `g1` entries at 0
    // (a third of the bytes of its EDT blocks, and compared 16 at a time).
    let (g1, edt): (_, &EdtMap) = (&cache.g1, map);
    let found = share_out(
        blocks.iter().copied(),
        blocks.len() >= 2 * MIN_TASKS,
        || (),
        |(), key| {
            let now = obstacles.block_bits(key);
            let mut m = now;
            if let Some(b) = g1.get(&key) {
                for (w, o) in m.iter_mut().zip(mask_where(b, |&d| d == 0)) {
                    *w ^= o;
                }
            }
            // Counted for the report: obstacles that appeared (flipped and
            // there now), those of them with no obstacle among their 26
            // neighbours before, and those that vanished.
            let mut counts = [0; 3];
            let old = edt.get(key);
            for (i, (&f, &o)) in m.iter().zip(&now).enumerate() {
                let mut added = f & o;
                counts[0] += added.count_ones() as usize;
                counts[2] += (f & !o).count_ones() as usize;
                while added != 0 {
                    let at = 64 * i + added.trailing_zeros() as usize;
                    added &= added - 1;
                    counts[1] += usize::from(old.is_none_or(|b| b.dist_sq(at) > 3));
                }
            }
            (counts[0] + counts[2] != 0).then_some((key, m, counts))
        },
    );
    let mut counts = [0; 3];
    let flips: Dirty = found
        .into_iter()
        .flatten()
        .map(|(key, m, c)| {
            for (t, c) in counts.iter_mut().zip(c) {
                *t += c;
            }
            (key, m)
        })
        .collect();
    let dirty = flips.iter().map(|(&k, &m)| (k, m, None)).collect();
    let mut report = run_passes(map, &pass, cache, dirty, &flips, true);
    [report.exact.obstacles_added, report.exact.obstacles_added_apart, report.exact.obstacles_removed] = counts;
    cache.valid_for = Some((map.stamp(), cutoff));
    cache.roots = Some(roots);
    report
}

/// Rebuilds `g1` and `g2` from the map's obstacles (its voxels at distance 0).
fn rebuild(map: &mut EdtMap, pass: &Pass<'_>, cache: &mut SeparableCache) {
    cache.forget();
    let obstacles: Marked = map
        .iter()
        .collect::<Vec<_>>()
        .par_iter()
        .filter_map(|&(key, block)| {
            Some(obstacle_bits(block)).filter(|m| m.iter().any(|&w| w != 0)).map(|m| (key, m, None))
        })
        .collect();
    run_passes(map, pass, cache, obstacles, &Dirty::default(), false);
}

/// Small frames stay on one thread rather than pay for waking the others:
/// half the fewest blocks the flip test, and the fewest tasks (lines of
/// blocks) or dirty blocks a pass, shares out among threads ([`shared`]).
const MIN_TASKS: usize = 16;

/// Whether a pass of `n` tasks (lines of blocks, with `blocks` dirty
/// blocks among them) is shared out among threads ([`share_out`]): not
/// when there are fewer than `2 * MIN_TASKS` of both, nor four tasks or
/// fewer. Counting the blocks too shares out a pass of few but long
/// lines: pass x of 3dmatch-seq01 at 2 m has some 30 tasks of 16 µs each.
fn shared(n: usize, blocks: usize) -> bool {
    (n >= 2 * MIN_TASKS || blocks >= 2 * MIN_TASKS) && n > 4
}

/// One bit per voxel of a block, by offset.
type Mask = [u64; 8];
/// Voxels to look at, per block.
type Dirty = FxHashMap<BlockKey, Mask>;
/// How the entries of a block that a pass changed changed.
#[derive(Debug)]
struct Changed {
    /// How far along the next pass each can matter, voxels: `sqrt(max -
    /// f)` for the smaller of its old and new values `f`.
    radius: [u16; BLOCK_VOXELS],
    /// Those whose value fell.
    lowered: Mask,
}

/// The blocks a pass looks at: key, voxels, and how they changed (after
/// pass x or y). Handed from one pass to the next as a list, which the
/// next sorts by its lines: no look-up by key.
type Marked = Vec<(BlockKey, Mask, Option<Box<Changed>>)>;

/// The voxels of a block's values `v` (by offset) where `hit` holds, 64
/// to a word (the test inlined, so it vectorises).
#[inline]
fn mask_where<T>(v: &[T; BLOCK_VOXELS], hit: impl Fn(&T) -> bool) -> Mask {
    let mut m = [0u64; 8];
    for (w, d) in m.iter_mut().zip(v.chunks_exact(64)) {
        *w = d.iter().enumerate().fold(0, |a, (i, d)| a | u64::from(hit(d)) << i);
    }
    m
}

/// The obstacles of an EDT block: its voxels at distance 0.
fn obstacle_bits(b: &EdtBlock) -> Mask {
    b.to_nearest.mask_where(|d| d == [0; 3])
}

fn bit(m: &Mask, o: usize) -> bool {
    m[o / 64] >> (o % 64) & 1 == 1
}

/// The voxels of `m` on each line along `axis` through a block: entry `u +
/// 8 v` for the line at `(u, v)` in the block's other two axes, bit `t` for
/// its voxel `t` along `axis`.
fn line_bits(m: &Mask, axis: usize) -> [u8; 64] {
    let mut out = [0u8; 64];
    match axis {
        // Line (y, z) is byte y of word z.
        0 => {
            for (v, w) in m.iter().enumerate() {
                out[8 * v..8 * v + 8].copy_from_slice(&w.to_le_bytes());
            }
        }
        // Line (x, z): bits x, x + 8, .., x + 56 of word z, gathered into
        // the top byte by one multiplication.
        1 => {
            for (v, &w) in m.iter().enumerate() {
                for u in 0..8 {
                    out[u + 8 * v] = ((w >> u & 0x0101_0101_0101_0101).wrapping_mul(0x0102_0408_1020_4080) >> 56) as u8;
                }
            }
        }
        // Line (x, y): bit x + 8 y of each word z. For each y, the bytes
        // y of the eight words are an 8 x 8 bit matrix whose transpose
        // holds the lines (x, y): a fixed cost, where a loop over the set
        // bits took up to 8 times as long on a full block (pass z's dirty
        // blocks mostly are).
        _ => {
            for y in 0..8 {
                let rows = m.iter().enumerate().fold(0u64, |a, (z, &w)| a | (w >> (8 * y) & 0xFF) << (8 * z));
                out[8 * y..8 * y + 8].copy_from_slice(&transpose_bits(rows).to_le_bytes());
            }
        }
    }
    out
}

/// The transpose of an 8 x 8 bit matrix held as byte `r` = row `r`, bit
/// `c` = column `c`: three exchanges of blocks across the diagonal.
fn transpose_bits(mut x: u64) -> u64 {
    for (shift, mask) in [(7, 0x00AA_00AA_00AA_00AA), (14, 0x0000_CCCC_0000_CCCC), (28, 0x0000_0000_F0F0_F0F0)] {
        let t = (x ^ (x >> shift)) & mask;
        x ^= t ^ (t << shift);
    }
    x
}

/// The three passes from the rows through `dirty` (obstacles flipped where
/// `flips` says); the last, into `map`, only when `last`.
fn run_passes(
    map: &mut EdtMap,
    pass: &Pass<'_>,
    cache: &mut SeparableCache,
    dirty: Marked,
    flips: &Dirty,
    last: bool,
) -> IntegrationReport {
    let SeparableCache { g1, g2, .. } = cache;
    // Pass x: the rows through the obstacles that changed.
    let edt: &EdtMap = map;
    let (value1, value2) = (g1_value, g2_value);
    let (dirty1, x) = drive(
        &mut Cached { map: g1, none: NONE },
        0,
        dirty,
        None::<&Rescan>,
        pass,
        |s, seg, _, out| pass.row(edt, flips, seg, s, out),
        value1,
        |_, _| 0.0,
    );
    // Pass y: the columns through the g1 entries that changed.
    let g1: &FxHashMap<_, _> = g1;
    let (dirty2, y) = drive(
        &mut Cached { map: g2, none: NONE2 },
        1,
        dirty1,
        Some(&LowerY { g1 }),
        pass,
        |s, seg, col, out| pass.column(g1, col, seg, s, out),
        value2,
        |_, _| 0.0,
    );
    if !last {
        return IntegrationReport::default();
    }
    // Pass z: the lines through the g2 entries that changed, into the map.
    let g2: &FxHashMap<_, _> = g2;
    // The distance, at most the cutoff (FAR included).
    // (The table and the cutoff copied in: read through `pass` they were
    // loaded again after every write of the lowering.)
    let (exact, max) = (&pass.roots.exact[..], pass.max);
    let truncated = move |d: u32| root(exact, d.min(max));
    let amount = |o: Out, n: Out| (truncated(n.0) - truncated(o.0)).abs();
    let (changed, z) = if pass.planar {
        in_layer(map, dirty2, g2, max, amount)
    } else {
        drive(
            map,
            2,
            dirty2,
            Some(&LowerZ { g2 }),
            pass,
            |s, seg, col, out| pass.depth(g2, col, seg, s, out),
            |v: Out| v.0,
            amount,
        )
    };
    let mut changed_blocks: Vec<BlockKey> = changed.into_iter().map(|c| c.0).collect();
    changed_blocks.sort_unstable();
    let passes = [x, y, z];
    IntegrationReport {
        voxels_changed: z.changed,
        change_sum_vox: z.sum,
        changed_blocks,
        region_voxels: z.visited,
        waves: WaveCounts::default(),
        exact: ExactCounts {
            changed: passes.map(|p| p.changed),
            nearest_only: passes.map(|p| p.same),
            rescanned: passes.map(|p| p.rescanned),
            visited: passes.map(|p| p.visited),
            ..ExactCounts::default()
        },
    }
}

/// Pass z of a planar map: each voxel's distance is its own layer's, its
/// `g2` entry within the cutoff, so only the outputs at the `g2` entries
/// that changed (`dirty`) are written, each from its entry alone. Returns
/// the blocks written and what changed, as [`drive`] does.
fn in_layer(
    map: &mut EdtMap,
    dirty: Marked,
    g2: &FxHashMap<BlockKey, Box<G2Block>>,
    max: u32,
    amount: impl Fn(Out, Out) -> f64 + Sync,
) -> (Marked, Stats) {
    let keys: Vec<BlockKey> = dirty.iter().map(|e| e.0).collect();
    let taken = map.take_shared(&keys);
    let written: Vec<(BlockKey, Option<SharedBlock<EdtBlock>>, Mask, Stats)> = share_out(
        dirty.into_iter().zip(taken),
        shared(keys.len(), keys.len()),
        || (),
        |(), ((key, mask, _), block)| {
            let mut block = SharedBlock::into_owned(block);
            let input = g2.get(&key);
            let (mut st, mut out) = (Stats::default(), [0u64; 8]);
            for (w, &bits) in mask.iter().enumerate() {
                let mut bits = bits;
                while bits != 0 {
                    let o = 64 * w + bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    let e = input.map_or(NONE2, |b| b[o]);
                    let d = g2_value(e);
                    let new = if d > max { (FAR_DIST_SQ, NO_OFFSET) } else { (d, [e[0], e[1], 0]) };
                    let old = block.stored(o);
                    st.visited += 1;
                    if old != new {
                        block.to_nearest.set(o, new.1);
                        out[w] |= 1 << (o % 64);
                        st.changed += 1;
                        st.same += usize::from(old.0 == new.0);
                        st.sum += amount(old, new);
                    }
                }
            }
            let back = (!block.trim()).then(|| SharedBlock::new(block));
            (key, back, out, st)
        },
    );
    let mut stats = Stats::default();
    let mut back = Vec::new();
    let mut changed = Marked::new();
    for (key, block, mask, st) in written {
        stats.add(st);
        if let Some(b) = block {
            back.push((key, b));
        }
        if mask.iter().any(|&w| w != 0) {
            changed.push((key, mask, None));
        }
    }
    map.restore_shared(back);
    (changed, stats)
}

/// A layer of per-voxel values in blocks, taken out to be written by one
/// task and put back.
trait Layer: Sync {
    /// Whether a pass follows this one (and needs to know how each entry
    /// changed).
    const FEEDS_NEXT: bool;
    type Block: Send + Sync;
    type Value: Copy + PartialEq + Send + Sync;
    /// A block as taken out of the layer, not yet writable.
    type Taken: Send;
    /// A block as put back.
    type Back: Send;
    /// Takes the blocks at `keys` out (the serial half: the writable
    /// blocks are made by [`Layer::own`] in each task, on its thread).
    fn take(&mut self, keys: &[BlockKey]) -> Vec<Self::Taken>;
    /// The writable block of one taken out (a new one where there was
    /// none).
    fn own(&self, t: Self::Taken) -> Box<Self::Block>;
    /// A written block, to put back.
    fn give(b: Box<Self::Block>) -> Self::Back;
    fn get(&self, key: BlockKey) -> Option<&Self::Block>;
    /// Puts blocks back (the caller leaves out those [`Layer::empty`]
    /// says hold nothing).
    fn restore(&mut self, blocks: Vec<(BlockKey, Self::Back)>);
    /// Whether the block holds nothing worth keeping (no value within the
    /// cutoff), freeing what it need not keep.
    fn empty(&self, b: &mut Self::Block) -> bool;
    /// Asks for the block's cache lines without waiting for them.
    fn warm(b: &Self::Block) {
        prefetch(b);
    }
    fn read(b: &Self::Block, o: usize) -> Self::Value;
    fn write(b: &mut Self::Block, o: usize, v: Self::Value);
}

/// A cache layer, `none` where no obstacle is within the cutoff.
struct Cached<'a, T> {
    map: &'a mut FxHashMap<BlockKey, Box<[T; BLOCK_VOXELS]>>,
    none: T,
}

impl<T: Copy + PartialEq + Send + Sync> Layer for Cached<'_, T> {
    const FEEDS_NEXT: bool = true;
    type Block = [T; BLOCK_VOXELS];
    type Value = T;
    type Taken = Option<Box<Self::Block>>;
    type Back = Box<Self::Block>;
    fn take(&mut self, keys: &[BlockKey]) -> Vec<Self::Taken> {
        keys.iter().map(|k| self.map.remove(k)).collect()
    }
    fn own(&self, t: Self::Taken) -> Box<Self::Block> {
        t.unwrap_or_else(|| Box::new([self.none; BLOCK_VOXELS]))
    }
    fn give(b: Box<Self::Block>) -> Self::Back {
        b
    }
    fn get(&self, key: BlockKey) -> Option<&Self::Block> {
        self.map.get(&key).map(|b| &**b)
    }
    fn restore(&mut self, blocks: Vec<(BlockKey, Self::Back)>) {
        self.map.extend(blocks);
    }
    fn empty(&self, b: &mut Self::Block) -> bool {
        b.iter().all(|&t| t == self.none)
    }
    #[inline]
    fn read(b: &Self::Block, o: usize) -> T {
        b[o]
    }
    #[inline]
    fn write(b: &mut Self::Block, o: usize, v: T) {
        b[o] = v;
    }
}

impl Layer for EdtMap {
    const FEEDS_NEXT: bool = false;
    type Block = EdtBlock;
    type Value = Out;
    type Taken = Option<SharedBlock<EdtBlock>>;
    type Back = SharedBlock<EdtBlock>;
    fn take(&mut self, keys: &[BlockKey]) -> Vec<Self::Taken> {
        BlockMap::take_shared(self, keys)
    }
    fn own(&self, t: Self::Taken) -> Box<EdtBlock> {
        SharedBlock::into_owned(t)
    }
    fn give(b: Box<EdtBlock>) -> Self::Back {
        SharedBlock::new(b)
    }
    fn get(&self, key: BlockKey) -> Option<&EdtBlock> {
        EdtMap::get(self, key)
    }
    fn restore(&mut self, blocks: Vec<(BlockKey, Self::Back)>) {
        BlockMap::restore_shared(self, blocks);
    }
    fn empty(&self, b: &mut EdtBlock) -> bool {
        b.trim()
    }
    fn warm(b: &EdtBlock) {
        b.to_nearest.prefetch();
    }
    #[inline]
    fn read(b: &EdtBlock, o: usize) -> Out {
        b.stored(o)
    }
    #[inline]
    fn write(b: &mut EdtBlock, o: usize, v: Out) {
        b.to_nearest.set(o, v.1);
    }
}

/// What one pass changed, and what it read to find it.
#[derive(Debug, Default, Clone, Copy)]
struct Stats {
    /// Entries changed.
    changed: usize,
    /// Of those, entries whose value stayed (only where it comes from
    /// changed).
    same: usize,
    /// The pass's `amount` summed over the changed entries.
    sum: f64,
    /// Outputs rescanned.
    rescanned: usize,
    /// Outputs read.
    visited: usize,
}

impl Stats {
    fn add(&mut self, o: Stats) {
        self.changed += o.changed;
        self.same += o.same;
        self.sum += o.sum;
        self.rescanned += o.rescanned;
        self.visited += o.visited;
    }
}

/// The two axes other than `axis`, in order.
fn others(axis: usize) -> [usize; 2] {
    match axis {
        0 => [1, 2],
        1 => [0, 2],
        _ => [0, 1],
    }
}

/// Calls `f(key, offset, stride, range)` for each block that the `n`
/// positions of `line` along `axis` from `first` cross: the block's key,
/// the offset in it of the first of them, the offset step along `axis`,
/// and which of the `n` positions lie in it.
fn by_block(
    line: [i32; 3],
    axis: usize,
    first: i32,
    n: usize,
    mut f: impl FnMut(BlockKey, usize, usize, Range<usize>),
) {
    let stride = [1, 8, 64][axis];
    let mut i = 0;
    while i < n {
        let p = first + i as i32;
        let t = p.rem_euclid(BLOCK_SIDE) as usize;
        let len = (BLOCK_SIDE as usize - t).min(n - i);
        let v = at_axis(line, axis, p);
        f(v.block(), v.offset_in_block(), stride, i..i + len);
        i += len;
    }
}

/// Offset in a block of the voxel at `t` along `axis` on line `(u, v)`.
fn local(axis: usize, u: usize, v: usize, t: usize) -> usize {
    let mut c = [0; 3];
    let [b, d] = others(axis);
    (c[axis], c[b], c[d]) = (t, u, v);
    c[0] + 8 * (c[1] + 8 * c[2])
}

/// A task's blocks: coordinate along the axis, block, voxels changed and
/// how they changed.
type Owned<B> = Vec<(i32, Box<B>, Mask, Option<Box<Changed>>)>;

/// One segment of a line: its first voxel's coordinates (the `axis`
/// coordinate unused) and the changes it covers, `lo..=hi` along `axis`
/// (its outputs `lo - reach ..= hi + reach`), and how far its inputs reach
/// past its outputs on each side (the reach, or less where passes y and z
/// know that no input further away can be nearest).
#[derive(Debug, Clone, Copy)]
struct Segment {
    line: [i32; 3],
    lo: i32,
    hi: i32,
    margin: (i32, i32),
}

impl Segment {
    /// The first input and the number of inputs of a scan of this
    /// segment: its outputs grown by its margins.
    fn inputs(&self, reach: i32) -> (i32, usize) {
        let base = self.lo - reach - self.margin.0;
        (base, (self.hi + reach + self.margin.1 - base + 1) as usize)
    }
}

/// The work of one line: outputs to recompute from all their inputs
/// (`segments`, outputs `lo - reach ..= hi + reach`), then outputs to lower
/// from the entries that were lowered (`lower`: outputs `a..=b` and the
/// range of `entries` that can reach them).
#[derive(Debug, Default)]
struct LineWork {
    line: [i32; 3],
    segments: Range<usize>,
    lower: Range<usize>,
    risen: Range<usize>,
}

/// A lowering range of a line, `a..=z`, and its entries' place among the
/// plan's entries.
type Lowering = (i32, i32, Range<usize>);

/// A task's plan: its lines, their segments, their lowering ranges and the
/// positions of the lowered entries, and the blocks they write.
#[derive(Debug, Default)]
struct Plan {
    lines: Vec<LineWork>,
    segments: Vec<Segment>,
    lower: Vec<Lowering>,
    entries: Vec<i32>,
    /// The entries that rose (or changed without falling): position and
    /// the run where their outputs can be, searched in the task's blocks
    /// once they are warm.
    risen: Vec<(i32, i32, i32)>,
    /// Where the rescans of the risen entries' outputs can write: their
    /// runs joined where less than twice the reach apart, as [`rescans`]
    /// joins the outputs found in them.
    spans: Vec<(i32, i32)>,
    owned: Vec<i32>,
    visited: usize,
    /// The task's first dirty block and the last one's coordinate along
    /// the axis.
    dirty: (BlockKey, i32),
}

/// How a pass's outputs follow from its inputs, for the outputs lowered
/// directly by the entries that were lowered.
trait Lower<V>: Sync {
    type Entry: Copy;
    /// Squared distance and position along the axis of the entry output
    /// `o` at `q` comes from; `None` for no obstacle.
    fn key(&self, q: i32, o: V) -> Option<(u32, i32)>;
    /// A block of the previous pass's layer.
    type In: Sync;
    /// The previous pass's block at `key`.
    fn input(&self, key: BlockKey) -> Option<&Self::In>;
    /// The entry at offset `o` of block `b` (none where there is no block)
    /// with its squared distance, `UNREACHABLE_DIST_SQ` for none.
    fn entry(&self, b: Option<&Self::In>, o: usize) -> (u32, Self::Entry);
    /// The output at `q` of `line` from entry `e` at `p`, `d` away.
    fn make(&self, line: [i32; 3], q: i32, p: i32, d: u32, e: Self::Entry) -> V;
}

/// Pass x has no previous pass to follow: its rows are always rescanned.
struct Rescan;

impl Lower<i16> for Rescan {
    type Entry = ();
    type In = ();
    fn key(&self, _: i32, _: i16) -> Option<(u32, i32)> {
        None
    }
    fn input(&self, _: BlockKey) -> Option<&()> {
        None
    }
    fn entry(&self, _: Option<&()>, _: usize) -> (u32, ()) {
        (UNREACHABLE_DIST_SQ, ())
    }
    fn make(&self, _: [i32; 3], _: i32, _: i32, _: u32, _: ()) -> i16 {
        NONE
    }
}

/// Squared distance of a `g1` entry, `UNREACHABLE_DIST_SQ` for none.
fn g1_value(o: i16) -> u32 {
    if o == NONE {
        UNREACHABLE_DIST_SQ
    } else {
        (i32::from(o) * i32::from(o)) as u32
    }
}

/// Squared distance of a `g2` entry, `UNREACHABLE_DIST_SQ` for none.
fn g2_value(o: [i16; 2]) -> u32 {
    if o[0] == NONE {
        UNREACHABLE_DIST_SQ
    } else {
        (i32::from(o[0]).pow(2) + i32::from(o[1]).pow(2)) as u32
    }
}

/// Pass y follows pass x: the nearest entry of a column is a `g1` entry.
struct LowerY<'a> {
    g1: &'a FxHashMap<BlockKey, Box<G1Block>>,
}

impl Lower<[i16; 2]> for LowerY<'_> {
    type Entry = i16;
    type In = G1Block;
    fn key(&self, q: i32, o: [i16; 2]) -> Option<(u32, i32)> {
        (o[0] != NONE).then(|| (g2_value(o), q + i32::from(o[1])))
    }
    fn input(&self, key: BlockKey) -> Option<&G1Block> {
        self.g1.get(&key).map(|b| &**b)
    }
    fn entry(&self, b: Option<&G1Block>, o: usize) -> (u32, i16) {
        let e = b.map_or(NONE, |b| b[o]);
        (g1_value(e), e)
    }
    fn make(&self, _: [i32; 3], q: i32, p: i32, _: u32, e: i16) -> [i16; 2] {
        [e, (p - q) as i16]
    }
}

/// Pass z follows pass y: the nearest entry of a line is a `g2` entry.
struct LowerZ<'a> {
    g2: &'a FxHashMap<BlockKey, Box<G2Block>>,
}

impl Lower<Out> for LowerZ<'_> {
    type Entry = [i16; 2];
    type In = G2Block;
    fn key(&self, q: i32, o: Out) -> Option<(u32, i32)> {
        (o.0 != FAR_DIST_SQ).then(|| (o.0, q + i32::from(o.1[2])))
    }
    fn input(&self, key: BlockKey) -> Option<&G2Block> {
        self.g2.get(&key).map(|b| &**b)
    }
    fn entry(&self, b: Option<&G2Block>, o: usize) -> (u32, [i16; 2]) {
        let e = b.map_or(NONE2, |b| b[o]);
        (g2_value(e), e)
    }
    fn make(&self, _: [i32; 3], q: i32, p: i32, d: u32, e: [i16; 2]) -> Out {
        (d, [e[0], e[1], (p - q) as i16])
    }
}

/// The lower envelope of a few parabolas `(x - p)² + f` at ascending
/// positions over `lo..=hi`, as pieces, ties to the lowest position (as
/// Meijster's integer envelope in [`envelope`] breaks them).
///
/// Built over the reals, as Felzenszwalb and Huttenlocher's envelope is,
/// with each crossing kept as a fraction and crossings compared by
/// cross-multiplying: no division while building (each one waited on the
/// last: about 11 % of the exact integration on 3dmatch-seq01 at 2 m). Only the
/// pieces' integer ends are divided out, independently of each other.
#[derive(Debug, Default)]
struct Sparse {
    stack: Vec<Kept>,
    /// `lo` and `hi - lo`: positions are kept from `lo`, which keeps
    /// every product well inside `i64`.
    lo: i64,
    hi: i64,
}

/// A parabola of a [`Sparse`] envelope: position (from `lo`), value,
/// index among the input, and the crossing `num / den` (`den > 0`) past
/// which it beats the one below it on the stack (unused for the first).
#[derive(Debug, Clone, Copy)]
struct Kept {
    p: i64,
    f: i64,
    num: i64,
    den: i64,
    index: usize,
}

impl Sparse {
    fn build(&mut self, lo: i32, hi: i32, items: impl Iterator<Item = (i32, u32)>) {
        self.stack.clear();
        self.lo = i64::from(lo);
        self.hi = i64::from(hi) - self.lo;
        for (index, (q, f)) in items.enumerate() {
            if f == UNREACHABLE_DIST_SQ {
                continue;
            }
            let (q, fq) = (i64::from(q) - self.lo, i64::from(f));
            loop {
                let Some(&t) = self.stack.last() else {
                    self.stack.push(Kept { p: q, f: fq, num: 0, den: 1, index });
                    break;
                };
                // Where q starts to beat t (strictly: ties go to t, the
                // lower position): past num / den.
                let (num, den) = (fq - t.f + (q - t.p) * (q + t.p), 2 * (q - t.p));
                // t is dropped when that is no later than where t starts
                // to beat the one below it (t owns no x), or, first on the
                // stack, before x = 0 (t owns no x of the range).
                let gone = if self.stack.len() == 1 {
                    num < 0
                } else {
                    i128::from(num) * i128::from(t.den) <= i128::from(t.num) * i128::from(den)
                };
                if gone {
                    self.stack.pop();
                    continue;
                }
                // Kept when it owns some x up to hi.
                if num < self.hi * den {
                    self.stack.push(Kept { p: q, f: fq, num, den, index });
                }
                break;
            }
        }
    }

    /// The envelope's pieces, in order: each parabola's position `p`,
    /// value `f`, the range `s..=e` of x where it is the envelope (ties to
    /// the lowest position), and its index among the input. A parabola
    /// the envelope touches between two integers only owns no x: left out.
    fn pieces(&self) -> impl Iterator<Item = Piece> + '_ {
        // The last x each parabola owns, from the next one's crossing.
        let ends = self.stack.iter().skip(1).map(|n| n.num.div_euclid(n.den)).chain(std::iter::once(self.hi));
        let mut s = 0;
        self.stack.iter().zip(ends).filter_map(move |(k, e)| {
            let piece = Piece { p: k.p + self.lo, f: k.f, s: s + self.lo, e: e + self.lo, index: k.index };
            let owns = s <= e;
            s = e + 1;
            owns.then_some(piece)
        })
    }
}

/// One parabola `(x - p)² + f` of a [`Sparse`] envelope, the envelope over
/// `s..=e`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Piece {
    p: i64,
    f: i64,
    s: i64,
    e: i64,
    index: usize,
}

impl Piece {
    fn at(&self, x: i64) -> i64 {
        (x - self.p) * (x - self.p) + self.f
    }
}

/// Runs one pass along `axis`: every line with a voxel in `dirty` is
/// brought up to date around it, by `scan(scratch, segment, out)`, which
/// fills `out` with the new values from `lo - reach` to `hi + reach`.
///
/// Without `follow` (pass x) each line is rescanned over its dirty voxels
/// grown by the reach. With it, each dirty entry is one the previous pass
/// changed, and its block's [`Changed`] in `dirty` says how (how far it
/// can matter, whether it was lowered): the outputs whose nearest entry
/// rose or changed are rescanned (found among the old outputs), and the
/// others are lowered directly by
/// the lower envelope of the lowered entries alone, without reading the
/// unchanged inputs. Each task owns one line of blocks of `layer` along
/// `axis`, so it writes them directly. Returns the voxels whose value
/// changed, as masks with how they changed (the next pass's `dirty`), and
/// what changed (`amount` of each).
#[allow(clippy::too_many_arguments)]
fn drive<L: Layer, Lo: Lower<L::Value>>(
    layer: &mut L,
    axis: usize,
    mut dirty: Marked,
    follow: Option<&Lo>,
    pass: &Pass<'_>,
    scan: impl for<'x> Fn(&mut Scratch, Segment, Column<'x, Lo::In>, &mut Vec<L::Value>) + Sync,
    value: impl Fn(L::Value) -> u32 + Sync,
    amount: impl Fn(L::Value, L::Value) -> f64 + Sync,
) -> (Marked, Stats)
where
    L::Block: Send,
{
    let reach = pass.reach;
    // Tasks: lines of blocks along `axis`, each with its dirty blocks in order.
    let [b, d] = others(axis);
    dirty.sort_unstable_by_key(|e| (e.0 .0[b], e.0 .0[d], e.0 .0[axis]));
    let keys: Vec<BlockKey> = dirty.iter().map(|e| e.0).collect();
    let mut tasks: Vec<Range<usize>> = Vec::new();
    let mut start = 0;
    for i in 1..=keys.len() {
        if i == keys.len() || keys[i].0[b] != keys[i - 1].0[b] || keys[i].0[d] != keys[i - 1].0[d] {
            tasks.push(start..i);
            start = i;
        }
    }
    // Each task's plan, from the old outputs.
    let (side, stride) = (BLOCK_SIDE, [1, 8, 64][axis]);
    let view: &L = layer;
    let planned: Vec<Plan> = share_out(
        &tasks,
        shared(tasks.len(), keys.len()),
        || (Vec::new(), Scratch::default()),
        |(found, scratch), r| {
            let ks = &keys[r.clone()];
            // Each block's dirty voxels by line and how they changed, looked
            // up once for its 64 lines.
            let masks: Vec<([u8; 64], Option<&Changed>)> =
                dirty[r.clone()].iter().map(|e| (line_bits(&e.1, axis), e.2.as_deref())).collect();
            for c in masks.iter().filter_map(|m| m.1) {
                prefetch(c);
            }
            let mut plan = Plan { dirty: (ks[0], ks[ks.len() - 1].0[axis]), ..Plan::default() };
            // The old outputs' blocks along the task's line of blocks, as far
            // as a dirty entry reaches: looked up once for all its lines,
            // and only once an entry rose (most tasks of a frame only have
            // lowered entries, which need no old output here).
            let base = ks[0].0[axis] - (reach + side - 1) / side;
            let mut column: Option<Vec<Option<&L::Block>>> = None;
            let look_up = || {
                let mut k = ks[0].0;
                (base..=ks[ks.len() - 1].0[axis] + (reach + side - 1) / side)
                    .map(|c| {
                        k[axis] = c;
                        view.get(BlockKey(k))
                    })
                    .collect()
            };
            // Only the lines with a dirty voxel in one of the blocks (their
            // lines' bits joined, then one bit per line, without a branch).
            let mut any = [0u8; 64];
            for m in &masks {
                for (a, &t) in any.iter_mut().zip(&m.0) {
                    *a |= t;
                }
            }
            let mut lines = any.iter().enumerate().fold(0u64, |a, (l, &t)| a | u64::from(t != 0) << l);
            // The lists sized once (a line each, at most an entry per dirty
            // voxel) rather than grown by doubling.
            plan.lines.reserve(lines.count_ones() as usize);
            if follow.is_some() {
                plan.entries.reserve(dirty[r.clone()].iter().flat_map(|e| e.1).map(|w| w.count_ones() as usize).sum());
                plan.lower.reserve(lines.count_ones() as usize);
            } else {
                plan.segments.reserve(lines.count_ones() as usize);
            }
            while lines != 0 {
                let l = lines.trailing_zeros() as usize;
                lines &= lines - 1;
                let (u, v) = (l % 8, l / 8);
                let mut line = [0; 3];
                (line[b], line[d]) = (ks[0].0[b] * side + u as i32, ks[0].0[d] * side + v as i32);
                let o_line = local(axis, u, v, 0);
                let (first_segment, first_lower, first_risen) =
                    (plan.segments.len(), plan.lower.len(), plan.risen.len());
                // The line's dirty entries, position and reach: the lowered
                // ones of passes y and z go straight to their lowering
                // ranges (in ascending order, as they must), the others to
                // `found`.
                found.clear();
                for (k, &(ref bits, ch)) in ks.iter().zip(&masks) {
                    let mut ts = bits[l];
                    while ts != 0 {
                        let t = ts.trailing_zeros() as usize;
                        ts &= ts - 1;
                        let o = o_line + t * stride;
                        let (w, lowered) = ch.map_or((reach, false), |c| (i32::from(c.radius[o]), bit(&c.lowered, o)));
                        let p = k.0[axis] * side + t as i32;
                        if lowered {
                            plan_lowered(&mut plan, first_lower, p, w);
                        } else {
                            found.push((p, w));
                        }
                    }
                }
                match follow {
                    None => plan_rescan(&mut plan, line, found, reach),
                    Some(_) if found.is_empty() => {}
                    Some(lo) => {
                        let column = column.get_or_insert_with(look_up);
                        let key = |q: i32| {
                            let block = Column { base, blocks: column }.at(q.div_euclid(side))??;
                            lo.key(q, L::read(block, o_line + q.rem_euclid(side) as usize * stride))
                        };
                        plan_follow(&mut plan, key, found, (reach, pass.max));
                    }
                }
                plan.lines.push(LineWork {
                    line,
                    segments: first_segment..plan.segments.len(),
                    lower: first_lower..plan.lower.len(),
                    risen: first_risen..plan.risen.len(),
                });
            }
            // The blocks written: those the segments' outputs, the risen
            // entries' runs (where their outputs to rescan are searched
            // for, and the rescans write) and the lowering ranges cross.
            let spans = plan
                .segments
                .iter()
                .map(|s| (s.lo - reach, s.hi + reach))
                .chain(plan.spans.iter().copied())
                .chain(plan.lower.iter().map(|&(a, z, _)| (a, z)));
            merged(spans.map(|(a, z)| (a.div_euclid(side), z.div_euclid(side))), &mut scratch.ranges);
            plan.owned.extend(scratch.ranges.iter().flat_map(|&(a, z)| a..=z));
            plan
        },
    );
    // Take every task's blocks out of the layer.
    let key_of = |r: &Range<usize>, c: i32| {
        let mut k = keys[r.start].0;
        k[axis] = c;
        BlockKey(k)
    };
    let all: Vec<BlockKey> =
        tasks.iter().zip(&planned).flat_map(|(r, p)| p.owned.iter().map(move |&c| key_of(r, c))).collect();
    let mut taken: Vec<Option<L::Taken>> = layer.take(&all).into_iter().map(Some).collect();
    // Each task's plan with its share of them.
    let mut work: Vec<(Plan, &mut [Option<L::Taken>])> = Vec::with_capacity(planned.len());
    let mut rest: &mut [Option<L::Taken>] = &mut taken;
    for plan in planned {
        let (mine, more) = std::mem::take(&mut rest).split_at_mut(plan.owned.len());
        rest = more;
        work.push((plan, mine));
    }
    // Lower, scan, compare, write.
    let cap = i64::from(pass.max) + 1;
    let view: &L = layer;
    type Written<L> = Vec<(i32, Option<<L as Layer>::Back>, Mask, Option<Box<Changed>>)>;
    let stats: Vec<(Stats, Written<L>)> = share_out(
        work,
        shared(tasks.len(), keys.len()),
        || (Scratch::default(), Vec::new(), Vec::new(), Sparse::default(), Vec::new(), Vec::new()),
        |(s, out, entries, sparse, rescan, index), (plan, slots)| {
            let mut st = Stats { visited: plan.visited, ..Stats::default() };
            // The task's blocks made writable here, on its thread.
            let mut owned: Owned<L::Block> = plan
                .owned
                .iter()
                .zip(slots.iter_mut())
                .map(|(&c, t)| (c, view.own(t.take().expect("one block per key")), [0u64; 8], None))
                .collect();
            let blocks = &mut owned;
            // The task's blocks asked for first: the lowering walks each
            // line a few outputs at a time, a cache line apart, and
            // waited on one miss after another (pass z on 3dmatch-seq01
            // at 2 m: some 15-20 % of the integration).
            for b in blocks.iter() {
                L::warm(&b.1);
            }
            // The previous pass's blocks along the task's line of blocks
            // from `from` to `to`, looked up once: along its dirty
            // blocks, where the lowered entries lie, and, once a line
            // is rescanned, along its blocks grown by the reach, where
            // the rescans read.
            let (first, last) = plan.dirty;
            let column = |from: i32, to: i32| -> Vec<Option<&Lo::In>> {
                follow.map_or_else(Vec::new, |lo| {
                    let mut k = first.0;
                    (from..=to)
                        .map(|c| {
                            k[axis] = c;
                            lo.input(BlockKey(k))
                        })
                        .collect()
                })
            };
            let inputs = column(first.0[axis], last);
            let inputs = Column { base: first.0[axis], blocks: &inputs };
            let mut wide: Option<(i32, Vec<Option<&Lo::In>>)> = None;
            // Keeps how the entry at `o` changed, for the next pass.
            let note = |changed: &mut Option<Box<Changed>>, o: usize, old: L::Value, new: L::Value| {
                let (vo, vn) = (value(old), value(new));
                let f = vo.min(vn);
                let w = if f > pass.max { 0 } else { pass.roots.floor(pass.max - f) };
                let c = changed.get_or_insert_with(|| Box::new(Changed { radius: [0; BLOCK_VOXELS], lowered: [0; 8] }));
                c.radius[o] = w;
                if vn < vo {
                    c.lowered[o / 64] |= 1 << (o % 64);
                }
            };
            // Writes `new` over `old` at `o` of block `j` if it differs.
            let replace =
                |blocks: &mut Owned<L::Block>, j: usize, o: usize, old: L::Value, new: L::Value, st: &mut Stats| {
                    let (_, block, mask, changed) = &mut blocks[j];
                    if old != new {
                        L::write(block, o, new);
                        mask[o / 64] |= 1 << (o % 64);
                        st.changed += 1;
                        st.same += usize::from(value(old) == value(new));
                        st.sum += amount(old, new);
                        if L::FEEDS_NEXT {
                            note(changed, o, old, new);
                        }
                    }
                };
            // Writes `new` at `o` of block `j` if it differs.
            let put = |blocks: &mut Owned<L::Block>, j: usize, o: usize, new: L::Value, st: &mut Stats| {
                let old = L::read(&blocks[j].1, o);
                replace(blocks, j, o, old, new, st);
            };
            // Each block's place among the task's blocks, by coordinate
            // along the axis from the first (for the risen entries'
            // searches, so not in pass x).
            let c0 = blocks.first().map_or(0, |x| x.0);
            index.clear();
            if follow.is_some() {
                index.resize(blocks.last().map_or(0, |x| (x.0 - c0 + 1) as usize), usize::MAX);
                for (j, x) in blocks.iter().enumerate() {
                    index[(x.0 - c0) as usize] = j;
                }
            }
            for lw in &plan.lines {
                let o_line = local(axis, lw.line[b].rem_euclid(side) as usize, lw.line[d].rem_euclid(side) as usize, 0);
                // The outputs to rescan: planned (pass x), or those of
                // the risen entries, searched for among the old outputs
                // now that the blocks are warm (in the planning, the
                // same searches were cache misses one after another).
                let segments: &[Segment] = match follow {
                    None => &plan.segments[lw.segments.clone()],
                    Some(lo) => {
                        // The old output at q: every one searched lies
                        // in a risen entry's reach, so in the task's
                        // blocks.
                        let key = |q: i32| {
                            let j = *index.get(usize::try_from(q.div_euclid(side) - c0).ok()?)?;
                            lo.key(q, L::read(&blocks.get(j)?.1, o_line + q.rem_euclid(side) as usize * stride))
                        };
                        // How far from output q the inputs reach that
                        // can be nearest to it, q's old nearest input
                        // at p: output q is at most `u = (q - p)² + f`,
                        // `f` the input at p now (risen entries lie in
                        // the dirty blocks), so no input further than
                        // `floor(sqrt(u))` is nearest to it, nor ties
                        // with what is. Most inputs of a rescan were the
                        // reach on each side of its few outputs.
                        let bound = |p: i32, qs: [i32; 2]| {
                            let (f, _) = lo.entry(
                                inputs.at(p.div_euclid(side)).flatten(),
                                o_line + p.rem_euclid(side) as usize * stride,
                            );
                            // (Capped at the cutoff: an output beyond it
                            // is far whichever input is nearest; so
                            // capped, `q -+ bound` only grows with q.)
                            qs.map(|q| {
                                let u =
                                    (u64::from(f) + u64::from((q - p).unsigned_abs()).pow(2)).min(u64::from(pass.max));
                                i32::from(pass.roots.floor(u as u32)).min(reach)
                            })
                        };
                        st.visited += rescans(key, bound, lw.line, &plan.risen[lw.risen.clone()], reach, rescan);
                        rescan
                    }
                };
                if let Some(lo) = follow {
                    // First the outputs the lowered entries lower, from
                    // the old outputs: the rescans below overwrite
                    // their own outputs, which this leaves to them.
                    st.add(lower_line::<L, Lo, _, _>(
                        blocks,
                        lo,
                        inputs,
                        (&plan.lower[lw.lower.clone()], &plan.entries),
                        lw.line,
                        (o_line, stride),
                        (segments, reach),
                        (cap, pass.max),
                        (entries, sparse),
                        &amount,
                        &note,
                    ));
                }
                if !segments.is_empty() && wide.is_none() {
                    let grow = (reach + side - 1) / side;
                    let (from, to) =
                        (blocks.first().map_or(0, |x| x.0) - grow, blocks.last().map_or(0, |x| x.0) + grow);
                    wide = Some((from, column(from, to)));
                }
                let col = wide
                    .as_ref()
                    .map_or(Column { base: 0, blocks: &[] }, |(base, v)| Column { base: *base, blocks: v });
                for seg in segments {
                    out.clear();
                    scan(s, *seg, col, out);
                    let first = seg.lo - reach;
                    st.visited += out.len();
                    st.rescanned += out.len();
                    let mut j = blocks.partition_point(|x| x.0 < first.div_euclid(side));
                    by_block(seg.line, axis, first, out.len(), |key, o0, stride, range| {
                        while blocks[j].0 != key.0[axis] {
                            j += 1;
                        }
                        for (k, &new) in out[range].iter().enumerate() {
                            put(blocks, j, o0 + k * stride, new, &mut st);
                        }
                    });
                }
            }
            // Which blocks to keep, read while they are in this core's
            // cache, and those to keep made ready to put back (a serial
            // loop over them all took 0.1-0.2 ms). The plan and the
            // blocks not kept freed here, on the thread that used them.
            drop(plan);
            (
                st,
                owned
                    .into_iter()
                    .map(|(c, mut b, mask, changed)| (c, (!view.empty(&mut b)).then(|| L::give(b)), mask, changed))
                    .collect(),
            )
        },
    );
    // Put the blocks back; the changed voxels are the next pass's dirty ones.
    drop(dirty);
    let mut next =
        Marked::with_capacity(stats.iter().flat_map(|s| &s.1).filter(|e| e.2.iter().any(|&w| w != 0)).count());
    let mut back = Vec::with_capacity(stats.iter().flat_map(|s| &s.1).filter(|e| e.1.is_some()).count());
    let mut total = Stats::default();
    for (r, (st, blocks)) in tasks.iter().zip(stats) {
        total.add(st);
        for (c, kept, mask, changed) in blocks {
            let key = key_of(r, c);
            // Every block with a changed voxel (how each changed is kept
            // only where a pass follows).
            if mask.iter().any(|&w| w != 0) {
                next.push((key, mask, changed));
            }
            if let Some(block) = kept {
                back.push((key, block));
            }
        }
    }
    layer.restore(back);
    (next, total)
}

/// Lowers the outputs of a line of pass y or z from its lowered entries
/// (`ranges`: each lowering range with its entries' positions among
/// `positions`): the lower envelope of each range's entries, and each of
/// its pieces walked over the old outputs it beats ([`walk`]), but not
/// over the outputs a rescan (`segments`, grown by `reach`) writes. A
/// function of its own, like the walk, rather than part of the task's
/// closure. `inputs`: the previous pass's blocks along the task's dirty
/// blocks; `(o_line, stride)`, `(cap, max)`: as for [`walk`]; `entries`,
/// `sparse`: the thread's working memory.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn lower_line<
    L: Layer,
    Lo: Lower<L::Value>,
    A: Fn(L::Value, L::Value) -> f64,
    N: Fn(&mut Option<Box<Changed>>, usize, L::Value, L::Value),
>(
    blocks: &mut Owned<L::Block>,
    lo: &Lo,
    inputs: Column<'_, Lo::In>,
    (ranges, positions): (&[Lowering], &[i32]),
    line: [i32; 3],
    (o_line, stride): (usize, usize),
    (segments, reach): (&[Segment], i32),
    (cap, max): (i64, u32),
    (entries, sparse): (&mut Vec<(u32, Lo::Entry)>, &mut Sparse),
    amount: &A,
    note: &N,
) -> Stats {
    let side = BLOCK_SIDE;
    let mut st = Stats::default();
    let rescanned = |q: i64| segments.iter().any(|g| i64::from(g.lo - reach) <= q && q <= i64::from(g.hi + reach));
    for &(a, z, ref ps) in ranges {
        let ps = &positions[ps.clone()];
        entries.clear();
        entries.extend(ps.iter().map(|&p| {
            lo.entry(inputs.at(p.div_euclid(side)).flatten(), o_line + p.rem_euclid(side) as usize * stride)
        }));
        sparse.build(a, z, ps.iter().zip(entries.iter()).map(|(&p, &(f, _))| (p, f)));
        let (ca, ja) = (i64::from(a.div_euclid(side)), blocks.partition_point(|x| x.0 < a.div_euclid(side)));
        // Block and offset of the output at q.
        let slot = |q: i64| {
            (
                ja + (q.div_euclid(i64::from(side)) - ca) as usize,
                o_line + q.rem_euclid(i64::from(side)) as usize * stride,
            )
        };
        // The old output at q (block j, offset o): its squared distance
        // capped just past the cutoff, and its key.
        let old_at = |blocks: &Owned<L::Block>, (j, o): (usize, usize), q: i64| {
            let old = L::read(&blocks[j].1, o);
            let key = lo.key(q as i32, old);
            (key.map_or(cap, |k| i64::from(k.0).min(cap)), key, old)
        };
        for piece in sparse.pieces() {
            let clear =
                !segments.iter().any(|g| i64::from(g.lo - reach) <= piece.e && piece.s <= i64::from(g.hi + reach));
            // The old outputs less the piece, capped, are concave along
            // the line (each old output is a least parabola; two
            // parabolas differ by a line), so the outputs the piece beats
            // are one run: walk out from the parabola's own position when
            // the piece beats it there (as it mostly does), else from the
            // peak, found by bisection.
            let start = piece.p.clamp(piece.s, piece.e);
            let (at_start, key, _) = old_at(blocks, slot(start), start);
            let l = if at_start >= piece.at(start) {
                start
            } else {
                // No piece of this envelope wrote on `s..=e` yet, so the
                // outputs there still lie at or below the parabola of the
                // output at `start`. The piece less that parabola is a
                // line: the piece can only beat outputs where it lies at
                // or below the parabola, a run found by arithmetic alone
                // (none: skip it), and the peak is searched there.
                let (mut l, mut h) = (piece.s, piece.e);
                if let Some((d, site)) = key {
                    let site = i64::from(site);
                    let f = i64::from(d) - (start - site) * (start - site);
                    let Some(run) = half_line(l, h, |q| (q - site) * (q - site) + f >= piece.at(q)) else { continue };
                    (l, h) = run;
                }
                while l < h {
                    let m = l + (h - l) / 2;
                    let gain = |q| old_at(blocks, slot(q), q).0 - piece.at(q);
                    st.visited += 2;
                    if gain(m) >= gain(m + 1) {
                        h = m;
                    } else {
                        l = m + 1;
                    }
                }
                if l == start || old_at(blocks, slot(l), l).0 < piece.at(l) {
                    continue;
                }
                l
            };
            // From the peak down, then up.
            let entry = entries[piece.index].1;
            let make = |q: i32, d: u32| lo.make(line, q, piece.p as i32, d, entry);
            let keep = |q: i64| clear || !rescanned(q);
            st.add(walk::<L, Lo>(
                blocks,
                lo,
                &piece,
                l,
                (ja, ca),
                (o_line, stride),
                (cap, max),
                keep,
                make,
                amount,
                note,
            ));
        }
    }
    st
}

/// Walks a lowering piece over the outputs it beats, down from `peak` (an
/// output it beats) to the first it does not beat or the piece's start,
/// then up from `peak + 1` likewise to its end, and writes those it
/// lowers: where `keep` (no rescan writes it), and the piece's value is
/// within the cutoff and less than the old output's, or equal from a
/// lower site (`make(q, value)`: the new output at `q`). Each of the
/// task's blocks is looked up once per stretch along it, not per output,
/// and what changed is counted in registers (on 3dmatch-seq01 at 2 m the
/// walks took about a quarter of the integration's samples, the lowering
/// around them, [`lower_line`], a third). `(ja, ca)`: the place among the
/// task's blocks of one block along the line and its coordinate along the
/// axis; `(o_line, stride)`: the line's offset in a block and the stride
/// along the axis; `(cap, max)`: the cap of old values and the cutoff's
/// squared distance.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn walk<L: Layer, Lo: Lower<L::Value>>(
    blocks: &mut Owned<L::Block>,
    lo: &Lo,
    piece: &Piece,
    peak: i64,
    (ja, ca): (usize, i64),
    (o_line, stride): (usize, usize),
    (cap, max): (i64, u32),
    keep: impl Fn(i64) -> bool,
    make: impl Fn(i32, u32) -> L::Value,
    amount: impl Fn(L::Value, L::Value) -> f64,
    note: impl Fn(&mut Option<Box<Changed>>, usize, L::Value, L::Value),
) -> Stats {
    let side = BLOCK_SIDE as i64;
    let mut st = Stats::default();
    let p = piece.p as i32;
    // The output at `q`, offset `o` of `block`: whether the piece lies at
    // or below it, and if so, the output lowered where it should be.
    // (A macro: as a closure it was not inlined, a call per output.)
    macro_rules! step {
        ($entry:expr, $o:expr, $q:expr) => {{
            let ((_, block, mask, how), o, q) = ($entry, $o, $q);
            st.visited += 1;
            let old = L::read(block, o);
            let key = lo.key(q as i32, old);
            let dq = piece.at(q);
            if key.map_or(cap, |k| i64::from(k.0).min(cap)) < dq {
                false
            } else {
                let dq = dq as u32;
                if dq <= max && keep(q) && key.is_none_or(|cur| (dq, p) < cur) {
                    // Nearer, as near from a lower site, or where the old
                    // output is far: never the old output again.
                    // (The task's `replace`, written out: shared through
                    // an inlined function, 3dmatch-seq01 at 2 m measured
                    // 3-4 % slower.)
                    let new = make(q as i32, dq);
                    debug_assert!(new != old);
                    L::write(block, o, new);
                    mask[o / 64] |= 1 << (o % 64);
                    st.changed += 1;
                    st.same += usize::from(key.is_some_and(|k| k.0 == dq));
                    st.sum += amount(old, new);
                    if L::FEEDS_NEXT {
                        note(how, o, old, new);
                    }
                }
                true
            }
        }};
    }
    let slot = |q: i64| ja + (q.div_euclid(side) - ca) as usize;
    let mut q = peak;
    'down: loop {
        let entry = &mut blocks[slot(q)];
        let stop = (q.div_euclid(side) * side).max(piece.s);
        let mut o = o_line + q.rem_euclid(side) as usize * stride;
        loop {
            if !step!(&mut *entry, o, q) {
                break 'down;
            }
            if q <= stop {
                break;
            }
            q -= 1;
            o -= stride;
        }
        if q <= piece.s {
            break;
        }
        q -= 1;
    }
    q = peak + 1;
    'up: while q <= piece.e {
        let entry = &mut blocks[slot(q)];
        let stop = (q.div_euclid(side) * side + side - 1).min(piece.e);
        let mut o = o_line + q.rem_euclid(side) as usize * stride;
        loop {
            if !step!(&mut *entry, o, q) {
                break 'up;
            }
            if q >= stop {
                break;
            }
            q += 1;
            o += stride;
        }
        q += 1;
    }
    st
}

/// Plans a line of pass x: its dirty voxels, each grown by its reach,
/// rescanned in segments (those closer than twice the reach merged).
fn plan_rescan(plan: &mut Plan, line: [i32; 3], found: &[(i32, i32)], reach: i32) {
    // (last dirty position, lowest and highest output).
    let mut cur: Option<(i32, i32, i32)> = None;
    // A segment's outputs as `lo - reach ..= hi + reach`.
    let segment = |(_, a, b): (i32, i32, i32)| Segment { line, lo: a + reach, hi: b - reach, margin: (reach, reach) };
    for &(p, w) in found {
        cur = match cur {
            Some((last, a, b)) if p - last <= 2 * reach + 1 => Some((p, a.min(p - w), b.max(p + w))),
            Some(c) => {
                plan.segments.push(segment(c));
                Some((p, p - w, p + w))
            }
            None => Some((p, p - w, p + w)),
        };
    }
    plan.segments.extend(cur.map(segment));
}

/// Plans a line of pass y or z from the entries the previous pass changed
/// without lowering them (`found`: position, reach; ascending): each is
/// kept for [`rescans`] with where its outputs can be. `key(q)`: the
/// squared distance and position of the entry the old output at `q` came
/// from.
fn plan_follow(
    plan: &mut Plan,
    key: impl Fn(i32) -> Option<(u32, i32)>,
    found: &[(i32, i32)],
    (reach, max): (i32, u32),
) {
    let first_risen = plan.risen.len();
    for &(p, w) in found {
        // Where the outputs from `p` can be: the entry's old value is more
        // than `max - (w + 1)²` (its reach `w` is the floor of the root of
        // the difference), and the outputs in reach lie at or below the
        // parabola of the output at `p`, so they came from `p` only where
        // `p`'s parabola with that least value lies at or below that one,
        // a run found by arithmetic (none: skip it).
        let (mut from, mut to) = (p - w, p + w);
        if let Some((d, s)) = key(p) {
            plan.visited += 1;
            let (pp, s, w) = (i64::from(p), i64::from(s), i64::from(w));
            let (f, least) = (i64::from(d) - (pp - s) * (pp - s), i64::from(max) + 1 - (w + 1) * (w + 1));
            let Some(run) = half_line(pp - w, pp + w, |q| (q - s) * (q - s) + f >= (q - pp) * (q - pp) + least) else {
                continue;
            };
            (from, to) = (run.0 as i32, run.1 as i32);
        }
        plan.risen.push((p, from, to));
    }
    // Two outputs found in these runs, less than twice the reach apart,
    // are rescanned as one segment, so are the outputs between them: the
    // runs joined likewise cover it.
    let at = plan.spans.len();
    plan.spans.extend(plan.risen[first_risen..].iter().map(|&(_, a, z)| (a, z)));
    join_within(&mut plan.spans, at, 2 * reach);
}

/// Plans a lowered entry of pass y or z at `p`, of reach `w`: its reach
/// joins the line's lowering ranges (from `first` on), merged where they
/// overlap or touch, each with the entries that make it up. The entries
/// come in ascending order, so a reach can only overlap the last merged
/// ones: merged back, mostly into the last one alone, in place.
fn plan_lowered(plan: &mut Plan, first: usize, p: i32, w: i32) {
    let n = plan.entries.len();
    plan.entries.push(p);
    let (a, z) = (p - w, p + w);
    match plan.lower[first..].last_mut() {
        Some(last) if a >= last.0 && a <= last.1 + 1 => {
            last.1 = last.1.max(z);
            last.2.end = n + 1;
        }
        _ => {
            let mut cur = (a, z, n..n + 1);
            while plan.lower.len() > first && plan.lower.last().is_some_and(|last| cur.0 <= last.1 + 1) {
                let Some(last) = plan.lower.pop() else { break };
                cur = (cur.0.min(last.0), cur.1.max(last.1), last.2.start..cur.2.end);
            }
            plan.lower.push(cur);
        }
    }
}

/// The segments of a line of pass y or z to rescan, into `out`: the outputs
/// whose nearest entry is one of `risen` (position and the run where its
/// outputs can be, from [`plan_follow`]; ascending), found among
/// the old outputs (`key(q)` as there), runs less than twice the reach
/// apart merged. Returns how many outputs it read.
fn rescans(
    key: impl Fn(i32) -> Option<(u32, i32)>,
    bound: impl Fn(i32, [i32; 2]) -> [i32; 2],
    line: [i32; 3],
    risen: &[(i32, i32, i32)],
    reach: i32,
    out: &mut Vec<Segment>,
) -> usize {
    out.clear();
    let mut visited = 0;
    // Along a line the sites of the outputs never decrease (of two
    // parabolas the one further on wins from some x on), and within an
    // entry's reach no old output is far, so the outputs from each entry
    // are one run, found by bisection.
    let site = |q: i32| key(q).map(|k| k.1);
    // The run being joined: its first and last outputs, and how far its
    // inputs reach before the first and past the last. The outputs from
    // `p`, `q0..=q1`, reach no further than `bound(p, [q0, q1])` before
    // `q0` and past `q1` (`q -+` its bound only grows with q);
    // the outputs between two runs, whose nearest input did not rise,
    // are given the whole reach.
    let mut run: Option<(i32, i32, i32, i32)> = None;
    let segment = |(s, e, l, r): (i32, i32, i32, i32)| Segment {
        line,
        lo: s + reach,
        hi: e - reach,
        margin: (l.clamp(0, reach), r.clamp(0, reach)),
    };
    let mut add = |out: &mut Vec<Segment>, (q0, q1): (i32, i32), [b0, b1]: [i32; 2]| {
        run = match run {
            Some((s, e, l, r)) if q0 - e <= 2 * reach => {
                let gap = q0 > e + 1;
                let l = l.max(b0 - (q0 - s)).max(if gap { reach - (e + 1 - s) } else { 0 });
                let r = b1.max(r - (q1 - e)).max(if gap { reach - (q1 - q0 + 1) } else { 0 });
                Some((s, q1.max(e), l, r))
            }
            Some(cur) => {
                out.push(segment(cur));
                Some((q0, q1, b0, b1))
            }
            None => Some((q0, q1, b0, b1)),
        };
    };
    for &(p, from, to) in risen {
        // The outputs from `p`, `q0..q1`: from the first output in
        // `from..=to` whose site is at least `p` to the first past `p`,
        // by one bisection until it meets an output from `p`, then one on
        // each side of it; `None` if an output read had no site.
        let from_p = |visited: &mut usize| {
            let (mut l, mut h) = (from, to + 1);
            while l < h {
                let m = l + (h - l) / 2;
                *visited += 1;
                match site(m)? {
                    s if s < p => l = m + 1,
                    s if s > p => h = m,
                    _ => {
                        let (mut q0, mut z) = (l, m);
                        while q0 < z {
                            let c = q0 + (z - q0) / 2;
                            *visited += 1;
                            (q0, z) = if site(c)? >= p { (q0, c) } else { (c + 1, z) };
                        }
                        let (mut q1, mut z) = (m + 1, h);
                        while q1 < z {
                            let c = q1 + (z - q1) / 2;
                            *visited += 1;
                            (q1, z) = if site(c)? > p { (q1, c) } else { (c + 1, z) };
                        }
                        return Some((q0, q1));
                    }
                }
            }
            Some((l, l))
        };
        match from_p(&mut visited) {
            Some((q0, q1)) if q0 < q1 => add(out, (q0, q1 - 1), bound(p, [q0, q1 - 1])),
            Some(_) => {}
            // Not the exact EDT of its inputs: read every output where
            // those from `p` can be.
            None => {
                visited += (to - from + 1) as usize;
                for q in (from..=to).filter(|&q| site(q) == Some(p)) {
                    add(out, (q, q), bound(p, [q, q]));
                }
            }
        }
    }
    if let Some(cur) = run {
        out.push(segment(cur));
    }
    visited
}

/// The run of `lo..=hi` where `ok` holds, `ok(q)` being that a line (a
/// linear function of `q`) is at least 0 at `q`: all of it, none, or the
/// part on one side of where the line crosses 0, found by bisection on
/// `ok` alone.
fn half_line(lo: i64, hi: i64, ok: impl Fn(i64) -> bool) -> Option<(i64, i64)> {
    match (ok(lo), ok(hi)) {
        (true, true) => Some((lo, hi)),
        (false, false) => None,
        (false, true) => {
            let (mut a, mut z) = (lo, hi);
            while a < z {
                let m = a + (z - a) / 2;
                (a, z) = if ok(m) { (a, m) } else { (m + 1, z) };
            }
            Some((a, hi))
        }
        (true, false) => {
            let (mut a, mut z) = (lo, hi);
            while a < z {
                let m = a + (z - a + 1) / 2;
                (a, z) = if ok(m) { (m, z) } else { (a, m - 1) };
            }
            Some((lo, a))
        }
    }
}

/// The union of intervals, as disjoint ascending intervals (touching ones
/// joined), into `out`.
fn merged(iv: impl Iterator<Item = (i32, i32)>, out: &mut Vec<(i32, i32)>) {
    out.clear();
    out.extend(iv);
    join_within(out, 0, 1);
}

/// Sorts the intervals of `v` from `from` on and joins those less than
/// `gap` apart (`gap` 1: overlapping or touching), in place.
fn join_within(v: &mut Vec<(i32, i32)>, from: usize, gap: i32) {
    v[from..].sort_unstable();
    let mut n = from;
    for i in from..v.len() {
        let (a, b) = v[i];
        if n > from && a - v[n - 1].1 <= gap {
            v[n - 1].1 = v[n - 1].1.max(b);
        } else {
            v[n] = (a, b);
            n += 1;
        }
    }
    v.truncate(n);
}

/// `floor(sqrt(v))`, at most `u16::MAX`.
fn isqrt(v: u32) -> u16 {
    let mut r = f64::from(v).sqrt() as u64;
    while r * r > u64::from(v) {
        r -= 1;
    }
    while (r + 1) * (r + 1) <= u64::from(v) {
        r += 1;
    }
    r.min(u64::from(u16::MAX)) as u16
}

/// The blocks of a layer along one line of blocks, from `base` on (the
/// coordinate along the line's axis).
#[derive(Debug)]
struct Column<'a, B> {
    base: i32,
    blocks: &'a [Option<&'a B>],
}

impl<B> Clone for Column<'_, B> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<B> Copy for Column<'_, B> {}

impl<'a, B> Column<'a, B> {
    /// The block at `c` along the axis (`None` for none), `None` outside
    /// the column.
    fn at(&self, c: i32) -> Option<Option<&'a B>> {
        usize::try_from(c - self.base).ok().and_then(|i| self.blocks.get(i).copied())
    }
}

/// Working memory of one thread.
#[derive(Debug, Default)]
struct Scratch {
    f: Vec<u32>,
    site: Vec<u32>,
    out_f: Vec<u32>,
    out_site: Vec<u32>,
    flags: Vec<bool>,
    off: Vec<[i16; 2]>,
    envelope: EnvelopeScratch,
    /// Planning: merged reaches.
    ranges: Vec<(i32, i32)>,
}

impl Scratch {
    fn reset(&mut self, n: usize) {
        for v in [&mut self.f, &mut self.site, &mut self.out_f, &mut self.out_site] {
            v.clear();
            v.resize(n, 0);
        }
    }

    /// Reads `self.f.len()` entries of `layer` (its blocks from `col` where
    /// it has them) along `axis` from `base` on `line` into `off` (as
    /// offsets along x and y) and `f` (their squared distances, none for
    /// none).
    fn gather<T: Copy>(
        &mut self,
        layer: &FxHashMap<BlockKey, Box<[T; BLOCK_VOXELS]>>,
        col: Column<'_, [T; BLOCK_VOXELS]>,
        line: [i32; 3],
        axis: usize,
        base: i32,
        offsets: impl Fn(T) -> [i16; 2],
    ) {
        let n = self.f.len();
        self.off.clear();
        self.off.resize(n, NONE2);
        let (f, off) = (&mut self.f, &mut self.off);
        by_block(line, axis, base, n, |key, o0, stride, range| {
            let Some(block) = col.at(key.0[axis]).unwrap_or_else(|| layer.get(&key).map(|b| &**b)) else {
                f[range].fill(UNREACHABLE_DIST_SQ);
                return;
            };
            for (k, i) in range.enumerate() {
                let o = offsets(block[o0 + k * stride]);
                off[i] = o;
                f[i] = g2_value(o);
            }
        });
    }

    /// Meijster's envelope of `self.f` into `out_f` / `out_site` (local
    /// positions, ties to the lowest).
    fn scan(&mut self) {
        let n = self.f.len();
        for (i, s) in self.site.iter_mut().enumerate() {
            *s = i as u32;
        }
        let line = Line { f: &self.f, site: &self.site, stride: 1, n };
        envelope(line, &mut self.out_f, &mut self.out_site, &mut self.envelope);
    }
}

/// The cutoff, as the passes use it.
struct Pass<'a> {
    reach: i32,
    max: u32,
    /// A planar map's: pass z keeps each layer's `g2` ([`in_layer`]).
    planar: bool,
    roots: &'a Roots,
}

/// `floor(sqrt(v))` and `sqrt(v)` for every `v` up to the cutoff's squared
/// distance, looked up for each changed entry (a large frame changes
/// millions) rather than computed; computed beyond `ROOTS_MAX`.
#[derive(Debug)]
struct Roots {
    max: u32,
    floor: Vec<u16>,
    exact: Vec<f64>,
}

/// Largest squared cutoff given tables (2.5 MB).
const ROOTS_MAX: u32 = 1 << 18;

impl Roots {
    fn new(max: u32) -> Roots {
        let top = if max <= ROOTS_MAX { max as usize + 1 } else { 0 };
        Roots {
            max,
            floor: (0..top as u32).map(isqrt).collect(),
            exact: (0..top as u32).map(|v| f64::from(v).sqrt()).collect(),
        }
    }

    fn floor(&self, v: u32) -> u16 {
        self.floor.get(v as usize).copied().unwrap_or_else(|| isqrt(v))
    }
}

/// `sqrt(v)`, from `exact` (the square roots of 0, 1, ..) where it has it.
fn root(exact: &[f64], v: u32) -> f64 {
    exact.get(v as usize).copied().unwrap_or_else(|| f64::from(v).sqrt())
}

fn at_axis(mut c: [i32; 3], axis: usize, t: i32) -> VoxelIndex {
    c[axis] = t;
    VoxelIndex(c)
}

impl Pass<'_> {
    /// Pass x on row `line` from `lo - reach` to `hi + reach`: the offset
    /// to the nearest obstacle, the map's obstacles flipped where `flips`
    /// says.
    fn row(&self, edt: &EdtMap, flips: &Dirty, seg: Segment, s: &mut Scratch, out: &mut Vec<i16>) {
        let (line, margin) = (seg.line, seg.margin);
        let (base, n) = seg.inputs(self.reach);
        s.flags.clear();
        s.flags.resize(n, false);
        let flags = &mut s.flags;
        by_block(line, 0, base, n, |key, o0, _, range| {
            // A row of a block lies in one layer.
            let (layer, flip) = (edt.get(key).and_then(|b| b.to_nearest.layer(o0 / 64)), flips.get(&key));
            for (k, i) in range.enumerate() {
                let was = layer.is_some_and(|l| l[o0 % 64 + k] == [0; 3]);
                flags[i] = was != flip.is_some_and(|m| bit(m, o0 + k));
            }
        });
        s.reset(n);
        let flags = &s.flags;
        sweep_row(|i| flags[i], 0, &mut s.out_f, &mut s.out_site);
        for i in margin.0 as usize..n - margin.1 as usize {
            out.push(if s.out_site[i] == NO_SITE || s.out_f[i] > self.max {
                NONE
            } else {
                (s.out_site[i] as i32 - i as i32) as i16
            });
        }
    }

    /// Pass y on column `line` from `lo - reach` to `hi + reach`: offsets
    /// to the slice's nearest obstacle, from `g1`.
    fn column(
        &self,
        g1: &FxHashMap<BlockKey, Box<G1Block>>,
        col: Column<'_, G1Block>,
        seg: Segment,
        s: &mut Scratch,
        out: &mut Vec<[i16; 2]>,
    ) {
        let (line, margin) = (seg.line, seg.margin);
        let (base, n) = seg.inputs(self.reach);
        s.reset(n);
        s.gather(g1, col, line, 1, base, |o| [o, 0]);
        s.scan();
        for i in margin.0 as usize..n - margin.1 as usize {
            out.push(if s.out_f[i] == UNREACHABLE_DIST_SQ || s.out_f[i] > self.max {
                NONE2
            } else {
                let p = s.out_site[i] as usize;
                [s.off[p][0], (p as i32 - i as i32) as i16]
            });
        }
    }

    /// Pass z on line `line` from `lo - reach` to `hi + reach`: distances
    /// and nearest obstacles, from `g2`.
    fn depth(
        &self,
        g2: &FxHashMap<BlockKey, Box<G2Block>>,
        col: Column<'_, G2Block>,
        seg: Segment,
        s: &mut Scratch,
        out: &mut Vec<Out>,
    ) {
        let (line, margin) = (seg.line, seg.margin);
        let (base, n) = seg.inputs(self.reach);
        s.reset(n);
        s.gather(g2, col, line, 2, base, |o| o);
        s.scan();
        for i in margin.0 as usize..n - margin.1 as usize {
            out.push(if s.out_f[i] == UNREACHABLE_DIST_SQ || s.out_f[i] > self.max {
                (FAR_DIST_SQ, NO_OFFSET)
            } else {
                let p = s.out_site[i] as usize;
                (s.out_f[i], [s.off[p][0], s.off[p][1], (p as i32 - i as i32) as i16])
            });
        }
    }
}

const _: () = assert!(BLOCK_SIDE == 8);

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The sparse envelope is the least (value, position) over its
        /// parabolas at every x of its range, by brute force: ties, equal
        /// values, parabolas owning no integer, and x far from all of them.
        #[test]
        fn sparse_envelope_is_the_least_value_then_position(
            raw in prop::collection::vec((0i32..40, 0u32..60), 0..12),
            lo in -10i32..20,
            len in 0i32..50,
        ) {
            let mut items: Vec<(i32, u32)> = raw;
            items.sort_unstable_by_key(|&(p, _)| p);
            items.dedup_by_key(|&mut (p, _)| p);
            let hi = lo + len;
            let mut sparse = Sparse::default();
            sparse.build(lo, hi, items.iter().copied());
            // The pieces, one per x they cover, in order.
            let mut read = Vec::new();
            for piece in sparse.pieces() {
                prop_assert!(piece.s <= piece.e, "empty piece {:?}", piece);
                read.extend((piece.s..=piece.e).map(|x| (x as i32, (piece.at(x) as u32, piece.index))));
            }
            if !read.is_empty() {
                prop_assert!(read.iter().enumerate().all(|(i, r)| r.0 == lo + i as i32), "pieces cover lo..=hi in order: {:?}", read);
            }
            for x in lo..=hi {
                let got = read.iter().find(|r| r.0 == x).map(|r| r.1);
                let want = items
                    .iter()
                    .enumerate()
                    .map(|(i, &(p, f))| (f + (x - p).unsigned_abs().pow(2), p, i))
                    .min_by_key(|&(v, p, _)| (v, p))
                    .map(|(v, _, i)| (v, i));
                prop_assert_eq!(got, want, "x {} items {:?}", x, items);
            }
        }
    }

    proptest! {
        /// Each line's bits are the mask's voxels on that line, by brute
        /// force, along every axis.
        #[test]
        fn line_bits_are_the_voxels_of_each_line(m in prop::array::uniform8(any::<u64>()), axis in 0usize..3) {
            let bits = line_bits(&m, axis);
            for (l, line) in bits.iter().enumerate() {
                for t in 0..8 {
                    prop_assert_eq!(line >> t & 1 == 1, bit(&m, local(axis, l % 8, l / 8, t)), "axis {} line {} t {}", axis, l, t);
                }
            }
        }
    }

    proptest! {
        /// The run where a line is at least 0 is every such point of the
        /// range, whichever way the line goes.
        #[test]
        fn half_line_is_where_the_line_is_at_least_zero(slope in -50i64..50, at in -2000i64..2000, lo in -100i64..100, len in 0i64..200) {
            let hi = lo + len;
            let ok = |q: i64| slope * q + at >= 0;
            let want: Vec<i64> = (lo..=hi).filter(|&q| ok(q)).collect();
            let got: Vec<i64> = half_line(lo, hi, ok).map_or_else(Vec::new, |(a, z)| (a..=z).collect());
            prop_assert_eq!(got, want);
        }
    }

    #[test]
    fn merged_joins_overlapping_and_touching_intervals() {
        let mut out = Vec::new();
        merged([(5, 9), (0, 2), (3, 4), (20, 25), (8, 12), (14, 14)].into_iter(), &mut out);
        assert_eq!(out, [(0, 12), (14, 14), (20, 25)]);
    }
}
