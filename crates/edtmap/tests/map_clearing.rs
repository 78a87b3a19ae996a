//! `Mapper::clear_far`: the map beyond a radius is forgotten, and the
//! global EDT stays the exact EDT of the obstacles kept (checked against an
//! exact EDT computed from scratch), before and after mapping goes on.

use edtmap::eval::{edt_errors, edt_extent};
use edtmap::sensor::{Frame, Measurement, PointCloud, RangeLimits, Sensor};
use edtmap::{Mapper, MapperParams, VoxelIndex};
use nalgebra::Isometry3;
use rand::{Rng, SeedableRng};

/// A corridor of random pillars along x, seen from `x` (metres).
fn frame(x: f64, rng: &mut rand::rngs::StdRng, pillars: &[[f64; 2]]) -> Frame {
    let mut points = Vec::new();
    for p in pillars {
        if (p[0] - x).abs() < 6.0 {
            for _ in 0..150 {
                let (a, z): (f64, f64) = (rng.random_range(0.0..std::f64::consts::TAU), rng.random_range(0.1..2.5));
                points.push([(p[0] + 0.3 * a.cos() - x) as f32, (p[1] + 0.3 * a.sin()) as f32, (z - 1.0) as f32]);
            }
        }
    }
    Frame {
        stamp_s: x,
        t_world_sensor: Isometry3::translation(x, 0.0, 1.0),
        measurement: Measurement::Points(PointCloud { points }),
    }
}

fn assert_exact(mapper: &Mapper, when: &str) {
    let map = mapper.map();
    let errors = edt_errors(map, &edt_extent(map).expect("an EDT")).expect("exact EDT");
    assert!(errors.max_m == 0.0 && errors.wrong_fraction == 0.0, "{when}: {errors:?}");
}

/// The window's states are the map's, voxel by voxel.
fn assert_states_are_the_maps(mapper: &Mapper, when: &str) {
    let volume = mapper.local_volume().expect("a frame was integrated");
    let states = mapper.local_states().as_slice();
    let [nx, ny, nz] = volume.dims;
    assert_eq!(states.len(), nx * ny * nz, "{when}");
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let v = volume.world([x, y, z]);
                assert_eq!(states[x + nx * (y + ny * z)], mapper.state(v), "{when}: voxel {v:?}");
            }
        }
    }
}

#[test]
fn clearing_far_blocks_keeps_the_edt_exact_and_frees_memory() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(31);
    let pillars: Vec<[f64; 2]> = (0..40).map(|i| [f64::from(i) * 0.9 - 2.0, rng.random_range(-3.0..3.0)]).collect();
    let sensor = Sensor::Points(RangeLimits { min_m: 0.1, max_m: 8.0 });
    let mut mapper = Mapper::new(sensor, MapperParams::for_voxel_size(0.2)).expect("mapper");
    for i in 0..40 {
        mapper.integrate_frame(&frame(f64::from(i) * 0.5, &mut rng, &pillars)).expect("frame");
    }
    assert_exact(&mapper, "before clearing");
    assert_states_are_the_maps(&mapper, "before clearing");
    let centre = [19.5, 0.0, 1.0];
    let radius = 6.0;
    let kept_before = mapper.backend().kept_bytes();
    let cleared = mapper.clear_far(centre, radius).expect("clears");
    // The exact mode's kept passes shrink with the map.
    assert!(mapper.backend().kept_bytes() < kept_before, "{} then {}", kept_before, mapper.backend().kept_bytes());
    assert!(cleared.occupancy_blocks > 10, "{cleared:?}");
    assert!(cleared.bytes_after < cleared.bytes_before, "{cleared:?}");
    let side = 8.0 * 0.2;
    for (k, _) in mapper.map().occupancy().iter() {
        let d = (0..3).map(|a| ((f64::from(k.0[a]) + 0.5) * side - centre[a]).powi(2)).sum::<f64>().sqrt();
        assert!(d <= radius, "block {k:?} at {d} m was kept");
    }
    // A voxel far behind is forgotten; one near the robot is not.
    assert_eq!(mapper.state(VoxelIndex([0, 0, 5])), edtmap::VoxelState::Unknown);
    assert_exact(&mapper, "after clearing");
    // The window's states are read again, where blocks were dropped too.
    assert_states_are_the_maps(&mapper, "after clearing");
    // Mapping goes on (back over the cleared part too), still exact.
    for i in (0..40).rev().step_by(3) {
        mapper.integrate_frame(&frame(f64::from(i) * 0.5, &mut rng, &pillars)).expect("frame");
    }
    assert_exact(&mapper, "after mapping on");
    let again = mapper.clear_far([0.0, 0.0, 1.0], 4.0).expect("clears");
    assert!(again.occupancy_blocks > 0);
    assert_exact(&mapper, "after a second clearing");
    assert_states_are_the_maps(&mapper, "after a second clearing");
}

#[test]
fn clearing_needs_the_exact_mode_and_a_radius() {
    let sensor = Sensor::Points(RangeLimits { min_m: 0.1, max_m: 8.0 });
    let mut params = MapperParams::for_voxel_size(0.2);
    let mut mapper = Mapper::new(sensor.clone(), params.clone()).expect("mapper");
    assert!(mapper.clear_far([0.0; 3], -1.0).expect_err("negative").to_string().contains("map_clearing_radius_m"));
    params.global.mode = edtmap::IntegrationMode::Wavefront;
    let mut wave = Mapper::new(sensor, params).expect("mapper");
    assert!(wave.clear_far([0.0; 3], 5.0).expect_err("wavefront").to_string().contains("exact"));
}
