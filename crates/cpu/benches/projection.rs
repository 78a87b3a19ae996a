//! Criterion benchmarks of volumetric projection's misses (`mark_misses`).
//!
//! `cargo bench -p edtmap-cpu --bench projection`: one frame of each
//! built-in scene with the window its config gives, projected with
//! `mark_misses` (tiles culled, a LiDAR's tests reordered) and with the
//! definition on every voxel, as projection ran before the per-geometry fast paths.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use edtmap_core::construction::{project_job, OgmOptions};
use edtmap_core::{mark_misses, LocalVolume, Observations, ProjectJob, VolumeParams, OBS_MISS};
use edtmap_sim::{Scene, SceneName, SceneOptions};
use rayon::prelude::*;
use std::time::Duration;

/// Each scene with its config's voxel size and window (configs/*.toml).
const SCENES: [(SceneName, f64, [f64; 3], Option<f64>); 5] = [
    (SceneName::Room, 0.05, [6.0, 6.0, 3.0], None),
    (SceneName::UavPillars, 0.2, [10.0, 10.0, 3.0], None),
    // The issue-15 setting `--voxel-size 0.05`: 200 × 200 × 60 voxels.
    (SceneName::UavPillars, 0.05, [10.0, 10.0, 3.0], None),
    (SceneName::UgvCorridor, 0.1, [10.0, 10.0, 2.4], Some(1.2)),
    (SceneName::Planar, 0.1, [12.0, 12.0, 0.1], None),
];

/// The definition on every voxel, row by row: projection before culling.
fn every_voxel(obs: &Observations, job: &ProjectJob<'_>) {
    let geom = job.voxel_to_sensor();
    let [nx, ny, nz] = job.volume.dims;
    (0..ny * nz).into_par_iter().with_min_len(8).for_each(|row| {
        let (y, z) = (row % ny, row / ny);
        let shared = geom.row(y, z);
        for x in 0..nx {
            if job.is_miss_at(geom.point_in_row(&shared, x)) {
                obs.mark([x, y, z], x + nx * row, OBS_MISS);
            }
        }
    });
}

fn scenes(c: &mut Criterion) {
    for (name, voxel_size_m, size_m, fixed_height_m) in SCENES {
        let scene = Scene::new(name, &SceneOptions::default()).expect("built-in scene");
        let sensor = scene.default_sensor();
        let frame = scene.frame(&sensor, 40).expect("frame");
        let params = VolumeParams { size_m, fixed_height_m };
        let volume = LocalVolume::centred(&params, voxel_size_m, frame.t_world_sensor.translation.vector.into())
            .expect("volume");
        let job = project_job(&sensor, &frame, volume, &OgmOptions::default()).expect("projectable");
        let mut obs = Observations::new(volume);
        let mut g = c.benchmark_group(format!("project_{name:?}_{voxel_size_m}m"));
        g.sample_size(20).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
        g.throughput(Throughput::Elements(volume.len() as u64));
        for (label, f) in
            [("every_voxel", every_voxel as fn(&Observations, &ProjectJob<'_>)), ("mark_misses", mark_misses)]
        {
            g.bench_function(BenchmarkId::from_parameter(label), |b| {
                b.iter(|| {
                    obs.reset(volume);
                    f(&obs, &job)
                })
            });
        }
        g.finish();
    }
}

criterion_group!(benches, scenes);
criterion_main!(benches);
