//! The GPU's projection on the projecting scenes (room: a depth camera;
//! planar: a 2D scan): few voxels left to the host, and the observations
//! identical to the CPU's. Skipped without an adapter unless
//! `EDTMAP_REQUIRE_GPU=1`.

#[path = "../../gpu/tests/common/mod.rs"]
mod gpu_common;
use gpu_common as common;

use edtmap::config::Config;
use edtmap::cpu::CpuBackend;
use edtmap::stages::{project_job, OccupancyStage};
use edtmap_core::{LocalVolume, PROJ_UNCERTAIN};
use edtmap_sim::{Scene, SceneName, SceneOptions};
use std::path::PathBuf;

/// The share of uncertain voxels on the projecting scenes (room: a depth
/// camera; planar: a 2D scan), and the observations after the host's
/// decision identical to the CPU's.
#[test]
fn projection_on_the_scenes_is_the_cpus() {
    let Some(mut gpu) = common::gpu_or_skip("GPU conformance") else { return };
    for name in ["room", "planar"] {
        let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../../configs/{name}.toml"));
        let (sensor, params) = Config::load(&path).expect("shipped config").mapper_params().expect("valid config");
        let scene =
            Scene::new(name.parse::<SceneName>().expect("scene name"), &SceneOptions::default()).expect("scene");
        let (mut cpu_stage, mut gpu_stage) = (OccupancyStage::default(), OccupancyStage::default());
        let (mut voxels, mut uncertain, mut bits) = (0, 0, Vec::new());
        let step = (scene.default_frames() / 10).max(1);
        for i in (0..10).map(|k| k * step) {
            let frame = scene.frame(&sensor, i).expect("frame");
            let centre = frame.t_world_sensor.translation.vector.into();
            let volume = LocalVolume::centred(&params.volume, params.voxel_size_m, centre).expect("volume");
            assert!(gpu
                .project_bits(&project_job(&sensor, &frame, volume, &params.ogm).expect("projectable"), &mut bits)
                .expect("projection"));
            voxels += bits.len();
            uncertain += bits.iter().filter(|&&b| b == PROJ_UNCERTAIN).count();
            let want =
                cpu_stage.observe(&mut CpuBackend::default(), &sensor, &frame, volume, &params.ogm).expect("cpu");
            let got = gpu_stage.observe(&mut gpu, &sensor, &frame, volume, &params.ogm).expect("gpu");
            assert!((0..volume.len()).all(|v| want.get(v) == got.get(v)), "{name} frame {i}: observations differ");
        }
        let share = uncertain as f64 / voxels as f64;
        eprintln!("{name}: {uncertain} of {voxels} voxels uncertain ({:.4} %)", 100.0 * share);
        assert!(share < 0.01, "{name}: too many uncertain voxels");
    }
}
