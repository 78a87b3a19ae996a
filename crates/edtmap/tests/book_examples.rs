//! The Rust examples of the book (docs/library.md, docs/queries.md), which
//! includes them from here between their `ANCHOR` lines, so that what the
//! book shows compiles and runs.

use std::path::Path;

#[test]
fn a_mapper_from_one_frame() -> Result<(), Box<dyn std::error::Error>> {
    // ANCHOR: mapper
    use edtmap::sensor::{Frame, Measurement, PointCloud, RangeLimits, Sensor};
    use edtmap::{Mapper, MapperParams, VoxelIndex, VoxelState};
    use nalgebra::Isometry3;

    let sensor = Sensor::Points(RangeLimits { min_m: 0.1, max_m: 20.0 });
    let mut mapper = Mapper::new(sensor, MapperParams::for_voxel_size(0.1))?;
    let frame = Frame {
        stamp_s: 0.0,
        t_world_sensor: Isometry3::translation(0.0, 0.0, 1.0), // T_world_sensor
        measurement: Measurement::Points(PointCloud { points: vec![[2.05, 0.05, 0.05]] }),
    };
    let stats = mapper.integrate_frame(&frame)?; // ogm_ms, batch_edt_ms, integrate_ms, changed_blocks, …
    assert_eq!(mapper.state(VoxelIndex([20, 0, 10])), VoxelState::Occupied);
    let edt = mapper.local_edt(); // exact EDT of the local volume
    let d = mapper.distance([1.55, 0.05, 1.05]); // global EDT: 0.5 m from the return, with gradient
                                                 // ANCHOR_END: mapper
    assert!(stats.total_ms >= 0.0 && !edt.dist_sq_vox().is_empty());
    assert!((d.distance_m - 0.5).abs() < 1e-6, "{}", d.distance_m);
    Ok(())
}

#[test]
fn frames_on_the_cores_left_free() -> Result<(), Box<dyn std::error::Error>> {
    // ANCHOR: threads
    use edtmap::sensor::{Frame, Measurement, PointCloud, RangeLimits, Sensor};
    use edtmap::{FrameThreads, Mapper, MapperParams, VoxelIndex, VoxelState};
    use nalgebra::Isometry3;

    let sensor = Sensor::Points(RangeLimits { min_m: 0.1, max_m: 20.0 });
    let mut mapper = Mapper::new(sensor, MapperParams::for_voxel_size(0.1))?;
    let mut threads = FrameThreads::new(); // once, then for every frame
    let frame = Frame {
        stamp_s: 0.0,
        t_world_sensor: Isometry3::translation(0.0, 0.0, 1.0),
        measurement: Measurement::Points(PointCloud { points: vec![[2.05, 0.05, 0.05]] }),
    };
    let stats = threads.run(|| mapper.integrate_frame(&frame))?; // on threads.threads() threads
    assert_eq!(mapper.state(VoxelIndex([20, 0, 10])), VoxelState::Occupied);
    // ANCHOR_END: threads
    assert!(stats.voxels_updated >= 19);
    assert!((1..=rayon::current_num_threads()).contains(&threads.threads()));
    Ok(())
}

#[test]
fn an_exact_edt_of_a_grid() -> Result<(), Box<dyn std::error::Error>> {
    // ANCHOR: batch
    use edtmap::{cpu, EdtParams, Grid3, VoxelState};

    let states =
        Grid3::from_fn(
            [64, 64, 32],
            |x, y, _| {
                if x == 10 && y == 20 {
                    VoxelState::Occupied
                } else {
                    VoxelState::Free
                }
            },
        )?;
    let edt = cpu::edt::batch_edt(&states, &EdtParams::default())?; // unknown counts as free
    let i = states.linear([13, 24, 5]);
    assert_eq!(edt.dist_sq_vox()[i], 3 * 3 + 4 * 4); // exact, in voxels²
    assert_eq!(edt.nearest_coords(i), Some([10, 20, 5]));
    // ANCHOR_END: batch
    Ok(())
}

#[test]
fn queries_and_saved_maps() -> Result<(), Box<dyn std::error::Error>> {
    use edtmap::sensor::{Frame, Measurement, PointCloud, RangeLimits, Sensor};
    use edtmap::{Mapper, MapperParams};
    use nalgebra::Isometry3;

    let dir = tempfile::tempdir()?;
    std::env::set_current_dir(dir.path())?;
    let sensor = Sensor::Points(RangeLimits { min_m: 0.1, max_m: 20.0 });
    let params = MapperParams::for_voxel_size(0.1);
    let mut mapper = Mapper::new(sensor.clone(), params.clone())?;
    let wall: Vec<[f32; 3]> =
        (0..40).flat_map(|i| (0..20).map(move |k| [3.0, -1.0 + 0.05 * i as f32, 0.05 * k as f32])).collect();
    let frame = Frame {
        stamp_s: 0.0,
        t_world_sensor: Isometry3::translation(0.0, 0.0, 1.0),
        measurement: Measurement::Points(PointCloud { points: wall }),
    };
    mapper.integrate_frame(&frame)?;
    let other_map = mapper.map().clone();
    let points = vec![[1.0, 0.0, 1.0], [2.5, 0.2, 1.2]];
    let p = [2.9, 0.0, 1.0];
    // ANCHOR: queries
    let d = mapper.distance([1.0, 2.0, 1.5]); // trilinear between voxel centres
    println!(
        "{} m, gradient {:?}, {:?}, observed {}, saturated {}",
        d.distance_m, d.gradient, d.state, d.observed, d.saturated
    );
    let many = mapper.distances(&points); // in parallel, same order
    let inside = mapper.signed_distance(p); // to the obstacle voxels' surface, negative inside
    let state = mapper.state_at(p); // Outside | Unknown | Free | Occupied
    let frontiers = mapper.frontiers(); // observed free voxels next to unknown ones
    let local = mapper.local_edt(); // the latest window's exact EDT (high-rate local planning)
    edtmap::save_map(mapper.map(), Path::new("map.edtmap"))?;
    let map = edtmap::load_map(Path::new("map.edtmap"))?; // a GlobalMap: query it with edtmap::query
    let mut mapper = Mapper::with_map(sensor, params, map)?; // or go on mapping from it
    mapper.add_prior(&other_map)?; // its obstacles become fixed obstacles
                                   // ANCHOR_END: queries
    assert_eq!(many.len(), 2);
    assert!(many[1].distance_m < many[0].distance_m);
    assert!(inside.distance_m < 0.2, "{}", inside.distance_m);
    assert_eq!(state, edtmap::PointState::Free);
    assert!(!frontiers.is_empty() && !local.dist_sq_vox().is_empty());
    Ok(())
}
