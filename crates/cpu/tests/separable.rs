//! The exact mode's incremental update (`IntegrationWork::Changes`) against an
//! independent answer: after every step, the map must equal a fresh exact
//! batch EDT of all the obstacles (the shared `recompute_exact`, through the
//! batch EDT whose tie rule `separable_oracle` checks), block for block,
//! nearest obstacles included, and its distances the brute-force ones.
//! Steps make obstacles appear and vanish, sparse and in walls, inside and
//! outside earlier windows, and sometimes hand the backend a map it has not
//! seen (a clone), so the cache is rebuilt from the map. The blocks the
//! update reports changed must be exactly those where a voxel changed, and
//! the voxels it counts (and among them those whose nearest obstacle alone
//! changed) and their change in distance those found by comparing the
//! maps, as the obstacles it counts added and removed are.

use edtmap_core::exact::{recompute_exact, ExactBuffers};
use edtmap_core::region::{Packing, Region};
use edtmap_core::{
    Backend, BlockKey, Cutoff, EdtMap, FixedMap, GlobalParams, IntegrationJob, IntegrationWork, LogOdds, Obstacles,
    OccupancyMap, OccupancyParams, VoxelIndex, BLOCK_VOXELS, FAR_DIST_SQ, NO_OFFSET,
};
use edtmap_cpu::CpuBackend;
use proptest::prelude::*;
use std::collections::BTreeSet;

/// The box obstacles live in, voxels.
const LO: [i32; 3] = [-13, -9, -6];
const DIMS: [i32; 3] = [30, 22, 15];

struct World {
    lo: LogOdds,
    occ: OccupancyMap,
    fixed: FixedMap,
    set: BTreeSet<VoxelIndex>,
}

impl World {
    fn obstacles(&self) -> Obstacles<'_> {
        Obstacles { occupancy: &self.occ, log_odds: &self.lo, fixed: &self.fixed, unknown_as_occupied: false }
    }

    fn toggle(&mut self, v: VoxelIndex) {
        let now = !self.set.contains(&v);
        let value = if now { self.lo.max } else { self.lo.min };
        self.occ.get_or_insert(v.block()).log_odds.set(v.offset_in_block(), value);
        if now {
            self.set.insert(v);
        } else {
            self.set.remove(&v);
        }
    }
}

/// The exact EDT of `world`'s obstacles over the box grown by the reach.
fn reference(world: &World, cutoff: Cutoff) -> EdtMap {
    let mut map = EdtMap::new();
    let region = Region { origin: LO, dims: DIMS.map(|d| d as usize) }.grown(cutoff.reach + 1);
    let packing = Packing::new(region, cutoff).expect("small region");
    let mut edt = CpuBackend::default();
    recompute_exact(&mut edt, &mut map, &world.obstacles(), &packing, &mut ExactBuffers::default()).expect("cpu");
    map
}

fn brute(world: &World, v: VoxelIndex, max: u32) -> u32 {
    let d = world.set.iter().map(|o| (0..3).map(|a| i64::from(v.0[a] - o.0[a]).pow(2)).sum::<i64>()).min();
    match d {
        Some(d) if d <= i64::from(max) => d as u32,
        _ => FAR_DIST_SQ,
    }
}

/// One step: `(kind, a, b, c)` drawn by proptest.
fn step(world: &mut World, (kind, a, b, c): (u8, u32, u32, u32)) -> Vec<BlockKey> {
    let at = |k: u32, axis: usize| LO[axis] + (k % DIMS[axis] as u32) as i32;
    let mut touched = Vec::new();
    match kind % 4 {
        // A wall along y, appearing or vanishing as a whole.
        0 => {
            let (x, z, y0) = (at(a, 0), at(c, 2), at(b, 1));
            for y in y0..(y0 + 6).min(LO[1] + DIMS[1]) {
                touched.push(VoxelIndex([x, y, z]));
            }
        }
        // A slab in the xz plane.
        1 => {
            let (x0, y, z0) = (at(a, 0), at(b, 1), at(c, 2));
            for z in z0..(z0 + 3).min(LO[2] + DIMS[2]) {
                for x in x0..(x0 + 4).min(LO[0] + DIMS[0]) {
                    touched.push(VoxelIndex([x, y, z]));
                }
            }
        }
        // Sparse noise.
        _ => {
            let mut s = u64::from(a) << 32 | u64::from(b ^ c.rotate_left(7));
            for _ in 0..1 + c % 9 {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let r = (s >> 33) as u32;
                touched.push(VoxelIndex([at(r, 0), at(r / 31, 1), at(r / 701, 2)]));
            }
        }
    }
    touched.sort_unstable();
    touched.dedup();
    for &v in &touched {
        world.toggle(v);
    }
    let mut blocks: Vec<BlockKey> = touched.iter().map(|v| v.block()).collect();
    blocks.sort_unstable();
    blocks.dedup();
    blocks
}

/// Runs `steps` from an empty map at a cutoff of `cutoff_tenths` / 10
/// voxels, checking the map after each.
fn check(cutoff_tenths: u32, steps: Vec<(u8, u32, u32, u32)>, clone_at: usize) -> Result<(), TestCaseError> {
    let lo = OccupancyParams::default().log_odds().expect("default parameters");
    let mut world = World { lo, occ: OccupancyMap::new(), fixed: FixedMap::new(), set: BTreeSet::new() };
    let params = GlobalParams { max_distance_m: f64::from(cutoff_tenths) / 10.0, ..Default::default() };
    let cutoff = params.cutoff(1.0).expect("valid cutoff");
    let mut backend = CpuBackend::default();
    let mut map = EdtMap::new();
    for (i, s) in steps.into_iter().enumerate() {
        if i == clone_at {
            // A map the backend has not seen: its cache is rebuilt.
            map = map.clone();
        }
        let blocks = step(&mut world, s);
        let before = map.clone();
        let report = backend
            .integrate(IntegrationJob {
                map: &mut map,
                obstacles: world.obstacles(),
                cutoff,
                work: IntegrationWork::Changes { blocks: &blocks },
            })
            .expect("cpu");
        // The blocks reported changed are those where some voxel changed.
        let keys: BTreeSet<BlockKey> = before.iter().chain(map.iter()).map(|(k, _)| k).collect();
        let differ: Vec<BlockKey> = keys.into_iter().filter(|&k| before.get(k) != map.get(k)).collect();
        prop_assert_eq!(&report.changed_blocks, &differ, "step {}: changed blocks", i);
        // The voxels reported changed (distance or nearest obstacle), and
        // the sum of their distances' changes, distances capped at the
        // cutoff (the paper's change score, eq. 6, before the mean).
        let capped = |o: [i16; 3]| {
            let d = if o == NO_OFFSET { f64::INFINITY } else { o.iter().map(|&c| f64::from(c).powi(2)).sum() };
            d.min(f64::from(cutoff.max_dist_sq)).sqrt()
        };
        let (mut changed, mut sum, mut nearest_only) = (0, 0.0, 0);
        for &k in &differ {
            for o in 0..BLOCK_VOXELS {
                let at = |m: &EdtMap| m.get(k).map_or(NO_OFFSET, |b| b.to_nearest[o]);
                let (was, now) = (at(&before), at(&map));
                if was != now {
                    changed += 1;
                    sum += (capped(now) - capped(was)).abs();
                    nearest_only +=
                        usize::from(before.get(k).map(|b| b.dist_sq(o)) == map.get(k).map(|b| b.dist_sq(o)));
                }
            }
        }
        prop_assert_eq!(report.voxels_changed, changed, "step {}: voxels changed", i);
        // Of those, the ones whose nearest obstacle alone changed; the
        // obstacles that appeared (apart: no obstacle among their 26
        // neighbours before) and vanished.
        prop_assert_eq!(
            (report.exact.changed[2], report.exact.nearest_only[2]),
            (changed, nearest_only),
            "step {}: nearest only",
            i
        );
        let added: Vec<VoxelIndex> = world.set.iter().copied().filter(|&v| before.entry(v).0 != 0).collect();
        let apart = added.iter().filter(|&&v| before.entry(v).0 > 3).count();
        let removed = before
            .iter()
            .flat_map(|(k, b)| (0..BLOCK_VOXELS).filter(move |&o| b.dist_sq(o) == 0).map(move |o| k.voxel(o)))
            .filter(|v| !world.set.contains(v))
            .count();
        prop_assert_eq!(
            (report.exact.obstacles_added, report.exact.obstacles_added_apart, report.exact.obstacles_removed),
            (added.len(), apart, removed),
            "step {}: obstacles added, apart, removed",
            i
        );
        prop_assert!(
            (report.change_sum_vox - sum).abs() <= 1e-9 * sum.max(1.0),
            "step {}: change sum {} against {}",
            i,
            report.change_sum_vox,
            sum
        );
        let want = reference(&world, cutoff);
        prop_assert_eq!(map.len(), want.len(), "step {}: blocks", i);
        for (key, block) in want.iter() {
            prop_assert!(map.get(key) == Some(block), "step {}: block {:?} differs from the batch EDT", i, key);
        }
        for z in LO[2] - 2..LO[2] + DIMS[2] + 2 {
            for y in LO[1] - 2..LO[1] + DIMS[1] + 2 {
                for x in LO[0] - 2..LO[0] + DIMS[0] + 2 {
                    let v = VoxelIndex([x, y, z]);
                    prop_assert_eq!(map.entry(v).0, brute(&world, v, cutoff.max_dist_sq), "step {}: voxel {:?}", i, v);
                }
            }
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, .. ProptestConfig::default() })]

    #[test]
    fn changes_keep_the_map_the_exact_batch_edt(
        cutoff_tenths in 10u32..60,
        steps in prop::collection::vec((any::<u8>(), any::<u32>(), any::<u32>(), any::<u32>()), 1..14),
        clone_at in 0usize..20,
    ) {
        check(cutoff_tenths, steps, clone_at)?;
    }

    /// Cutoffs of 8 to 20 voxels: lines long enough that the outputs a
    /// lowered entry lowers are found by bisection.
    #[test]
    fn changes_keep_the_map_exact_at_long_cutoffs(
        cutoff_tenths in 80u32..200,
        steps in prop::collection::vec((any::<u8>(), any::<u32>(), any::<u32>(), any::<u32>()), 1..10),
        clone_at in 0usize..20,
    ) {
        check(cutoff_tenths, steps, clone_at)?;
    }
}
