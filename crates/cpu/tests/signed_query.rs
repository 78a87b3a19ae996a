//! The signed distance (`edtmap_core::query::distance` with `signed`)
//! against brute force to the obstacle voxels' surface, on a map whose
//! global EDT the CPU backend computed.

use edtmap::stages::IntegrationStage;
use edtmap_core::query::distance;
use edtmap_core::{
    GlobalMap, GlobalParams, Grid3, IntegrationMode, LocalVolume, OccupancyParams, VoxelIndex, FAR_DIST_SQ,
};
use edtmap_cpu::edt::{edt_with, ScanLayout};
use edtmap_cpu::CpuBackend;

const VS: f64 = 0.1;

/// The point of voxel `w`'s cube (voxel units) nearest `u`.
fn closest_on_cube(u: [f64; 3], w: VoxelIndex) -> [f64; 3] {
    [0, 1, 2].map(|a| u[a].clamp(f64::from(w.0[a]), f64::from(w.0[a]) + 1.0))
}

fn dist_sq(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum()
}

/// SplitMix64: a small seeded generator.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A map observed over `dims` voxels from the origin, `mask` voxels
/// occupied, its global EDT computed exactly.
fn map_of(mask: &Grid3<bool>) -> GlobalMap {
    let params = GlobalParams { max_distance_m: 1.2, mode: IntegrationMode::Exact, ..Default::default() };
    let mut map = GlobalMap::new(VS, OccupancyParams::default(), params).expect("valid");
    let window = LocalVolume { origin: VoxelIndex([0; 3]), dims: mask.dims(), voxel_size_m: VS };
    let (min, max) = (map.log_odds().min, map.log_odds().max);
    for (i, &o) in mask.as_slice().iter().enumerate() {
        let v = window.world(mask.coords(i));
        map.occupancy_mut().get_or_insert(v.block()).log_odds.set(v.offset_in_block(), if o { max } else { min });
    }
    let batch = edt_with(mask, |&o| o, ScanLayout::default()).expect("batch");
    let stage = IntegrationStage::new(map.params(), VS).expect("valid");
    let (edt, obstacles) = map.edt_and_obstacles();
    stage.merge_window(&mut CpuBackend::default(), edt, obstacles, &window, &batch).expect("integrate");
    map
}

/// The signed distance (voxels) of `u` by brute force over every voxel of the grid.
fn brute(mask: &Grid3<bool>, u: [f64; 3], inside: bool) -> f64 {
    let mut best = f64::INFINITY;
    for (i, &o) in mask.as_slice().iter().enumerate() {
        if o != inside {
            let [x, y, z] = mask.coords(i).map(|c| c as i32);
            best = best.min(dist_sq(u, closest_on_cube(u, VoxelIndex([x, y, z]))));
        }
    }
    if inside {
        -best.sqrt()
    } else {
        best.sqrt()
    }
}

#[test]
fn signed_distance_matches_brute_force_to_the_voxel_surface() {
    // Random blobs well inside a free margin, so every nearest free voxel
    // of an obstacle lies in the grid.
    let n = 20;
    let mut rng = Rng(13);
    let blobs: Vec<([f64; 3], f64)> =
        (0..6).map(|_| ([0, 1, 2].map(|_| 5.0 + 10.0 * rng.next()), 1.0 + 2.5 * rng.next())).collect();
    let mask = Grid3::from_fn([n; 3], |x, y, z| {
        let c = [x, y, z].map(|i| i as f64 + 0.5);
        blobs.iter().any(|(b, r)| dist_sq(c, *b) <= r * r)
    })
    .expect("dims");
    let map = map_of(&mask);
    let (mut worst, mut signs, mut inexact) = (0.0f64, 0, 0);
    for _ in 0..4000 {
        let u = [0, 1, 2].map(|_| 3.0 + 14.0 * rng.next());
        let v = VoxelIndex(u.map(|c| c.floor() as i32));
        let inside = mask.get(v.0.map(|c| c as usize)).copied().unwrap_or(false);
        if !inside {
            assert!(map.entry(v).0 != FAR_DIST_SQ, "the cutoff covers the grid");
        }
        let d = distance(&map, u.map(|c| c * VS), true);
        let truth = brute(&mask, u, inside);
        // Outside, the cube found is a real obstacle: never nearer than the nearest.
        assert!(d.distance_m / VS >= truth - 1e-9, "{u:?}: {} below the exact {truth}", d.distance_m / VS);
        let err = (d.distance_m / VS - truth).abs();
        worst = worst.max(err);
        inexact += usize::from(err > 1e-9);
        signs += usize::from((d.distance_m < 0.0) != inside);
        let g = d.gradient;
        assert!(((g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt() - 1.0).abs() < 1e-9, "{u:?}: gradient {g:?}");
    }
    assert_eq!(signs, 0, "sign differs from the voxel's");
    // The EDT's nearest obstacle by centre is nearly always the nearest cube.
    assert!(worst < 0.1 && inexact < 40, "largest error {worst} voxels, {inexact} of 4000 inexact");
}
