//! The built-in scenes: safe trajectories, valid frames, seeded noise and
//! exact ground truth.

use edtmap_core::sensor::{Measurement, PinholeCamera, RangeLimits, Sensor, SpinningLidar};
use edtmap_core::{LocalVolume, VolumeParams};
use edtmap_sim::{Scene, SceneName, SceneOptions, SimError};
use nalgebra::Vector3;

fn scene(name: SceneName, seed: u64) -> Scene {
    Scene::new(name, &SceneOptions { seed, ..Default::default() }).expect("valid options")
}

fn sensor_position(scene: &Scene, t_s: f64) -> [f64; 3] {
    scene.sensor_pose(&scene.default_sensor(), t_s).translation.vector.into()
}

/// Every sensor model, for frames of any scene.
fn all_sensors() -> Vec<Sensor> {
    let range = RangeLimits { min_m: 0.2, max_m: 15.0 };
    vec![
        Sensor::Depth(PinholeCamera { fx: 100.0, fy: 100.0, cx: 63.5, cy: 47.5, width: 128, height: 96, range }),
        Sensor::Lidar(SpinningLidar::uniform(8, -0.3, 0.3, 180, range)),
        Sensor::Points(range),
        Sensor::Planar,
    ]
}

fn returns(m: &Measurement) -> (usize, usize) {
    let count = |v: &[f32]| v.iter().filter(|r| r.is_finite()).count();
    match m {
        Measurement::Depth(img) => {
            let n = (img.width * img.height) as usize;
            ((0..n).filter(|&i| img.depth_m(i).is_finite()).count(), n)
        }
        Measurement::Lidar(s) => (count(&s.ranges), s.ranges.len()),
        Measurement::Points(pc) => (pc.points.len(), 32 * 900),
        Measurement::Scan(s) => (count(&s.ranges), s.ranges.len()),
    }
}

#[test]
fn trajectories_keep_half_a_metre_from_every_solid() {
    for name in SceneName::ALL {
        for seed in [7, 1, 2024] {
            let s = scene(name, seed);
            // 650 frames (65 s) cover a whole lap of every scene.
            for i in 0..650.max(s.default_frames()) {
                let t = i as f64 * s.frame_period_s();
                let p = sensor_position(&s, t);
                let c = s.clearance_m(p, t);
                assert!(c >= 0.5, "{name} seed {seed}: frame {i} at {p:?} is {c} m from a solid");
            }
        }
    }
}

#[test]
fn frames_fit_every_sensor_model_and_see_structure() {
    for name in SceneName::ALL {
        let s = scene(name, 7);
        let index = s.default_frames() / 2;
        let own = s.default_sensor();
        let frame = s.frame(&own, index).expect("valid sensor");
        own.check(&frame).expect("a valid frame");
        let (hits, rays) = returns(&frame.measurement);
        assert!(hits * 10 >= rays * 3, "{name}: only {hits} of {rays} rays return");
        assert_eq!(frame.t_world_sensor, s.sensor_pose(&own, index as f64 * s.frame_period_s()));
        for sensor in all_sensors() {
            let frame = s.frame(&sensor, index).expect("valid sensor");
            sensor.check(&frame).expect("a valid frame");
        }
    }
}

/// Culled, parallel frames against the plain nearest-hit search.
#[test]
fn frames_agree_with_ray_distance() {
    let lidar = SpinningLidar::uniform(24, -1.2, 1.2, 240, RangeLimits { min_m: 0.2, max_m: 20.0 });
    for name in SceneName::ALL {
        let s = scene(name, 7);
        let index = 17;
        let t = index as f64 * s.frame_period_s();
        let frame = s.frame(&Sensor::Lidar(lidar.clone()), index).expect("valid");
        let Measurement::Lidar(scan) = &frame.measurement else { panic!("a range image") };
        let origin: [f64; 3] = frame.t_world_sensor.translation.vector.into();
        let mut checked = 0;
        for (i, &range) in scan.ranges.iter().enumerate() {
            let (r, b) = (i / lidar.azimuth_bins, i % lidar.azimuth_bins);
            let dir: [f64; 3] = (frame.t_world_sensor.rotation * Vector3::from(lidar.direction(r, b))).into();
            match s.ray_distance(origin, dir, t, 20.0) {
                Some(d) if d >= 0.2 => {
                    assert!((range as f64 - d).abs() < 1e-5, "{name} beam {i}: {range} vs {d}");
                    checked += 1;
                }
                _ => assert!(range.is_nan(), "{name} beam {i}: {range} but no surface"),
            }
        }
        assert!(checked > scan.ranges.len() / 4, "{name}: {checked}");
    }
}

#[test]
fn noise_follows_the_seed() {
    let options = |seed| SceneOptions { seed, range_noise_m: 0.02, dropout: 0.1 };
    let bits = |seed| {
        let s = Scene::new(SceneName::Room, &options(seed)).expect("valid");
        match s.frame(&s.default_sensor(), 5).expect("valid").measurement {
            Measurement::Depth(img) => {
                (0..(img.width * img.height) as usize).map(|i| img.depth_m(i).to_bits()).collect::<Vec<u32>>()
            }
            m => panic!("not a depth image: {}", m.kind()),
        }
    };
    assert_eq!(bits(3), bits(3));
    assert_ne!(bits(3), bits(4));
}

#[test]
fn bad_options_are_refused_by_name() {
    let e = Scene::new(SceneName::Planar, &SceneOptions { range_noise_m: -1.0, ..Default::default() })
        .expect_err("negative noise");
    assert!(matches!(&e, SimError::InvalidOption { field: "range_noise_m", .. }), "{e}");
    let e = Scene::new(SceneName::Planar, &SceneOptions { dropout: 2.0, ..Default::default() })
        .expect_err("dropout over 1");
    assert!(e.to_string().contains("dropout"), "{e}");
}

/// Ground truth by testing every voxel against every solid.
fn brute_force(s: &Scene, v: &LocalVolume, t: f64) -> Vec<bool> {
    let solids = s.solids_at(t);
    let mut out = vec![false; v.len()];
    for z in 0..v.dims[2] {
        for y in 0..v.dims[1] {
            for x in 0..v.dims[0] {
                let w = v.world([x, y, z]).0;
                let lo = w.map(|i| i as f64 * v.voxel_size_m);
                let hi = w.map(|i| (i + 1) as f64 * v.voxel_size_m);
                out[v.linear([x, y, z])] = solids.iter().any(|p| p.intersects_box(lo, hi));
            }
        }
    }
    out
}

#[test]
fn ground_truth_matches_brute_force() {
    for name in SceneName::ALL {
        let s = scene(name, 7);
        for (frame, voxel) in [(0, 0.1), (s.default_frames() / 2, 0.05)] {
            let t = frame as f64 * s.frame_period_s();
            let params = VolumeParams { size_m: [4.0, 4.0, 2.4], fixed_height_m: None };
            let v = LocalVolume::centred(&params, voxel, sensor_position(&s, t)).expect("valid volume");
            let mut truth = Vec::new();
            s.ground_truth(&v, t, &mut truth);
            let want = brute_force(&s, &v, t);
            assert_eq!(truth, want, "{name} frame {frame}");
            let solid = truth.iter().filter(|&&o| o).count();
            assert!(solid > 0 && solid < truth.len() / 2, "{name}: {solid} of {} voxels", truth.len());
        }
    }
}

#[test]
fn pedestrians_walk_and_walls_stay() {
    let s = scene(SceneName::UgvCorridor, 7);
    let params = VolumeParams { size_m: [24.0, 16.0, 2.0], fixed_height_m: Some(1.0) };
    let b = s.bounds();
    let centre = [0, 1, 2].map(|a| 0.5 * (b.min[a] + b.max[a]));
    let v = LocalVolume::centred(&params, 0.2, centre).expect("valid volume");
    let (mut a, mut later) = (Vec::new(), Vec::new());
    s.ground_truth(&v, 0.0, &mut a);
    s.ground_truth(&v, 2.0, &mut later);
    let moved = a.iter().zip(&later).filter(|(x, y)| x != y).count();
    assert!(moved > 20, "only {moved} voxels changed");
    let still = scene(SceneName::UavPillars, 7);
    still.ground_truth(&v, 0.0, &mut a);
    still.ground_truth(&v, 2.0, &mut later);
    assert_eq!(a, later);
}

#[test]
fn layouts_follow_the_seed() {
    for name in SceneName::ALL {
        let (a, b, c) = (scene(name, 7), scene(name, 7), scene(name, 8));
        assert_eq!(a.solids_at(1.0), b.solids_at(1.0), "{name}");
        assert_ne!(a.solids_at(1.0), c.solids_at(1.0), "{name}");
    }
}

#[test]
fn bounds_hold_the_static_world() {
    for name in SceneName::ALL {
        let s = scene(name, 7);
        let b = s.bounds();
        assert!(b.min.iter().chain(&b.max).all(|v| v.is_finite()), "{name}: {b:?}");
        let p = sensor_position(&s, 0.0);
        assert_eq!(b.distance(p), 0.0, "{name}: the sensor starts inside the world");
    }
}

/// Guards [`edtmap_sim::WORLD_SHIFT_M`]: no flat face lies on a voxel
/// boundary of a common voxel size, so ground truth never hinges on rounding.
#[test]
fn flat_faces_avoid_common_voxel_boundaries() {
    use edtmap_sim::geometry::Primitive;
    for (name, seed) in SceneName::ALL.into_iter().flat_map(|n| [(n, 7), (n, 8), (n, 9)]) {
        for solid in scene(name, seed).solids_at(0.0) {
            let faces: Vec<f64> = match solid {
                Primitive::Box(b) => b.min.iter().chain(&b.max).copied().collect(),
                Primitive::Cylinder(c) => vec![c.z_min, c.z_max],
                Primitive::Ground(g) => vec![g.height_m],
                _ => Vec::new(),
            };
            for f in faces {
                for voxel in [0.01, 0.02, 0.025, 0.05, 0.1, 0.2] {
                    let off = (f / voxel - (f / voxel).round()).abs() * voxel;
                    assert!(off > 1e-4, "{name}: face at {f} m is on the {voxel} m grid ({solid:?})");
                }
            }
        }
    }
}
