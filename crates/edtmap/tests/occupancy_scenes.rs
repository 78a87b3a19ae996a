//! Occupancy on the built-in scenes against their exact ground truth:
//! both constructions, their agreement, and dynamic obstacles.

use edtmap::config::Config;
use edtmap::eval::{agreement, OccupancyScores};
use edtmap::sensor::Sensor;
use edtmap::stages::Construction;
use edtmap::{Mapper, MapperParams, VoxelIndex, VoxelState};
use edtmap_sim::{Scene, SceneName, SceneOptions};
use std::collections::HashMap;
use std::path::PathBuf;

fn setup(scene: &str) -> (Scene, Sensor, MapperParams) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../../configs/{scene}.toml"));
    let config = Config::load(&path).expect("shipped config");
    let (sensor, params) = config.mapper_params().expect("valid config");
    let name: SceneName = scene.parse().expect("scene name");
    let scene = Scene::new(name, &SceneOptions::default()).expect("scene");
    (scene, sensor, params)
}

fn mapper(sensor: &Sensor, params: &MapperParams, construction: Construction) -> Mapper {
    let mut p = params.clone();
    p.ogm.construction = construction;
    Mapper::new(sensor.clone(), p).expect("mapper")
}

/// Runs both constructions over `frames` frames; returns the summed scores
/// of each and the agreement of their local volumes over all frames.
fn run_both(scene_name: &str, frames: usize) -> (OccupancyScores, OccupancyScores, f64) {
    let (scene, sensor, params) = setup(scene_name);
    let mut cast = mapper(&sensor, &params, Construction::RayCasting);
    let mut proj = mapper(&sensor, &params, Construction::Projection);
    let (mut sc, mut sp) = (OccupancyScores::default(), OccupancyScores::default());
    let (mut same, mut both) = (0.0, 0usize);
    let (mut truth, mut seen) = (Vec::new(), Vec::new());
    let step = (scene.default_frames() / frames).max(1);
    for i in (0..frames).map(|k| k * step) {
        let frame = scene.frame(&sensor, i).expect("frame");
        cast.integrate_frame(&frame).expect("ray casting");
        proj.integrate_frame(&frame).expect("projection");
        let volume = *cast.local_volume().expect("volume");
        scene.ground_truth(&volume, frame.stamp_s, &mut truth);
        scene.seen_surface(&sensor, &frame, &volume, &mut seen);
        sc.add(&OccupancyScores::compare(cast.local_states().as_slice(), &truth, &seen));
        sp.add(&OccupancyScores::compare(proj.local_states().as_slice(), &truth, &seen));
        let (a, n) = agreement(cast.local_states().as_slice(), proj.local_states().as_slice());
        same += a * n as f64;
        both += n;
    }
    (sc, sp, same / both.max(1) as f64)
}

fn check_scene(scene: &str, frames: usize) {
    let (cast, proj, agree) = run_both(scene, frames);
    for (name, s) in [("ray casting", cast), ("projection", proj)] {
        let (p, r) = (s.precision().expect("occupied voxels"), s.recall().expect("occupied truth"));
        let rs = s.strict_recall().expect("observed solids");
        println!(
            "{scene} {name}: precision {p:.3}, recall {r:.3} (strict {rs:.3}) over {} observed voxels",
            s.observed
        );
        assert!(p >= 0.95 && r >= 0.95, "{scene} {name}: precision {p:.3}, recall {r:.3}");
    }
    println!("{scene}: the constructions agree on {:.3} of the voxels both observe", agree);
    assert!(agree >= 0.95, "{scene}: agreement {agree:.3}");
}

#[test]
fn uav_pillars_occupancy_matches_ground_truth() {
    check_scene("uav_pillars", 12);
}

#[test]
fn ugv_corridor_occupancy_matches_ground_truth() {
    check_scene("ugv_corridor", 12);
}

#[test]
fn room_occupancy_matches_ground_truth() {
    check_scene("room", 8);
}

#[test]
fn planar_occupancy_matches_ground_truth() {
    check_scene("planar", 12);
}

/// Whether the measurement passes through voxel `v`'s centre to a return
/// beyond it.
fn seen_through(sensor: &Sensor, frame: &edtmap::sensor::Frame, v: VoxelIndex, voxel_size_m: f64) -> bool {
    let c = v.centre(voxel_size_m);
    let p = frame.t_world_sensor.inverse_transform_point(&nalgebra::Point3::new(c[0], c[1], c[2]));
    match sensor.project(&frame.measurement, [p.x as f32, p.y as f32, p.z as f32]) {
        edtmap::sensor::Projection::Return { point_m, measured_m } => point_m < measured_m - voxel_size_m as f32,
        _ => false,
    }
}

/// Voxels a pedestrian occupied and then left must become free again within
/// a few frames once the sensor sees through them (OctoMap's clamping bounds
/// how many misses that takes).
#[test]
fn ugv_corridor_pedestrians_leave_free_space() {
    let (scene, sensor, params) = setup("ugv_corridor");
    let mut m = mapper(&sensor, &params, Construction::Auto);
    // World voxel -> number of consecutive frames it has been free in truth
    // after having been occupied in truth (by a pedestrian) and in the map.
    let mut vacated: HashMap<VoxelIndex, usize> = HashMap::new();
    let mut truth = Vec::new();
    const FEW: usize = 10;
    let (mut checked, mut stale) = (0usize, 0usize);
    for i in 0..scene.default_frames().min(120) {
        let frame = scene.frame(&sensor, i).expect("frame");
        m.integrate_frame(&frame).expect("frame");
        let volume = *m.local_volume().expect("volume");
        scene.ground_truth(&volume, frame.stamp_s, &mut truth);
        let states = m.local_states().as_slice();
        let mut next = HashMap::new();
        for (lin, (&occupied, &state)) in truth.iter().zip(states).enumerate() {
            let [nx, ny, _] = volume.dims;
            let v = volume.world([lin % nx, (lin / nx) % ny, lin / (nx * ny)]);
            if occupied {
                if state == VoxelState::Occupied {
                    next.insert(v, 0);
                }
            } else if let Some(&k) = vacated.get(&v) {
                // Count only frames whose measurement shows free space through the voxel.
                let seen = usize::from(seen_through(&sensor, &frame, v, volume.voxel_size_m));
                if k + seen >= FEW {
                    checked += 1;
                    stale += usize::from(state == VoxelState::Occupied);
                } else {
                    next.insert(v, k + seen);
                }
            }
        }
        // Voxels that left the volume are forgotten.
        vacated = next;
    }
    println!("{checked} vacated voxels checked {FEW} frames after; {stale} still occupied");
    assert!(checked > 50, "the pedestrians should vacate voxels in view ({checked})");
    assert!(
        (stale as f64) <= 0.05 * checked as f64,
        "{stale} of {checked} vacated voxels still occupied after {FEW} frames"
    );
}

/// The fused map is bit-identical whatever the number of threads, for both
/// constructions (observations are `fetch_or`s, which commute).
#[test]
fn maps_do_not_depend_on_thread_count() {
    let (scene, sensor, params) = setup("ugv_corridor");
    let run = |threads: usize, construction: Construction| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
        pool.install(|| {
            let mut m = mapper(&sensor, &params, construction);
            for i in 0..6 {
                m.integrate_frame(&scene.frame(&sensor, i * 5).expect("frame")).expect("frame");
            }
            let mut blocks: Vec<_> = m
                .map()
                .occupancy()
                .iter()
                .map(|(k, b)| (k, b.log_odds.iter().map(f32::to_bits).collect::<Vec<_>>()))
                .collect();
            blocks.sort_by_key(|(k, _)| *k);
            let mut edt: Vec<_> =
                m.map().edt().iter().map(|(k, b)| (k, b.to_nearest.iter().collect::<Vec<_>>())).collect();
            edt.sort_by_key(|(k, _)| *k);
            (blocks, edt, m.local_edt().dist_sq_vox().to_vec())
        })
    };
    for construction in [Construction::RayCasting, Construction::Projection] {
        let one = run(1, construction);
        assert!(one == run(3, construction), "{construction:?}: 1 and 3 threads differ");
    }
}
