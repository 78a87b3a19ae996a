//! Bad frames are refused with a clear error and leave the map as it was.

use edtmap::sensor::{
    DepthData, DepthImage, Frame, LaserScan, Measurement, PinholeCamera, PointCloud, RangeLimits, Sensor,
};
use edtmap::{Mapper, MapperParams, VoxelState};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

fn camera() -> PinholeCamera {
    PinholeCamera {
        fx: 40.0,
        fy: 40.0,
        cx: 15.5,
        cy: 11.5,
        width: 32,
        height: 24,
        range: RangeLimits { min_m: 0.1, max_m: 5.0 },
    }
}

/// A camera 2 m in front of a wall: every pixel sees depth 2 m.
fn wall_frame(width: u32, height: u32) -> Frame {
    // Optical z along world x.
    let rot = UnitQuaternion::from_euler_angles(-std::f64::consts::FRAC_PI_2, 0.0, -std::f64::consts::FRAC_PI_2);
    let image = DepthImage { width, height, data: DepthData::Metres(vec![2.0; (width * height) as usize]) };
    Frame {
        stamp_s: 0.0,
        t_world_sensor: Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.0), rot),
        measurement: Measurement::Depth(image),
    }
}

fn digest(m: &Mapper) -> Vec<(edtmap::BlockKey, Vec<u32>)> {
    let mut d: Vec<_> =
        m.map().occupancy().iter().map(|(k, b)| (k, b.log_odds.iter().map(|v| v.to_bits()).collect())).collect();
    d.sort_by_key(|(k, _)| *k);
    d
}

fn mapped() -> Mapper {
    let mut params = MapperParams::for_voxel_size(0.1);
    params.volume.size_m = [6.0, 6.0, 3.0];
    let mut m = Mapper::new(Sensor::Depth(camera()), params).expect("valid mapper");
    m.integrate_frame(&wall_frame(32, 24)).expect("valid frame");
    m
}

#[test]
fn a_valid_frame_maps_the_wall() {
    let m = mapped();
    // The wall at x = 2 m is occupied, the space before it free.
    assert_eq!(m.state(edtmap::VoxelIndex([20, 0, 10])), VoxelState::Occupied);
    assert_eq!(m.state(edtmap::VoxelIndex([10, 0, 10])), VoxelState::Free);
}

fn refused(frame: &Frame, expect: &str) {
    let mut m = mapped();
    let before = digest(&m);
    let err = m.integrate_frame(frame).expect_err("bad frame").to_string();
    assert!(err.contains(expect), "error {err:?} does not mention {expect:?}");
    assert!(digest(&m) == before, "the map changed after a refused frame");
}

#[test]
fn nan_pose_is_refused() {
    let mut f = wall_frame(32, 24);
    f.t_world_sensor.translation.vector = Vector3::new(f64::NAN, 0.0, 1.0);
    refused(&f, "not finite");
}

#[test]
fn non_unit_rotation_is_refused() {
    let mut f = wall_frame(32, 24);
    f.t_world_sensor.rotation = UnitQuaternion::new_unchecked(Quaternion::new(1.0, 0.5, 0.0, 0.0));
    refused(&f, "norm");
}

#[test]
fn image_size_must_match_intrinsics() {
    refused(&wall_frame(30, 24), "30x24");
}

#[test]
fn wrong_measurement_kind_is_refused() {
    let mut f = wall_frame(32, 24);
    f.measurement = Measurement::Scan(LaserScan {
        angle_min_rad: 0.0,
        angle_increment_rad: 0.01,
        ranges: vec![1.0],
        range: RangeLimits { min_m: 0.1, max_m: 5.0 },
    });
    refused(&f, "laser scan");
}

#[test]
fn empty_scans_are_refused() {
    let params = MapperParams::for_voxel_size(0.1);
    let mut m = Mapper::new(Sensor::Points(RangeLimits { min_m: 0.0, max_m: 10.0 }), params.clone()).expect("mapper");
    let f = Frame {
        stamp_s: 0.0,
        t_world_sensor: Isometry3::identity(),
        measurement: Measurement::Points(PointCloud::default()),
    };
    assert!(m.integrate_frame(&f).expect_err("empty").to_string().contains("empty"));
    let mut m = Mapper::new(Sensor::Planar, params).expect("mapper");
    let scan = LaserScan {
        angle_min_rad: 0.0,
        angle_increment_rad: 0.01,
        ranges: vec![],
        range: RangeLimits { min_m: 0.1, max_m: 5.0 },
    };
    let f = Frame { stamp_s: 0.0, t_world_sensor: Isometry3::identity(), measurement: Measurement::Scan(scan) };
    assert!(m.integrate_frame(&f).expect_err("empty").to_string().contains("no ranges"));
    assert!(m.map().occupancy().is_empty() && m.map().edt().is_empty());
}

#[test]
fn bad_parameters_are_refused() {
    let err = Mapper::new(Sensor::Depth(camera()), MapperParams::for_voxel_size(-0.1)).expect_err("negative voxel");
    assert!(err.to_string().contains("voxel_size_m"), "{err}");
    let mut bad = camera();
    bad.fx = 0.0;
    let err = Mapper::new(Sensor::Depth(bad), MapperParams::for_voxel_size(0.1)).expect_err("fx");
    assert!(err.to_string().contains("fx"), "{err}");
}
