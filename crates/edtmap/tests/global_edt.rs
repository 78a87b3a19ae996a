//! The global EDT through the whole pipeline: scenes with moving obstacles
//! against the exact EDT of the mapper's own map, save and load, forbidden
//! zones and prior maps.

use edtmap::config::Config;
use edtmap::eval::{edt_errors, edt_extent};
use edtmap::sensor::Sensor;
use edtmap::{
    load_map, save_map, Connectivity, ForbiddenZone, GlobalMap, IntegrationMode, Mapper, MapperParams, PointState,
};
use edtmap_sim::{Scene, SceneName, SceneOptions};
use std::path::PathBuf;

fn setup(scene: &str) -> (Scene, Sensor, MapperParams) {
    setup_with(scene, |_| {})
}

/// As [`setup`], with the shipped config edited first.
fn setup_with(scene: &str, edit: impl Fn(&mut Config)) -> (Scene, Sensor, MapperParams) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../../configs/{scene}.toml"));
    let mut config = Config::load(&path).expect("shipped config");
    edit(&mut config);
    let (sensor, params) = config.mapper_params().expect("valid config");
    let scene = Scene::new(scene.parse::<SceneName>().expect("name"), &SceneOptions::default()).expect("scene");
    (scene, sensor, params)
}

/// Runs `frames` frames (every `step`-th) and returns the mapper and the
/// worst global RMS and max error seen after any frame.
fn run(scene_name: &str, frames: usize, step: usize, edit: impl Fn(&mut MapperParams)) -> (Mapper, f64, f64) {
    run_on(setup(scene_name), frames, step, edit)
}

/// As [`run`], on a scene already set up.
fn run_on(
    (scene, sensor, mut params): (Scene, Sensor, MapperParams),
    frames: usize,
    step: usize,
    edit: impl Fn(&mut MapperParams),
) -> (Mapper, f64, f64) {
    edit(&mut params);
    let mut mapper = Mapper::new(sensor.clone(), params).expect("mapper");
    let (mut rms, mut max) = (0.0f64, 0.0f64);
    for i in 0..frames {
        mapper.integrate_frame(&scene.frame(&sensor, i * step).expect("frame")).expect("integrate");
        let region = edt_extent(mapper.map()).expect("some EDT");
        let e = edt_errors(mapper.map(), &region).expect("errors");
        (rms, max) = (rms.max(e.rms_m), max.max(e.max_m));
    }
    (mapper, rms, max)
}

#[test]
fn pedestrians_leave_no_error_in_exact_mode() {
    // Walking pedestrians appear and vanish inside and outside the window.
    let (_, rms, max) = run("ugv_corridor", 12, 4, |p| p.global.mode = IntegrationMode::Exact);
    assert_eq!((rms, max), (0.0, 0.0));
}

#[test]
fn exact_at_a_long_reach() {
    // At 0.05 m the cutoff is 40 voxels: a column's outputs whose nearest
    // entry rose are rescanned in runs joined up to twice that apart,
    // across blocks that nothing else in the frame touches (the fourth
    // frame of `uav_pillars` at 0.05 m once wrote past the blocks taken).
    let fine = setup_with("uav_pillars", |c| c.occupancy.voxel_size_m = 0.05);
    let (_, rms, max) = run_on(fine, 5, 1, |p| p.global.mode = IntegrationMode::Exact);
    assert_eq!((rms, max), (0.0, 0.0));
}

#[test]
fn wavefront_error_stays_below_the_papers() {
    // GIE-mapping reports a global RMS near 0.02 m at 0.1 m voxels; with 26
    // neighbours ours is at most a fraction of that.
    let (mapper, rms, max) = run("ugv_corridor", 12, 4, |p| p.global.connectivity = Connectivity::TwentySix);
    let vs = mapper.params().voxel_size_m;
    assert!(rms <= 0.002 && max <= 0.25 * vs, "global RMS {rms} m, max {max} m");
    let (_, rms6, max6) = run("uav_pillars", 10, 6, |p| p.global.connectivity = Connectivity::Six);
    assert!(rms6 <= 0.01 && max6 <= 0.5 * 0.2, "6-connectivity: RMS {rms6} m, max {max6} m");
}

#[test]
fn save_and_load_round_trip_bit_identical() {
    let (mapper, _, _) = run("room", 4, 10, |_| {});
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("room.edtmap");
    save_map(mapper.map(), &path).expect("save");
    let loaded = load_map(&path).expect("load");
    let blocks = |m: &GlobalMap| {
        let mut occ: Vec<_> =
            m.occupancy().iter().map(|(k, b)| (k, b.log_odds.iter().map(f32::to_bits).collect::<Vec<_>>())).collect();
        let mut edt: Vec<_> = m.edt().iter().map(|(k, b)| (k, b.to_nearest.iter().collect::<Vec<_>>())).collect();
        occ.sort_by_key(|b| b.0);
        edt.sort_by_key(|b| b.0);
        (occ, edt)
    };
    assert!(blocks(mapper.map()) == blocks(&loaded));
    assert_eq!(
        (loaded.params().clone(), loaded.occupancy_params().clone()),
        (mapper.map().params().clone(), mapper.map().occupancy_params().clone())
    );
    // A loaded map goes on mapping.
    let (scene, sensor, params) = setup("room");
    let mut again = Mapper::with_map(sensor.clone(), params, loaded).expect("mapper");
    again.integrate_frame(&scene.frame(&sensor, 45).expect("frame")).expect("integrate");
    // Corruption is refused with the file's name.
    let mut bytes = std::fs::read(&path).expect("read");
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x10;
    std::fs::write(&path, &bytes).expect("write");
    let err = load_map(&path).expect_err("corrupt").to_string();
    assert!(err.contains("room.edtmap") && err.contains("checksum"), "{err}");
}

#[test]
fn a_loaded_maps_voxel_size_sets_the_derived_lengths() {
    // The free margin and the planar half thickness default to fractions of
    // a voxel: a mapper going on from a map follows the map's voxel size,
    // whatever voxel size the configuration it was given said.
    let (scene, sensor, params) = setup("room");
    let vs = params.voxel_size_m;
    let mut first = Mapper::new(sensor.clone(), params.clone()).expect("mapper");
    first.integrate_frame(&scene.frame(&sensor, 0).expect("frame")).expect("integrate");
    let (_, _, other) = setup_with("room", |c| c.occupancy.voxel_size_m = 4.0 * vs);
    let go_on = |params: MapperParams| {
        let mut m = Mapper::with_map(sensor.clone(), params, first.map().clone()).expect("mapper");
        m.integrate_frame(&scene.frame(&sensor, 20).expect("frame")).expect("integrate");
        let mut occ: Vec<_> = m
            .map()
            .occupancy()
            .iter()
            .map(|(k, b)| (k, b.log_odds.iter().map(f32::to_bits).collect::<Vec<_>>()))
            .collect();
        occ.sort_by_key(|b| b.0);
        occ
    };
    assert!(go_on(other) == go_on(params), "the map's voxel size, not the configuration's, sets the free margin");
}

#[test]
fn forbidden_zones_and_prior_maps_are_obstacles() {
    // A forbidden box far from where any sensor looks: in the EDT at once.
    let zone = ForbiddenZone { min_m: [101.0, 0.4, 0.0], max_m: [101.4, 0.8, 1.0] };
    let (scene, sensor, mut params) = setup("ugv_corridor");
    params.global.forbidden = vec![zone];
    let vs = params.voxel_size_m;
    let mut mapper = Mapper::new(sensor.clone(), params).expect("mapper");
    let inside = mapper.distance([101.2, 0.6, 0.5]);
    assert_eq!((inside.distance_m, inside.state), (0.0, PointState::Occupied));
    // A voxel centre 0.5 m in front of the zone's face voxel centres.
    let face = 101.0 + 0.5 * vs;
    let near = mapper.distance([face - 0.5, 0.6 + 0.5 * vs, 0.5 + 0.5 * vs]);
    assert!((near.distance_m - 0.5).abs() < 1e-6, "{near:?}");
    mapper.integrate_frame(&scene.frame(&sensor, 0).expect("frame")).expect("integrate");
    assert_eq!(mapper.distance([101.2, 0.6, 0.5]).distance_m, 0.0, "frames elsewhere keep it");
    // The room's occupied voxels as a prior of an empty map.
    let (room, _, _) = run("room", 3, 10, |_| {});
    let (scene, sensor, params) = setup("room");
    let mut fresh = Mapper::new(sensor.clone(), params).expect("mapper");
    let added = fresh.add_prior(room.map()).expect("same voxel size");
    assert!(added > 100);
    fresh.integrate_frame(&scene.frame(&sensor, 0).expect("frame")).expect("integrate");
    let region = edt_extent(fresh.map()).expect("EDT");
    assert_eq!(edt_errors(fresh.map(), &region).expect("errors").max_m, 0.0);
}

/// A planar map with a forbidden zone several layers tall and a prior map:
/// both laid down a layer at a time, every stored distance that of its own
/// layer's obstacles by brute force, none across layers.
#[test]
fn a_planar_maps_zones_and_priors_are_laid_down_layer_by_layer() {
    let zone = ForbiddenZone { min_m: [3.0, -1.0, 0.5], max_m: [3.3, 1.0, 1.5] };
    let (scene, sensor, mut params) = setup("planar");
    params.global.forbidden = vec![zone];
    params.global.planar = true;
    let mut mapper = Mapper::new(sensor.clone(), params).expect("mapper");
    let (planar_run, _, _) = run("planar", 4, 5, |_| {});
    mapper.add_prior(planar_run.map()).expect("same voxel size");
    mapper.integrate_frame(&scene.frame(&sensor, 7).expect("frame")).expect("integrate");
    let map = mapper.map();
    let obstacles: Vec<edtmap::VoxelIndex> = {
        let o = map.obstacles();
        let mut all = Vec::new();
        let keys: std::collections::BTreeSet<edtmap::BlockKey> =
            map.fixed_obstacles().iter().map(|(k, _)| k).chain(map.occupancy().iter().map(|(k, _)| k)).collect();
        for key in keys {
            for offset in 0..edtmap::BLOCK_VOXELS {
                let v = key.voxel(offset);
                if o.contains(v) {
                    all.push(v);
                }
            }
        }
        all.sort_unstable();
        all.dedup();
        all
    };
    let layers: std::collections::BTreeSet<i32> = obstacles.iter().map(|v| v.0[2]).collect();
    assert!(layers.len() >= 8, "the zone spans layers: {layers:?}");
    let max = map.cutoff().max_dist_sq;
    let mut checked = 0;
    for (key, block) in map.edt().iter() {
        for offset in 0..edtmap::BLOCK_VOXELS {
            let v = key.voxel(offset);
            let truth = obstacles
                .iter()
                .filter(|o| o.0[2] == v.0[2])
                .map(|o| ((o.0[0] - v.0[0]).pow(2) + (o.0[1] - v.0[1]).pow(2)) as u32)
                .min()
                .filter(|&d| d <= max)
                .unwrap_or(edtmap::FAR_DIST_SQ);
            assert_eq!(block.dist_sq(offset), truth, "{v:?}");
            checked += usize::from(truth != edtmap::FAR_DIST_SQ);
        }
    }
    assert!(checked > 10_000, "{checked} voxels within the cutoff");
    let region = edt_extent(map).expect("EDT");
    assert_eq!(edt_errors(map, &region).expect("errors").max_m, 0.0);
}
