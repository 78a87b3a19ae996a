//! Simulated frames against closed-form ranges in hand-made worlds.

use super::*;
use crate::geometry::{Ground, Sphere};
use crate::trajectory::{Heading, Path};
use edtmap_core::sensor::{Frame, Measurement, PinholeCamera, RangeLimits, SpinningLidar};

/// A scene of `statics` seen from a sensor standing still at `at`, facing +x.
fn still(statics: Vec<Primitive>, at: [f64; 3], sensor: Sensor, options: SceneOptions) -> Scene {
    let trajectory = Route {
        path: Path::new([at[0], at[1]], 0.0),
        speed_mps: 0.0,
        start_s: 0.0,
        height_m: at[2],
        bob_m: 0.0,
        bob_cycles: 0.0,
        heading: Heading::AlongPath,
    };
    Scene::from_layout(
        SceneName::Room,
        options,
        Layout { statics, walkers: Vec::new(), trajectory, sensor, frame_period_s: 0.1, default_frames: 1 },
    )
}

fn camera() -> PinholeCamera {
    PinholeCamera {
        fx: 277.0,
        fy: 277.0,
        cx: 159.5,
        cy: 119.5,
        width: 320,
        height: 240,
        range: RangeLimits { min_m: 0.3, max_m: 5.0 },
    }
}

fn lidar() -> SpinningLidar {
    SpinningLidar::uniform(16, -15f64.to_radians(), 15f64.to_radians(), 360, RangeLimits { min_m: 0.2, max_m: 20.0 })
}

fn depths(f: &Frame) -> Vec<f32> {
    match &f.measurement {
        Measurement::Depth(img) => (0..(img.width * img.height) as usize).map(|i| img.depth_m(i)).collect(),
        m => panic!("not a depth image: {}", m.kind()),
    }
}

#[test]
fn a_camera_facing_a_wall_sees_its_distance_in_every_pixel() {
    let wall = Aabb::new([4.0, -50.0, -50.0], [4.5, 50.0, 50.0]).into();
    let sensor = Sensor::Depth(camera());
    let scene = still(vec![wall], [0.0, 0.0, 1.0], sensor.clone(), SceneOptions::default());
    let frame = scene.frame(&sensor, 3).expect("valid sensor");
    sensor.check(&frame).expect("a valid depth frame");
    assert!((frame.stamp_s - 0.3).abs() < 1e-12);
    assert!(depths(&frame).iter().all(|&d| (d - 4.0).abs() < 1e-5), "depth is optical z");
    // The same wall beyond the camera's range gives no returns.
    let far = Aabb::new([5.5, -50.0, -50.0], [6.0, 50.0, 50.0]).into();
    let scene = still(vec![far], [0.0, 0.0, 1.0], sensor.clone(), SceneOptions::default());
    assert!(depths(&scene.frame(&sensor, 0).expect("valid")).iter().all(|d| d.is_nan()));
}

#[test]
fn the_optical_frame_looks_along_body_x() {
    let sensor = Sensor::Depth(camera());
    let scene = still(Vec::new(), [1.0, 2.0, 3.0], sensor.clone(), SceneOptions::default());
    let pose = scene.sensor_pose(&sensor, 0.0);
    let z = pose.rotation * nalgebra::Vector3::z();
    let x = pose.rotation * nalgebra::Vector3::x();
    let y = pose.rotation * nalgebra::Vector3::y();
    assert!((z - nalgebra::Vector3::x()).norm() < 1e-12, "forward {z:?}");
    assert!((x + nalgebra::Vector3::y()).norm() < 1e-12, "right {x:?}");
    assert!((y + nalgebra::Vector3::z()).norm() < 1e-12, "down {y:?}");
    assert_eq!(scene.sensor_pose(&Sensor::Planar, 0.0), scene.body_pose(0.0));
}

#[test]
fn a_lidar_over_flat_ground_sees_h_over_sin_el() {
    let h = 1.5;
    let l = lidar();
    let sensor = Sensor::Lidar(l.clone());
    let scene = still(vec![Ground { height_m: 0.0 }.into()], [0.3, -0.2, h], sensor.clone(), SceneOptions::default());
    let frame = scene.frame(&sensor, 0).expect("valid");
    sensor.check(&frame).expect("a valid scan");
    let Measurement::Lidar(scan) = &frame.measurement else { panic!("not a range image") };
    for (r, &el) in l.ring_elevations_rad.iter().enumerate() {
        let want = h / (-el).sin();
        for b in 0..l.azimuth_bins {
            let got = scan.ranges[r * l.azimuth_bins + b];
            if el < 0.0 && want <= 20.0 {
                assert!((got as f64 - want).abs() < 1e-5, "ring {r}: {got} vs {want}");
            } else {
                assert!(got.is_nan(), "ring {r} at {el} rad has no return, got {got}");
            }
        }
    }
}

#[test]
fn points_and_planar_scans_measure_the_same_geometry() {
    let h = 1.2;
    let sensor = Sensor::Points(RangeLimits { min_m: 0.2, max_m: 20.0 });
    let scene = still(vec![Ground { height_m: 0.0 }.into()], [0.0, 0.0, h], sensor.clone(), SceneOptions::default());
    let frame = scene.frame(&sensor, 0).expect("valid");
    sensor.check(&frame).expect("a valid cloud");
    let Measurement::Points(pc) = &frame.measurement else { panic!("not a cloud") };
    let pattern = points_pattern(RangeLimits { min_m: 0.2, max_m: 20.0 });
    let reaching = pattern.ring_elevations_rad.iter().filter(|&&el| el < 0.0 && h / (-el).sin() <= 20.0).count();
    assert!(reaching > 10);
    assert_eq!(pc.points.len(), reaching * 900);
    assert!(pc.points.iter().all(|p| (p[2] as f64 + h).abs() < 1e-5));

    // A square room of half side 3 around a planar scanner.
    let walls = vec![
        Aabb::new([3.0, -4.0, 0.0], [3.2, 4.0, 2.0]).into(),
        Aabb::new([-3.2, -4.0, 0.0], [-3.0, 4.0, 2.0]).into(),
        Aabb::new([-4.0, 3.0, 0.0], [4.0, 3.2, 2.0]).into(),
        Aabb::new([-4.0, -3.2, 0.0], [4.0, -3.0, 2.0]).into(),
    ];
    let scene = still(walls, [0.0, 0.0, 1.0], Sensor::Planar, SceneOptions::default());
    let frame = scene.frame(&Sensor::Planar, 0).expect("valid");
    Sensor::Planar.check(&frame).expect("a valid scan");
    let Measurement::Scan(scan) = &frame.measurement else { panic!("not a scan") };
    assert_eq!(scan.ranges.len(), PLANAR_BEAMS);
    for (i, &r) in scan.ranges.iter().enumerate() {
        let a = scan.angle_min_rad + i as f64 * scan.angle_increment_rad;
        let want = 3.0 / a.cos().abs().max(a.sin().abs());
        assert!((r as f64 - want).abs() < 1e-5, "beam {i}: {r} vs {want}");
    }
}

#[test]
fn noise_is_seeded_and_dropout_gives_no_return() {
    // From the centre of a ball of radius 10 every beam measures its exit.
    let ball = Sphere { centre: [0.0; 3], radius_m: 10.0 };
    let sensor = Sensor::Lidar(lidar());
    let noisy = |seed, dropout| SceneOptions { seed, range_noise_m: 0.01, dropout };
    let ranges = |o: SceneOptions, index: usize| {
        let scene = still(vec![ball.into()], [0.0; 3], sensor.clone(), o);
        match scene.frame(&sensor, index).expect("valid").measurement {
            Measurement::Lidar(s) => s.ranges.iter().map(|r| r.to_bits()).collect::<Vec<u32>>(),
            m => panic!("not a range image: {}", m.kind()),
        }
    };
    let a = ranges(noisy(1, 0.25), 0);
    assert_eq!(a, ranges(noisy(1, 0.25), 0));
    assert_ne!(a, ranges(noisy(2, 0.25), 0));
    assert_ne!(a, ranges(noisy(1, 0.25), 1));
    let values: Vec<f32> = a.iter().map(|&b| f32::from_bits(b)).collect();
    let lost = values.iter().filter(|r| r.is_nan()).count() as f64 / values.len() as f64;
    assert!((lost - 0.25).abs() < 0.02, "lost {lost}");
    let kept: Vec<f64> = values.iter().filter(|r| r.is_finite()).map(|&r| r as f64).collect();
    let mean = kept.iter().sum::<f64>() / kept.len() as f64;
    let sd = (kept.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / kept.len() as f64).sqrt();
    assert!((mean - 10.0).abs() < 0.002 && (sd - 0.01).abs() < 0.001, "mean {mean}, sd {sd}");
}

#[test]
fn unusable_sensors_are_refused() {
    let scene = still(Vec::new(), [0.0; 3], Sensor::Planar, SceneOptions::default());
    let mut huge = camera();
    (huge.width, huge.height) = (1 << 16, 1 << 16);
    let err = scene.frame(&Sensor::Depth(huge), 0).expect_err("a 65536² camera");
    assert!(err.to_string().contains("pixels"), "{err}");
    let dense = SpinningLidar::uniform(4096, -0.5, 0.5, 1 << 20, RangeLimits { min_m: 0.2, max_m: 20.0 });
    assert!(matches!(scene.frame(&Sensor::Lidar(dense), 0), Err(SimError::TooManyRays { .. })));
    let mut bad = camera();
    bad.fx = -1.0;
    assert!(scene.frame(&Sensor::Depth(bad), 0).expect_err("negative focal length").to_string().contains("fx"));
}
