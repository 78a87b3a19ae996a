//! Distance, gradient and state queries against analytic scenes: a plane,
//! a sphere and a box of obstacle voxels. Distances are measured between
//! voxel centres, so the analytic answers are taken to the obstacle voxels'
//! centres.

use edtmap::cpu::edt::{edt_with, ScanLayout};
use edtmap::cpu::CpuBackend;
use edtmap::query::{distance, distance_box, distances, PointState};
use edtmap::stages::IntegrationStage;
use edtmap::{GlobalMap, GlobalParams, Grid3, IntegrationMode, LocalVolume, OccupancyParams, VoxelIndex};

const VS: f64 = 0.1;

/// A map whose box `lo + dims` is observed: `obstacle` voxels occupied, the
/// rest free; its global EDT computed exactly.
fn map_of(lo: [i32; 3], dims: [usize; 3], obstacle: impl Fn([f64; 3]) -> bool) -> GlobalMap {
    let params = GlobalParams { max_distance_m: 1.5, mode: IntegrationMode::Exact, ..Default::default() };
    let mut map = GlobalMap::new(VS, OccupancyParams::default(), params).expect("valid");
    let window = LocalVolume { origin: VoxelIndex(lo), dims, voxel_size_m: VS };
    let (min, max) = (map.log_odds().min, map.log_odds().max);
    let mask = Grid3::from_fn(dims, |x, y, z| obstacle(window.world([x, y, z]).centre(VS))).expect("dims");
    for (i, &o) in mask.as_slice().iter().enumerate() {
        let v = window.world(mask.coords(i));
        map.occupancy_mut().get_or_insert(v.block()).log_odds.set(v.offset_in_block(), if o { max } else { min });
    }
    let batch = edt_with(&mask, |&o| o, ScanLayout::default()).expect("batch");
    let stage = IntegrationStage::new(map.params(), VS).expect("valid");
    let (edt, obstacles) = map.edt_and_obstacles();
    stage.merge_window(&mut CpuBackend::default(), edt, obstacles, &window, &batch).expect("integrate");
    map
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn plane_distance_and_gradient_are_exact() {
    // Obstacle voxels fill the layer 0 <= z < 0.1 m; their centres lie at z = 0.05.
    let map = map_of([-30, -30, -5], [60, 60, 25], |c| c[2] > 0.0 && c[2] < 0.1);
    for p in [[0.0, 0.0, 0.5], [0.33, -0.71, 0.27], [-1.04, 1.2, 0.91], [0.5, 0.5, 1.2]] {
        let d = distance(&map, p, false);
        assert!(close(d.distance_m, p[2] - 0.05, 1e-9), "{p:?}: {} vs {}", d.distance_m, p[2] - 0.05);
        assert!(
            close(d.gradient[2], 1.0, 1e-9) && close(d.gradient[0], 0.0, 1e-9) && close(d.gradient[1], 0.0, 1e-9),
            "{:?}",
            d.gradient
        );
        assert_eq!((d.state, d.observed, d.saturated), (PointState::Free, true, false));
    }
    // Below the plane the distance grows downwards.
    let d = distance(&map, [0.1, 0.2, -0.25], false);
    assert!(close(d.distance_m, 0.3, 1e-9) && close(d.gradient[2], -1.0, 1e-9), "{d:?}");
    // Beyond the cutoff: saturated at max_distance_m.
    let d = distance(&map, [0.0, 0.0, 1.95], false);
    assert!(d.saturated && close(d.distance_m, 1.5, 1e-9), "{d:?}");
    // Inside the plane, the signed distance is negative.
    let s = distance(&map, [0.05, 0.05, 0.05], true);
    assert!(s.distance_m < 0.0 && s.state == PointState::Occupied, "{s:?}");
}

#[test]
fn sphere_distance_and_gradient_within_a_voxel() {
    let (c, r) = ([0.02, -0.03, 0.01], 0.6);
    let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let map = map_of([-20, -20, -20], [40, 40, 40], |p| norm(sub(p, c)) <= r);
    let mut checked = 0;
    for k in 0..200 {
        // Points on a spiral 0.4 to 0.9 m (4 to 9 voxels) from the surface,
        // where the voxelised sphere's facets no longer steer the gradient.
        let t = k as f64 / 200.0;
        let (theta, phi) = (t * 37.0, (2.0 * t - 1.0).acos());
        let dir = [phi.sin() * theta.cos(), phi.sin() * theta.sin(), phi.cos()];
        let rho = r + 0.4 + 0.5 * t;
        let p = [c[0] + rho * dir[0], c[1] + rho * dir[1], c[2] + rho * dir[2]];
        if p.iter().any(|x| x.abs() > 1.9) {
            continue;
        }
        let d = distance(&map, p, false);
        // The voxelised sphere's surface centres lie within half a voxel
        // diagonal of the true sphere.
        assert!(close(d.distance_m, rho - r, 0.5 * VS * 3f64.sqrt()), "{p:?}: {} vs {}", d.distance_m, rho - r);
        let g = d.gradient;
        let cos = (g[0] * dir[0] + g[1] * dir[1] + g[2] * dir[2]) / norm(g);
        assert!(cos > 0.95 && close(norm(g), 1.0, 0.15), "{p:?}: gradient {g:?} vs direction {dir:?}");
        checked += 1;
    }
    assert!(checked > 150);
}

#[test]
fn box_distance_is_exact_at_voxel_centres() {
    // Obstacle voxels with centres in [-0.25, 0.25] x [-0.45, 0.05] x [0.05, 0.35].
    let inside = |p: [f64; 3]| p[0].abs() < 0.3 && p[1] > -0.5 && p[1] < 0.1 && p[2] > 0.0 && p[2] < 0.4;
    let map = map_of([-20, -20, -10], [40, 40, 30], inside);
    let (lo, hi) = ([-0.25, -0.45, 0.05], [0.25, 0.05, 0.35]);
    for v in [[5, 0, 3], [9, 4, 12], [-12, -11, -4], [0, 6, 1], [3, -9, 8]] {
        let p = VoxelIndex(v).centre(VS);
        let out: Vec<f64> = (0..3).map(|a| (lo[a] - p[a]).max(p[a] - hi[a]).max(0.0)).collect();
        let truth = out.iter().map(|x| x * x).sum::<f64>().sqrt();
        let d = distance(&map, p, false);
        assert!(close(d.distance_m, truth, 1e-6), "{v:?}: {} vs {truth}", d.distance_m);
    }
}

#[test]
fn batched_equals_single_and_states_are_reported() {
    let map = map_of([-10, -10, -10], [20, 20, 20], |p| p[0] > 0.3 && p[0] < 0.4);
    let points: Vec<[f64; 3]> = (0..500)
        .map(|i| {
            let t = i as f64 * 0.013;
            [(t * 3.1).sin() * 1.4, (t * 1.7).cos() * 1.4, (t * 0.9).sin() * 1.4]
        })
        .chain([[f64::NAN, 0.0, 0.0], [1e300, 0.0, 0.0]])
        .collect();
    let batch = distances(&map, &points, false);
    for (p, b) in points.iter().zip(&batch) {
        let single = distance(&map, *p, false);
        assert!(
            single.distance_m.to_bits() == b.distance_m.to_bits()
                && single.gradient == b.gradient
                && single.state == b.state
        );
    }
    assert_eq!(batch[500].state, PointState::Outside);
    assert!(batch[500].distance_m.is_nan() && batch[501].distance_m.is_nan());
    assert_eq!(distance(&map, [0.35, 0.0, 0.0], false).state, PointState::Occupied);
    assert_eq!(distance(&map, [50.0, 0.0, 0.0], false).state, PointState::Outside);
    let b = distance_box(&map, [-0.2, -0.1, 0.0], [0.6, 0.1, 0.1], false).expect("box");
    assert_eq!(b.dims, [8, 2, 1]);
    assert!((b.distance_m[3] - 0.2).abs() < 1e-6, "voxel x = 1 is two voxels from the wall at x = 3");
    assert_eq!(b.state[3], PointState::Free as u8);
    assert!(distance_box(&map, [0.0; 3], [1e6; 3], false).is_err(), "too many voxels");
}
