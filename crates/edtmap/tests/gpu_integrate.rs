//! The GPU's wavefront integration against the CPU's (the reference),
//! through the same stage, on
//! the conformance suite's random worlds: after every step both global
//! EDTs must hold the same blocks with the same squared distances and
//! nearest obstacles, and the GPU's must pass the brute-force checks. The
//! same with the window's batch EDT left to each backend
//! (`integrate_mask`: on the GPU it never leaves the device).

#[path = "../../gpu/tests/common/mod.rs"]
mod gpu_common;
use gpu_common as common;

use edtmap::cpu::CpuBackend;
use edtmap::stages::IntegrationStage;
use edtmap_conformance::IntegrationWorld;
use edtmap_core::{BatchEdt, Connectivity, EdtField, EdtMap, GlobalParams, IntegrationMode};

/// Sorted (key, block) pairs of `map`, for an exact comparison.
fn blocks(map: &EdtMap) -> Vec<(edtmap_core::BlockKey, edtmap_core::EdtBlock)> {
    let mut v: Vec<_> = map.iter().map(|(k, b)| (k, b.clone())).collect();
    v.sort_by_key(|(k, _)| *k);
    v
}

#[test]
fn wavefront_integration_is_bit_identical_to_the_cpu() {
    let Some(mut gpu) = common::gpu_or_skip("GPU integration") else { return };
    let Some(mut gpu_masked) = common::gpu_or_skip("GPU integration") else { return };
    let conns = [Connectivity::Six, Connectivity::Eighteen, Connectivity::TwentySix];
    let mut cases = 0;
    for seed in 0..12u64 {
        let connectivity = conns[seed as usize % 3];
        let cutoff_vox = 2 + seed % 6;
        let params = GlobalParams {
            mode: IntegrationMode::Wavefront,
            connectivity,
            max_distance_m: cutoff_vox as f64 * IntegrationWorld::VOXEL_M,
            ..Default::default()
        };
        let mut world = IntegrationWorld::new(seed);
        let stage = IntegrationStage::new(&params, IntegrationWorld::VOXEL_M).expect("valid");
        let (mut cpu, mut cpu_masked) = (CpuBackend::default(), CpuBackend::default());
        let (mut cpu_map, mut gpu_map) = (EdtMap::new(), EdtMap::new());
        let (mut cpu_mask_map, mut gpu_mask_map) = (EdtMap::new(), EdtMap::new());
        let mut batch = EdtField::empty();
        for step in 0..10 {
            let (window, mask) = world.step();
            gpu.batch_edt(&mask, &mut batch).expect("batch EDT");
            let cpu_report =
                stage.merge_window(&mut cpu, &mut cpu_map, world.obstacles(), &window, &batch).expect("cpu");
            let gpu_report =
                stage.merge_window(&mut gpu, &mut gpu_map, world.obstacles(), &window, &batch).expect("gpu");
            let at = format!("seed {seed}, {} neighbours, cutoff {cutoff_vox}, step {step}", u8::from(connectivity));
            assert!(blocks(&cpu_map) == blocks(&gpu_map), "{at}: the maps differ");
            assert_eq!(cpu_report.changed_blocks, gpu_report.changed_blocks, "{at}");
            assert_eq!(cpu_report.voxels_changed, gpu_report.voxels_changed, "{at}");
            assert_eq!(
                (cpu_report.waves.raised, cpu_report.waves.seeds, cpu_report.waves.levels),
                (gpu_report.waves.raised, gpu_report.waves.seeds, gpu_report.waves.levels),
                "{at}"
            );
            world.check(&gpu_map, &params).unwrap_or_else(|e| panic!("{at}: {e}"));
            for (name, backend, map) in [
                ("cpu", &mut cpu_masked as &mut dyn edtmap_core::Backend, &mut cpu_mask_map),
                ("gpu", &mut gpu_masked, &mut gpu_mask_map),
            ] {
                let report = stage
                    .merge_window_mask(backend, map, world.obstacles(), &window, &mask)
                    .unwrap_or_else(|e| panic!("{at}, {name} from the mask: {e}"));
                assert!(blocks(&cpu_map) == blocks(map), "{at}: {name} from the mask differs");
                assert_eq!(
                    (&report.changed_blocks, report.voxels_changed),
                    (&cpu_report.changed_blocks, cpu_report.voxels_changed),
                    "{at}: {name} from the mask"
                );
            }
            cases += 1;
        }
    }
    assert_eq!(cases, 120);
}
