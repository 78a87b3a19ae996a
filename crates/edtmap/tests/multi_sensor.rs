//! Several sensors into one map: a ground robot's spinning LiDAR and a low
//! depth camera pitched at the floor in front of it.
//!
//! The oracle for fusing two sensors is the mapper with one sensor: the
//! same frames, interleaved in the same order, fed to a fresh single-sensor
//! mapper each that goes on from the map the previous one left
//! (`Mapper::with_map`, `Mapper::into_map`). A mapper with both sensors
//! must save the same bytes.

use edtmap::config::Config;
use edtmap::sensor::{PinholeCamera, RangeLimits, Sensor};
use edtmap::{save_map, GlobalMap, IntegrationMode, Mapper, MapperParams, MapperSensor, VoxelState};
use edtmap_sim::{Scene, SceneName, SceneOptions};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use std::path::PathBuf;

/// The frames each sensor takes: every tenth of the scene's first 70.
const FRAMES: [usize; 7] = [0, 10, 20, 30, 40, 50, 60];

fn lidar_and_params(mode: IntegrationMode) -> (Sensor, MapperParams) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs/ugv_corridor.toml");
    let (lidar, mut params) = Config::load(&path).expect("shipped config").mapper_params().expect("valid");
    params.global.mode = mode;
    (lidar, params)
}

/// A 160 × 120 depth camera 0.3 m below the LiDAR and 0.25 m ahead,
/// pitched 25° down: it sees the floor and low obstacles the LiDAR's
/// lowest ring (15° down from 0.6 m) passes over within 2.2 m.
fn camera() -> (Sensor, Isometry3<f64>) {
    let range = RangeLimits { min_m: 0.2, max_m: 5.0 };
    let camera = PinholeCamera { fx: 100.0, fy: 100.0, cx: 79.5, cy: 59.5, width: 160, height: 120, range };
    let pitch_down = UnitQuaternion::from_euler_angles(0.0, 25f64.to_radians(), 0.0);
    (Sensor::Depth(camera), Isometry3::from_parts(Translation3::new(0.25, 0.0, -0.3), pitch_down))
}

fn scene() -> Scene {
    Scene::new(SceneName::UgvCorridor, &SceneOptions::default()).expect("scene")
}

fn bytes(map: &GlobalMap) -> Vec<u8> {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("map.edtmap");
    save_map(map, &path).expect("save");
    std::fs::read(&path).expect("read back")
}

#[test]
fn two_sensors_fuse_as_single_sensor_mappers_sharing_the_map() {
    let scene = scene();
    let (cam, mount) = camera();
    for mode in [IntegrationMode::Exact, IntegrationMode::Wavefront] {
        let (lidar, params) = lidar_and_params(mode);
        let frames: Vec<_> = FRAMES
            .iter()
            .flat_map(|&i| {
                let l = scene.frame(&lidar, i).expect("LiDAR frame");
                let c = scene.mounted_frame(&cam, &mount, i).expect("camera frame");
                [(0, l), (1, c)]
            })
            .collect();

        let mut both = Mapper::new(lidar.clone(), params.clone()).expect("mapper");
        let cam_entry = MapperSensor { name: "front_camera".into(), sensor: cam.clone(), ogm: params.ogm };
        assert_eq!(both.add_sensor(cam_entry).expect("second sensor"), 1);
        both.rename_sensor(0, "lidar_top").expect("rename");
        for (s, f) in &frames {
            let stats = both.integrate_sensor_frame(*s, f).expect("frame");
            assert_eq!(stats.sensor, *s);
        }

        let mut map = None;
        for (s, f) in &frames {
            let sensor = if *s == 0 { lidar.clone() } else { cam.clone() };
            let mut one = match map.take() {
                None => Mapper::new(sensor, params.clone()),
                Some(m) => Mapper::with_map(sensor, params.clone(), m),
            }
            .expect("single-sensor mapper");
            one.integrate_frame(f).expect("frame");
            map = Some(one.into_map());
        }
        let oracle = map.expect("a map");
        assert!(bytes(both.map()) == bytes(&oracle), "{mode:?}: the two-sensor map differs from the shared map");
    }
}

/// Voxels known occupied in `map`, whichever sensor saw them.
fn occupied(mapper: &Mapper) -> std::collections::BTreeSet<[i32; 3]> {
    let mut out = std::collections::BTreeSet::new();
    for (key, _) in mapper.map().occupancy().iter() {
        for offset in 0..edtmap::BLOCK_VOXELS {
            let v = key.voxel(offset);
            if mapper.state(v) == VoxelState::Occupied {
                out.insert(v.0);
            }
        }
    }
    out
}

#[test]
fn the_combined_map_sees_what_neither_sensor_alone_sees() {
    let scene = scene();
    let (lidar, params) = lidar_and_params(IntegrationMode::Exact);
    let (cam, mount) = camera();
    let mut lidar_only = Mapper::new(lidar.clone(), params.clone()).expect("mapper");
    let mut camera_only = Mapper::new(cam.clone(), params.clone()).expect("mapper");
    let mut both = Mapper::new(lidar.clone(), params.clone()).expect("mapper");
    both.add_sensor(MapperSensor { name: "camera".into(), sensor: cam.clone(), ogm: params.ogm })
        .expect("second sensor");
    for &i in &FRAMES {
        let l = scene.frame(&lidar, i).expect("LiDAR frame");
        let c = scene.mounted_frame(&cam, &mount, i).expect("camera frame");
        lidar_only.integrate_frame(&l).expect("frame");
        camera_only.integrate_frame(&c).expect("frame");
        both.integrate_sensor_frame(0, &l).expect("frame");
        both.integrate_sensor_frame(1, &c).expect("frame");
    }
    let (l, c, b) = (occupied(&lidar_only), occupied(&camera_only), occupied(&both));
    let beyond_lidar = b.difference(&l).count();
    let beyond_camera = b.difference(&c).count();
    assert!(beyond_lidar > 100, "the camera adds {beyond_lidar} occupied voxels the LiDAR misses");
    assert!(beyond_camera > 100, "the LiDAR adds {beyond_camera} occupied voxels the camera misses");
    // The distance field follows: the combined map is nearer to an
    // obstacle wherever one sensor alone missed it.
    let probe = b.difference(&l).next().map(|v| v.map(|k| (k as f64 + 0.5) * params.voxel_size_m)).expect("a voxel");
    assert_eq!(both.distance(probe).distance_m, 0.0);
    assert!(lidar_only.distance(probe).distance_m > 0.0);
}

#[test]
fn sensors_are_named_once_and_frames_name_a_sensor_the_mapper_has() {
    let (lidar, params) = lidar_and_params(IntegrationMode::Exact);
    let (cam, _) = camera();
    let mut mapper = Mapper::new(lidar, params.clone()).expect("mapper");
    assert_eq!(mapper.sensors()[0].name, "lidar");
    let entry = MapperSensor { name: "lidar".into(), sensor: cam.clone(), ogm: params.ogm };
    let err = mapper.add_sensor(entry).expect_err("a second sensor named lidar").to_string();
    assert!(err.contains("name") && err.contains("\"lidar\""), "{err}");
    let err = mapper.add_sensor(MapperSensor { name: String::new(), sensor: cam, ogm: params.ogm });
    assert!(err.expect_err("an empty name").to_string().contains("1 to 64"));
    let frame = scene().frame(&mapper.sensor().clone(), 0).expect("frame");
    let err = mapper.integrate_sensor_frame(3, &frame).expect_err("no sensor 3").to_string();
    assert!(err.contains("sensor 3") && err.contains("1 sensor"), "{err}");
    assert_eq!(mapper.map().occupancy().len(), 0, "a refused frame leaves the map as it was");
}

#[test]
fn a_bad_frame_of_one_sensor_is_refused_and_the_others_go_on() {
    let scene = scene();
    let (lidar, params) = lidar_and_params(IntegrationMode::Exact);
    let (cam, mount) = camera();
    let mut mapper = Mapper::new(lidar.clone(), params.clone()).expect("mapper");
    mapper.add_sensor(MapperSensor { name: "camera".into(), sensor: cam.clone(), ogm: params.ogm }).expect("camera");
    mapper.integrate_sensor_frame(0, &scene.frame(&lidar, 0).expect("frame")).expect("LiDAR frame");
    let before = bytes(mapper.map());
    // A camera frame cut short (a corrupt message), and a LiDAR scan sent
    // as the camera's: both refused, naming the problem, the map as it was.
    let mut short = scene.mounted_frame(&cam, &mount, 1).expect("frame");
    if let edtmap::sensor::Measurement::Depth(image) = &mut short.measurement {
        image.height -= 1;
    }
    let err = mapper.integrate_sensor_frame(1, &short).expect_err("short image").to_string();
    assert!(err.contains("depth image is 160x119"), "{err}");
    let lidar_frame = scene.frame(&lidar, 1).expect("frame");
    let err = mapper.integrate_sensor_frame(1, &lidar_frame).expect_err("a LiDAR frame as the camera's").to_string();
    assert!(err.contains("spinning LiDAR") || err.contains("LiDAR range image"), "{err}");
    assert!(bytes(mapper.map()) == before, "a refused frame leaves the map as it was");
    // Both sensors go on.
    mapper.integrate_sensor_frame(0, &lidar_frame).expect("LiDAR frame");
    mapper.integrate_sensor_frame(1, &scene.mounted_frame(&cam, &mount, 1).expect("frame")).expect("camera frame");
}
