//! The whole pipeline on the GPU against the CPU, frame by frame, on the
//! built-in scenes with their shipped configs: the fusion's counts (the
//! GPU fuses on the device), the local occupancy states,
//! the local batch EDT (squared distances and nearest obstacles), the
//! global occupancy map and the global EDT must all be identical.

#[path = "../../gpu/tests/common/mod.rs"]
mod gpu_common;
use gpu_common as common;

use edtmap::config::Config;
use edtmap::sensor::Sensor;
use edtmap::stages::Construction;
use edtmap::{Backend, GlobalMap, IntegrationMode, Mapper, MapperParams};
use edtmap_gpu::GpuBackend;
use edtmap_sim::{Scene, SceneName, SceneOptions};
use std::path::PathBuf;

fn setup(scene: &str) -> (Scene, Sensor, MapperParams) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../../configs/{scene}.toml"));
    let (sensor, params) = Config::load(&path).expect("shipped config").mapper_params().expect("valid config");
    let name: SceneName = scene.parse().expect("scene name");
    (Scene::new(name, &SceneOptions::default()).expect("scene"), sensor, params)
}

/// Sorted blocks of both hashes of `map`, for exact comparison.
fn snapshot(map: &GlobalMap) -> (Vec<String>, Vec<String>) {
    let mut occ: Vec<String> = map
        .occupancy()
        .iter()
        .map(|(k, b)| format!("{k:?} {:?}", b.log_odds.iter().map(f32::to_bits).collect::<Vec<_>>()))
        .collect();
    let mut edt: Vec<String> = map.edt().iter().map(|(k, b)| format!("{k:?} {:?}", b.to_nearest)).collect();
    occ.sort();
    edt.sort();
    (occ, edt)
}

fn compare(
    scene_name: &str,
    construction: Construction,
    mode: IntegrationMode,
    frames: usize,
    backend: GpuBackend,
) -> GpuBackend {
    let (scene, sensor, mut params) = setup(scene_name);
    params.ogm.construction = construction;
    params.global.mode = mode;
    let mut cpu = Mapper::new(sensor.clone(), params.clone()).expect("cpu mapper");
    let mut gpu = Mapper::new_on(backend, sensor.clone(), params).expect("gpu mapper");
    let step = (scene.default_frames() / frames).max(1);
    for i in (0..frames).map(|k| k * step) {
        let frame = scene.frame(&sensor, i).expect("frame");
        let a = cpu.integrate_frame(&frame).expect("cpu frame");
        let b = gpu.integrate_frame(&frame).expect("gpu frame");
        let at = format!("{scene_name} {construction:?} {mode:?} frame {i}");
        // The fusion (on the device for the GPU): the same counts.
        assert_eq!(
            (a.voxels_updated, a.voxels_changed, a.occupancy_rewritten_blocks),
            (b.voxels_updated, b.voxels_changed, b.occupancy_rewritten_blocks),
            "{at}: fusion counts"
        );
        assert_eq!(a.changed_blocks, b.changed_blocks, "{at}: changed blocks");
        assert_eq!(a.edt_voxels_changed, b.edt_voxels_changed, "{at}: EDT voxels changed");
        assert!(cpu.local_states() == gpu.local_states(), "{at}: local states differ");
        assert!(cpu.local_edt() == gpu.local_edt(), "{at}: local batch EDT differs");
        assert!(snapshot(cpu.map()) == snapshot(gpu.map()), "{at}: global maps differ");
    }
    // Hand the device on to the next scene rather than opening another.
    gpu.into_backend()
}

#[test]
fn every_scene_is_bit_identical_on_both_backends() {
    let Some(mut backend) = common::gpu_or_skip("the GPU pipeline") else { return };
    eprintln!("device: {}", backend.name());
    for scene in ["uav_pillars", "ugv_corridor", "room", "planar"] {
        for construction in [Construction::RayCasting, Construction::Auto] {
            backend = compare(scene, construction, IntegrationMode::Wavefront, 4, backend);
        }
        // The exact mode: the device's batch EDT inside the shared host code.
        backend = compare(scene, Construction::Auto, IntegrationMode::Exact, 4, backend);
    }
}

/// A projection with more uncertain voxels than its list holds reads every
/// code back and is fused on the host; the frames after it fuse on the
/// device again, from a pool that must see what the host fusion changed.
#[test]
fn frames_whose_uncertain_voxels_overflow_the_list_are_the_cpus_too() {
    let Some(mut backend) = common::gpu_or_skip("the GPU pipeline") else { return };
    // No room at all: every frame with an uncertain voxel overflows.
    backend.limit_uncertain_list(0);
    let (scene, sensor, params) = setup("room");
    let mut cpu = Mapper::new(sensor.clone(), params.clone()).expect("cpu mapper");
    let mut gpu = Mapper::new_on(backend, sensor.clone(), params.clone()).expect("gpu mapper");
    let window = edtmap::LocalVolume::centred(&params.volume, params.voxel_size_m, [0.0; 3]).expect("window");
    let voxels = window.len() as u64;
    let mut overflowed = 0;
    for i in (0..8).map(|k| k * 7) {
        let frame = scene.frame(&sensor, i).expect("frame");
        let before = gpu.backend().device_counters().expect("a device");
        let a = cpu.integrate_frame(&frame).expect("cpu frame");
        let b = gpu.integrate_frame(&frame).expect("gpu frame");
        // The codes came back: a quarter byte per window voxel.
        overflowed += usize::from(
            gpu.backend().device_counters().expect("a device").since(before).downloaded_bytes >= voxels / 4,
        );
        assert_eq!(
            (a.voxels_updated, a.voxels_changed, a.changed_blocks.clone()),
            (b.voxels_updated, b.voxels_changed, b.changed_blocks.clone()),
            "frame {i}"
        );
        assert!(snapshot(cpu.map()) == snapshot(gpu.map()), "frame {i}: global maps differ");
    }
    assert!(overflowed > 0, "no frame overflowed the list");
    // Then with the default list, on the same device: fused there again.
    let mut backend = gpu.into_backend();
    backend.limit_uncertain_list(usize::MAX);
    let mut gpu = Mapper::with_map_on(backend, sensor.clone(), params, cpu.map().clone()).expect("gpu mapper");
    for i in (60..66).map(|k| k * 3) {
        let frame = scene.frame(&sensor, i).expect("frame");
        cpu.integrate_frame(&frame).expect("cpu frame");
        gpu.integrate_frame(&frame).expect("gpu frame");
        assert!(snapshot(cpu.map()) == snapshot(gpu.map()), "frame {i}: global maps differ");
    }
}

/// A planar map's passes run on the CPU only: a mapper on the GPU refuses
/// it when made, naming it, rather than at the first frame.
#[test]
fn a_planar_map_is_refused_on_the_gpu_when_the_mapper_is_made() {
    let Some(backend) = common::gpu_or_skip("the GPU pipeline") else { return };
    let (_, sensor, mut params) = setup("planar");
    params.global.planar = true;
    let Err(err) = Mapper::new_on(backend, sensor, params) else { panic!("a planar map on the GPU was accepted") };
    assert!(err.to_string().contains("planar map") && err.to_string().contains("CPU"), "{err}");
}
