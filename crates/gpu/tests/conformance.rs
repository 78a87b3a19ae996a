//! The backend conformance suite (`edtmap_sim::conformance`) on the GPU:
//! the same oracles as the CPU, bit for bit. Without an adapter the tests
//! say so and pass, unless `EDTMAP_REQUIRE_GPU=1` (CI sets it, with
//! lavapipe installed), where a missing adapter fails them.

mod common;

use edtmap::config::Config;
use edtmap::cpu::occupancy::{project_job, OccupancyStage};
use edtmap_core::{Backend, LocalVolume, PROJ_UNCERTAIN};
use edtmap_sim::conformance::{check_batch_edt, check_projection, check_raycast};
use edtmap_sim::{Scene, SceneName, SceneOptions};
use std::path::PathBuf;

#[test]
fn batch_edt_matches_the_separable_oracle() {
    let Some(mut gpu) = common::gpu_or_skip("GPU conformance") else { return };
    eprintln!("device: {}", edtmap_core::Backend::name(&gpu));
    let checked = check_batch_edt(&mut gpu).unwrap_or_else(|e| panic!("{e}"));
    assert!(checked > 100_000);
}

#[test]
fn ray_casting_matches_the_walk_definition() {
    let Some(mut gpu) = common::gpu_or_skip("GPU conformance") else { return };
    let checked = check_raycast(&mut gpu).unwrap_or_else(|e| panic!("{e}"));
    assert!(checked.is_some_and(|n| n > 9_000), "the GPU casts rays itself");
}

#[test]
fn projection_matches_the_definition_where_certain() {
    let Some(mut gpu) = common::gpu_or_skip("GPU conformance") else { return };
    let tally = check_projection(&mut gpu).unwrap_or_else(|e| panic!("{e}")).expect("the GPU projects depth images and planar scans itself");
    for (kind, (voxels, uncertain)) in [("depth", tally.depth), ("planar", tally.planar), ("aligned", tally.aligned)] {
        let share = uncertain as f64 / voxels as f64;
        eprintln!("{kind}: {uncertain} of {voxels} voxels uncertain ({:.4} %)", 100.0 * share);
        // Aligned cases put whole layers of voxels on thresholds.
        assert!(kind == "aligned" || share < 0.01, "{kind}: too many uncertain voxels");
    }
}

/// The share of uncertain voxels on the projecting scenes (room: a depth
/// camera; planar: a 2D scan), and the observations after the host's
/// decision identical to the CPU's.
#[test]
fn projection_on_the_scenes_is_the_cpus() {
    let Some(mut gpu) = common::gpu_or_skip("GPU conformance") else { return };
    for name in ["room", "planar"] {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../../configs/{name}.toml"));
        let (sensor, params) = Config::load(&path).expect("shipped config").mapper_params().expect("valid config");
        let scene = Scene::new(name.parse::<SceneName>().expect("scene name"), &SceneOptions::default()).expect("scene");
        let (mut cpu_stage, mut gpu_stage) = (OccupancyStage::default(), OccupancyStage::default());
        let (mut voxels, mut uncertain, mut bits) = (0, 0, Vec::new());
        let step = (scene.default_frames() / 10).max(1);
        for i in (0..10).map(|k| k * step) {
            let frame = scene.frame(&sensor, i).expect("frame");
            let centre = frame.t_world_sensor.translation.vector.into();
            let volume = LocalVolume::centred(&params.volume, params.voxel_size_m, centre).expect("volume");
            assert!(gpu.project_volume(project_job(&sensor, &frame, volume, &params.ogm), &mut bits).expect("projection"));
            voxels += bits.len();
            uncertain += bits.iter().filter(|&&b| b == PROJ_UNCERTAIN).count();
            let want = cpu_stage.observe(&sensor, &frame, volume, &params.ogm).expect("cpu");
            let got = gpu_stage.observe_on(&mut gpu, &sensor, &frame, volume, &params.ogm).expect("gpu");
            assert!((0..volume.len()).all(|v| want.get(v) == got.get(v)), "{name} frame {i}: observations differ");
        }
        let share = uncertain as f64 / voxels as f64;
        eprintln!("{name}: {uncertain} of {voxels} voxels uncertain ({:.4} %)", 100.0 * share);
        assert!(share < 0.01, "{name}: too many uncertain voxels");
    }
}
