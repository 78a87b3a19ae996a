//! The exact integration's resident block pool on the GPU against the CPU
//! backend, map for map and report for report: frame after frame (the
//! pool kept), with the map changed in between by the CPU (the pool
//! dropped), with a pool too small to keep anything (blocks evicted every
//! frame), and from a map holding values the pool cannot encode. The CPU's
//! exact update is itself checked against brute force by the conformance
//! suite. Also: what a frame costs in traffic.

mod common;

use std::collections::HashMap;

use edtmap::stages::IntegrationStage;
use edtmap_conformance::IntegrationWorld;
use edtmap_core::exact::{recompute_exact, ExactBuffers};
use edtmap_core::region::{Packing, Region};
use edtmap_core::{Backend, BlockKey, EdtMap, GlobalParams, IntegrationMode, IntegrationReport, VoxelIndex};
use edtmap_cpu::CpuBackend;

/// Every block of `map`, sorted, as comparable rows.
fn rows(map: &EdtMap) -> Vec<(BlockKey, Vec<[i16; 3]>)> {
    let mut rows: Vec<_> = map.iter().map(|(k, b)| (k, b.to_nearest.iter().collect::<Vec<_>>())).collect();
    rows.sort_by_key(|r| r.0 .0);
    rows
}

fn stage(cutoff_vox: u64) -> IntegrationStage {
    let params = GlobalParams {
        mode: IntegrationMode::Exact,
        max_distance_m: cutoff_vox as f64 * IntegrationWorld::VOXEL_M,
        ..Default::default()
    };
    IntegrationStage::new(&params, IntegrationWorld::VOXEL_M).expect("valid cutoff")
}

fn same_report(a: &IntegrationReport, b: &IntegrationReport, at: &str) {
    assert_eq!(a.voxels_changed, b.voxels_changed, "{at}: voxels changed");
    assert_eq!(a.changed_blocks, b.changed_blocks, "{at}: changed blocks");
    assert!((a.change_sum_vox - b.change_sum_vox).abs() <= 1e-9 * a.change_sum_vox.max(1.0), "{at}: change sum");
}

/// A GPU map kept equal to a CPU map while the pool is kept, dropped
/// (every third frame runs on the CPU instead) or evicted (a one-block
/// cap leaves only the current region resident), whole or in tiles.
#[test]
fn resident_pool_gives_the_cpu_map_frame_after_frame() {
    let Some(mut gpu) = common::gpu_or_skip("resident pool") else { return };
    let Some(mut tiny) = common::gpu_or_skip("resident pool") else { return };
    tiny.limit_resident_blocks(1);
    // Regions in tiles of at most 24³ source voxels: the cutoffs of 2–7
    // voxels leave tiles of 8 to 16 voxels a side.
    tiny.limit_tile_voxels(24 * 24 * 24);
    for seed in 0..6u64 {
        let stage = stage(2 + seed % 6);
        for (name, backend) in [("default pool", &mut gpu), ("one-block cap, small tiles", &mut tiny)] {
            let mut world = IntegrationWorld::new(100 + seed);
            let (mut cpu_map, mut gpu_map) = (EdtMap::new(), EdtMap::new());
            let mut cpu = CpuBackend::default();
            for step in 0..14 {
                let at = format!("{name}, seed {seed}, step {step}");
                let (window, _) = world.step();
                let blocks = window.region().blocks();
                let want = stage.apply_changes(&mut cpu, &mut cpu_map, world.obstacles(), &blocks).expect("cpu");
                let mut other = CpuBackend::default();
                let on: &mut dyn Backend = if step % 3 == 2 { &mut other } else { &mut *backend };
                let got = stage
                    .apply_changes(on, &mut gpu_map, world.obstacles(), &blocks)
                    .unwrap_or_else(|e| panic!("{at}: {e}"));
                same_report(&got, &want, &at);
                assert!(rows(&gpu_map) == rows(&cpu_map), "{at}: maps differ");
            }
        }
    }
}

/// Unknown voxels as obstacles: blocks the map lacks are obstacles only
/// (the device's `FULL` entry, no slot), observed blocks mixed; the map
/// still the CPU's, frame after frame. The maps start as the EDT of a box
/// around every window (the unknown space outside the windows is
/// obstacles from the start: an update takes the obstacles to change only
/// in the blocks it is given).
#[test]
fn unknown_as_occupied_gives_the_cpu_map() {
    let Some(mut gpu) = common::gpu_or_skip("resident pool") else { return };
    for seed in 0..3u64 {
        let stage = stage(3 + seed);
        let mut world = IntegrationWorld::new(40 + seed);
        let mut cpu = CpuBackend::default();
        let mut cpu_map = EdtMap::new();
        let around = Region { origin: [-48, -40, -40], dims: [96, 80, 80] };
        let obstacles = edtmap_core::Obstacles { unknown_as_occupied: true, ..world.obstacles() };
        stage.recompute(&mut cpu, &mut cpu_map, obstacles, &around).expect("cpu");
        let mut gpu_map = cpu_map.clone();
        for step in 0..8 {
            let at = format!("seed {seed}, step {step}");
            let (window, _) = world.step();
            let blocks = window.region().blocks();
            let obstacles = edtmap_core::Obstacles { unknown_as_occupied: true, ..world.obstacles() };
            let want = stage.apply_changes(&mut cpu, &mut cpu_map, obstacles, &blocks).expect("cpu");
            let got =
                stage.apply_changes(&mut gpu, &mut gpu_map, obstacles, &blocks).unwrap_or_else(|e| panic!("{at}: {e}"));
            same_report(&got, &want, &at);
            assert!(rows(&gpu_map) == rows(&cpu_map), "{at}: maps differ");
        }
    }
}

/// A map whose stored values are not the EDT of its obstacles (an
/// obstacle that is not one, one beyond the reach, which the pool cannot
/// encode) is rewritten as the host-side definition does (`recompute_exact` on the
/// CPU's batch EDT: the region recomputed, written where it differs).
#[test]
fn values_the_pool_cannot_encode_are_rewritten_as_the_definition_says() {
    let Some(mut gpu) = common::gpu_or_skip("resident pool") else { return };
    let stage = stage(4);
    let mut world = IntegrationWorld::new(7);
    let (window, _) = world.step();
    let blocks = window.region().blocks();
    let mut start = EdtMap::new();
    stage.apply_changes(&mut CpuBackend::default(), &mut start, world.obstacles(), &blocks).expect("cpu");
    let odd = [
        (window.world([3, 4, 2]), 3, [1, 1, -1]),
        (window.world([9, 2, 5]), 490_000, [700, 0, 0]),
        (window.world([0, 0, 0]), 0, [0, 0, 0]),
    ];
    for (v, dist_sq, off) in odd {
        let block = start.get_or_insert(v.block());
        block
            .set(v.block(), v.offset_in_block(), dist_sq, VoxelIndex([0, 1, 2].map(|a| v.0[a] + off[a])))
            .expect("within the offsets' range");
    }
    let (mut host_map, mut gpu_map) = (start.clone(), start);
    let region = Region::bounding(&blocks).expect("blocks").grown(stage.cutoff().reach);
    let packing = Packing::new(region, stage.cutoff()).expect("packing");
    let want = recompute_exact(
        &mut CpuBackend::default(),
        &mut host_map,
        &world.obstacles(),
        &packing,
        &mut ExactBuffers::default(),
    )
    .expect("host");
    let got = stage.apply_changes(&mut gpu, &mut gpu_map, world.obstacles(), &blocks).expect("gpu");
    assert_eq!((got.voxels_changed, &got.changed_blocks), (want.voxels_changed, &want.changed_blocks));
    assert!(want.voxels_changed >= 2, "the odd voxels rewritten");
    assert!(rows(&gpu_map) == rows(&host_map), "maps differ");
}

/// Traffic of one exact frame with the pools warm: up, the two slot tables
/// (4 bytes per region block, 4 per source block) and the obstacle blocks
/// whose bits the device does not hold yet (64 bytes each; blocks with no
/// obstacle or nothing else take none), no EDT block (all resident); down,
/// the changed-block list and only the changed blocks (2 KiB each); the
/// batch EDT's four dispatches and one more, in two submissions (one when
/// nothing changed).
#[test]
fn a_warm_frame_moves_only_changed_blocks() {
    let Some(mut gpu) = common::gpu_or_skip("resident pool") else { return };
    let stage = stage(5);
    let cutoff = stage.cutoff();
    let mut world = IntegrationWorld::new(3);
    let mut map = EdtMap::new();
    // The whole box once, so that every later region is resident.
    let all = Region { origin: [-32, -24, -24], dims: [64, 48, 48] };
    let blocks = all.blocks();
    let before = gpu.device_counters().expect("counters");
    stage.apply_changes(&mut gpu, &mut map, world.obstacles(), &blocks).expect("gpu");
    let cold = gpu.device_counters().expect("counters").since(before);
    // The bits of each block the device was last sent, as the test counts
    // them: a block goes up when its bits differ from these.
    let mut sent: HashMap<BlockKey, [u64; 8]> = HashMap::new();
    let mut obstacle_blocks_up = |source: Region, obstacles: &edtmap_core::Obstacles<'_>| {
        let mut up = 0;
        for key in source.blocks() {
            let bits = obstacles.block_bits(key);
            if bits.iter().all(|&w| w == 0) || bits.iter().all(|&w| w == u64::MAX) {
                continue;
            }
            if sent.insert(key, bits) != Some(bits) {
                up += 1;
            }
        }
        up
    };
    let region = Region::bounding(&blocks).expect("blocks").grown(cutoff.reach);
    let obstacle_blocks = obstacle_blocks_up(region.grown(cutoff.reach), &world.obstacles());
    // Cold, on an empty map: no EDT block goes up (the pool's slots are
    // cleared on the device), only the tables and the obstacle blocks.
    let tables = 4 * region.blocks().len() as u64 + 4 * region.grown(cutoff.reach).blocks().len() as u64;
    let least = tables + 64 * obstacle_blocks;
    assert!(
        cold.uploaded_bytes >= least && cold.uploaded_bytes <= least + 4 * 256 + 64,
        "cold: {cold:?}, tables {tables}, obstacle blocks {obstacle_blocks}"
    );
    let (mut checked, mut moved) = (0, 0);
    for step in 0..10 {
        let (window, _) = world.step();
        let blocks = window.region().blocks();
        let region = Region::bounding(&blocks).expect("blocks").grown(cutoff.reach);
        let nb = region.blocks().len() as u64;
        let source = region.grown(cutoff.reach);
        let before = gpu.device_counters().expect("counters");
        let report = stage.apply_changes(&mut gpu, &mut map, world.obstacles(), &blocks).expect("gpu");
        let d = gpu.device_counters().expect("counters").since(before);
        let changed = report.changed_blocks.len() as u64;
        assert_eq!(d.downloaded_bytes, 16 + 4 * nb + 2048 * changed, "step {step}: {d:?}");
        let obstacle_blocks = obstacle_blocks_up(source, &world.obstacles());
        let tables = 4 * nb + 4 * source.blocks().len() as u64;
        let (least, params) = (tables + 64 * obstacle_blocks, 4 * 256 + 64);
        assert!(
            d.uploaded_bytes >= least && d.uploaded_bytes <= least + params,
            "step {step}: {d:?}, tables {tables}, obstacle blocks {obstacle_blocks}"
        );
        // Against the mask it replaces, a bit per source voxel.
        assert!(d.uploaded_bytes < 4 * (source.len() as u64).div_ceil(32), "step {step}: {d:?}");
        moved += usize::from(obstacle_blocks > 0);
        assert_eq!(d.dispatches, 5, "step {step}");
        assert_eq!(d.submissions, if changed > 0 { 2 } else { 1 }, "step {step}");
        checked += usize::from(changed > 0);
    }
    assert!(checked >= 5, "too few frames changed anything");
    assert!(moved >= 5, "too few frames moved an obstacle block");
}
