//! The real 3DMatch depth frames in `../shared/data/3dmatch-seq01`: the
//! folder reader, and a map whose occupied voxels lie on the back-projected
//! depth points. The frames are not redistributable, so they are not in the
//! repository: these tests run where `../shared/data` sits beside the
//! checkout and are skipped, with a note, where it does not.

use edtmap::sensor::{Measurement, RangeLimits, Sensor};
use edtmap::{Mapper, MapperParams, VolumeParams, VoxelIndex, VoxelState};
use edtmap_io::depth_folder::DepthFolder;
use std::collections::HashSet;
use std::path::PathBuf;

/// The shared folder `name`, or `None` (with a note) where it is absent.
fn shared(name: &str) -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data").join(name);
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("skipped: {} is absent (the shared recordings are not in the repository)", dir.display());
        None
    }
}

#[test]
fn reads_every_frame_with_pose_and_intrinsics() {
    let range = RangeLimits { min_m: 0.3, max_m: 8.0 };
    let Some(folder) = shared("3dmatch-seq01") else { return };
    let data = DepthFolder::open(&folder, 0.001, range).expect("the shared 3DMatch folder");
    assert_eq!(data.frames.len(), 5);
    assert_eq!((data.camera.width, data.camera.height), (640, 480));
    assert!((data.camera.fx - 570.342).abs() < 1e-3 && (data.camera.cx - 320.0).abs() < 1e-9);
    for i in 0..5 {
        let frame = data.frame(i).expect("frame");
        let Measurement::Depth(image) = &frame.measurement else { panic!("a depth frame") };
        let valid = (0..640 * 480).filter(|&k| image.depth_m(k).is_finite()).count();
        let share = valid as f64 / (640.0 * 480.0);
        assert!((0.7..0.99).contains(&share), "frame {i}: {share} of pixels valid");
    }
    // Malformed folders name the problem.
    let err = DepthFolder::open(&folder.join("no-such-dir"), 0.001, range).expect_err("missing");
    assert!(err.to_string().contains("no-such-dir"), "{err}");
}

#[test]
fn occupied_voxels_lie_on_the_depth_points() {
    let range = RangeLimits { min_m: 0.3, max_m: 8.0 };
    let Some(folder) = shared("3dmatch-seq01") else { return };
    let data = DepthFolder::open(&folder, 0.001, range).expect("folder");
    let vs = 0.1;
    let mut params = MapperParams::for_voxel_size(vs);
    params.volume = VolumeParams { size_m: [16.0, 16.0, 16.0], fixed_height_m: None };
    let mut mapper = Mapper::new(Sensor::Depth(data.camera.clone()), params).expect("mapper");
    let mut points = HashSet::new();
    for i in 0..3 {
        let frame = data.frame(i).expect("frame");
        mapper.integrate_frame(&frame).expect("integrate");
        let Measurement::Depth(image) = &frame.measurement else { unreachable!() };
        let c = &data.camera;
        for k in (0..640 * 480).step_by(3) {
            let z = f64::from(image.depth_m(k));
            if !z.is_finite() || z < range.min_m as f64 || z > range.max_m as f64 {
                continue;
            }
            let (u, v) = ((k % 640) as f64 + 0.5, (k / 640) as f64 + 0.5);
            let p = nalgebra::Point3::new((u - c.cx) / c.fx * z, (v - c.cy) / c.fy * z, z);
            let w = frame.t_world_sensor * p;
            points.insert(VoxelIndex::containing([w.x, w.y, w.z], vs).expect("finite"));
        }
    }
    let map = mapper.map();
    let (mut occupied, mut on_points) = (0usize, 0usize);
    for (key, block) in map.occupancy().iter() {
        for (offset, lo) in block.log_odds.iter().enumerate() {
            if map.log_odds().state(lo) != VoxelState::Occupied {
                continue;
            }
            occupied += 1;
            let v = key.voxel(offset);
            let near = (-1..=1).any(|dz| {
                (-1..=1)
                    .any(|dy| (-1..=1).any(|dx| points.contains(&VoxelIndex([v.0[0] + dx, v.0[1] + dy, v.0[2] + dz]))))
            });
            on_points += usize::from(near);
        }
    }
    assert!(occupied > 5_000, "{occupied} occupied voxels");
    let share = on_points as f64 / occupied as f64;
    assert!(share > 0.99, "{share} of occupied voxels lie within a voxel of a depth point");
}
