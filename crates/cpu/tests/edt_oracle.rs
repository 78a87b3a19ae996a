//! The batch EDT against a brute-force oracle: for every voxel, the nearest
//! obstacle found by exhaustive search over all obstacles.

use edtmap_core::{EdtField, EdtParams, Grid3, VoxelState, NO_SITE, UNREACHABLE_DIST_SQ};
use edtmap_cpu::edt::{batch_edt, edt_with, ScanLayout};
use edtmap_sim::random_grid;
use proptest::prelude::*;

/// Exhaustive nearest-obstacle squared distance of every voxel.
fn brute_force(grid: &Grid3<bool>) -> Vec<u32> {
    let sites: Vec<[usize; 3]> = (0..grid.len()).filter(|&i| grid.as_slice()[i]).map(|i| grid.coords(i)).collect();
    (0..grid.len())
        .map(|i| {
            let c = grid.coords(i);
            sites
                .iter()
                .map(|s| (0..3).map(|a| (c[a].abs_diff(s[a]) as u32).pow(2)).sum::<u32>())
                .min()
                .unwrap_or(UNREACHABLE_DIST_SQ)
        })
        .collect()
}

/// Asserts exact distances and that every nearest index is an obstacle at
/// exactly the reported distance.
fn assert_matches_oracle(grid: &Grid3<bool>, edt: &EdtField) {
    let expected = brute_force(grid);
    assert_eq!(edt.dims(), grid.dims());
    for (i, (&got, &want)) in edt.dist_sq_vox().iter().zip(&expected).enumerate() {
        let c = grid.coords(i);
        assert_eq!(got, want, "distance at {c:?} in grid {:?}", grid.dims());
        let site = edt.nearest()[i];
        if want == UNREACHABLE_DIST_SQ {
            assert_eq!(site, NO_SITE, "voxel {c:?} has a site but the grid has no obstacle");
            continue;
        }
        let s = grid.coords(site as usize);
        assert!(grid.as_slice()[site as usize], "nearest of {c:?} is {s:?}, not an obstacle");
        let d: u32 = (0..3).map(|a| (c[a].abs_diff(s[a]) as u32).pow(2)).sum();
        assert_eq!(d, want, "nearest of {c:?} is {s:?} at {d}, not {want}");
    }
}

const LAYOUTS: [ScanLayout; 6] = [
    ScanLayout::PerLine,
    ScanLayout::TiledEnvelope { lanes: 5 },
    ScanLayout::TiledEnvelope { lanes: 16 },
    ScanLayout::Tiled { lanes: 3 },
    ScanLayout::Tiled { lanes: 16 },
    ScanLayout::Tiled { lanes: 64 },
];

fn density() -> impl Strategy<Value = f64> {
    prop_oneof![Just(0.0), Just(1.0), Just(0.002), 0.0..0.05f64, 0.0..1.0f64,]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_3d_grids_match_oracle(
        nx in 1usize..=24, ny in 1usize..=24, nz in 1usize..=24,
        density in density(), seed in any::<u64>(), layout in 0..LAYOUTS.len(),
    ) {
        let grid = random_grid([nx, ny, nz], density, seed).expect("valid dims");
        let edt = edt_with(&grid, |&o| o, LAYOUTS[layout]).expect("edt");
        assert_matches_oracle(&grid, &edt);
    }

    #[test]
    fn random_2d_grids_match_oracle(
        nx in 1usize..=64, ny in 1usize..=64,
        density in density(), seed in any::<u64>(), layout in 0..LAYOUTS.len(),
    ) {
        let grid = random_grid([nx, ny, 1], density, seed).expect("valid dims");
        let edt = edt_with(&grid, |&o| o, LAYOUTS[layout]).expect("edt");
        assert_matches_oracle(&grid, &edt);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Long sparse y lines: windows too long for the windowed scan, so the
    /// lower envelope (or a mix) runs.
    #[test]
    fn long_2d_lines_match_oracle(
        nx in 1usize..=9, ny in 200usize..=420,
        density in 0.0..0.02f64, seed in any::<u64>(), layout in 0..LAYOUTS.len(),
    ) {
        let grid = random_grid([nx, ny, 1], density, seed).expect("valid dims");
        let edt = edt_with(&grid, |&o| o, LAYOUTS[layout]).expect("edt");
        assert_matches_oracle(&grid, &edt);
    }
}

#[test]
fn full_24_cube_at_each_density() {
    for (k, density) in [0.0, 0.0005, 0.01, 0.1, 0.5, 1.0].into_iter().enumerate() {
        let grid = random_grid([24, 24, 24], density, 100 + k as u64).expect("valid dims");
        let edt = edt_with(&grid, |&o| o, ScanLayout::default()).expect("edt");
        assert_matches_oracle(&grid, &edt);
    }
}

#[test]
fn thin_and_degenerate_shapes() {
    let shapes = [[1, 1, 1], [1, 1, 24], [24, 1, 1], [1, 24, 1], [2, 1, 17], [23, 2, 1], [1, 5, 9]];
    for (k, dims) in shapes.into_iter().enumerate() {
        for density in [0.0, 0.1, 1.0] {
            let grid = random_grid(dims, density, k as u64).expect("valid dims");
            let edt = edt_with(&grid, |&o| o, ScanLayout::default()).expect("edt");
            assert_matches_oracle(&grid, &edt);
        }
    }
}

#[test]
fn single_corner_obstacle_reaches_far_corner() {
    let grid = Grid3::from_fn([20, 13, 7], |x, y, z| (x, y, z) == (0, 0, 0)).expect("valid dims");
    let edt = edt_with(&grid, |&o| o, ScanLayout::default()).expect("edt");
    let far = grid.linear([19, 12, 6]);
    assert_eq!(edt.dist_sq_vox()[far], 19 * 19 + 12 * 12 + 6 * 6);
    assert_eq!(edt.nearest_coords(far), Some([0, 0, 0]));
}

#[test]
fn grid_without_obstacles_is_saturated() {
    let grid = Grid3::from_vec([5, 4, 3], vec![false; 60]).expect("valid dims");
    let edt = edt_with(&grid, |&o| o, ScanLayout::default()).expect("edt");
    assert!(edt.dist_sq_vox().iter().all(|&d| d == UNREACHABLE_DIST_SQ));
    assert!(edt.nearest().iter().all(|&s| s == NO_SITE));
    assert_eq!(edt.distance_vox(0), f32::INFINITY);
}

#[test]
fn unknown_voxels_are_free_unless_asked() {
    // Occupied, free and unknown voxels mixed at random.
    let mask = random_grid([12, 10, 9], 0.05, 11).expect("valid dims");
    let unknown = random_grid([12, 10, 9], 0.2, 12).expect("valid dims");
    let states = Grid3::from_fn([12, 10, 9], |x, y, z| {
        let i = mask.linear([x, y, z]);
        match (mask.as_slice()[i], unknown.as_slice()[i]) {
            (true, _) => VoxelState::Occupied,
            (false, true) => VoxelState::Unknown,
            (false, false) => VoxelState::Free,
        }
    })
    .expect("valid dims");
    for unknown_as_occupied in [false, true] {
        let params = EdtParams { unknown_as_occupied };
        let edt = batch_edt(&states, &params).expect("edt");
        let sites = Grid3::from_fn(states.dims(), |x, y, z| {
            states.get([x, y, z]).is_some_and(|s| s.is_obstacle(unknown_as_occupied))
        })
        .expect("valid dims");
        assert_matches_oracle(&sites, &edt);
    }
}

#[test]
fn empty_rows_and_planes_between_dense_ones() {
    // Obstacles only in some z planes and, within those, some y rows: the
    // y and z scans see rows with no obstacle between rows with small
    // distances, the case the windowed scan handles specially.
    let dense = random_grid([40, 24, 30], 0.3, 5).expect("valid dims");
    let grid = Grid3::from_fn([40, 24, 30], |x, y, z| {
        let keep_plane = z % 7 == 2 || z == 29;
        let keep_row = y % 5 != 1;
        keep_plane && keep_row && dense.as_slice()[dense.linear([x, y, z])]
    })
    .expect("valid dims");
    for layout in LAYOUTS {
        let edt = edt_with(&grid, |&o| o, layout).expect("edt");
        assert_matches_oracle(&grid, &edt);
    }
}

#[test]
fn long_sparse_lines_use_the_envelope() {
    // Lines of 300 to 700 voxels with few obstacles: the windows would be
    // longer than the windowed scan's budget, so these tiles go through the
    // lower envelope (and mixed tiles through both).
    let shapes = [[4, 600, 3], [3, 2, 700], [2, 300, 300], [70, 1, 330]];
    for (k, dims) in shapes.into_iter().enumerate() {
        for density in [0.0005, 0.003, 0.02] {
            let grid = random_grid(dims, density, 40 + k as u64).expect("valid dims");
            for layout in [ScanLayout::PerLine, ScanLayout::default()] {
                let edt = edt_with(&grid, |&o| o, layout).expect("edt");
                assert_matches_oracle(&grid, &edt);
            }
        }
    }
}
