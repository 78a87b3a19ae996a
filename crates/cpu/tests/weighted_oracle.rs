//! The weighted (anisotropic) EDT against a brute-force oracle: for every
//! voxel, the nearest obstacle under `Σ w_k² d_k²` found by exhaustive
//! search, for integer spacings (exact) and real ones (to f64 rounding).

use edtmap_core::{Grid3, NO_SITE};
use edtmap_cpu::edt::{edt_weighted_int, edt_weighted_real, edt_with, ScanLayout};
use edtmap_sim::random_grid;
use proptest::prelude::*;

/// Weighted squared distance between the voxels `a` and `b` of `grid`.
fn weighted<T>(grid: &Grid3<T>, a: usize, b: usize, w: [f64; 3]) -> f64 {
    let (ca, cb) = (grid.coords(a), grid.coords(b));
    (0..3).map(|k| (w[k] * ca[k].abs_diff(cb[k]) as f64).powi(2)).sum()
}

/// Exhaustive minimum of `Σ w_k² d_k²` over the obstacles, per voxel, in
/// u128 for integer weights.
fn brute_int(grid: &Grid3<bool>, w: [u32; 3]) -> Vec<Option<u128>> {
    let sites: Vec<usize> = (0..grid.len()).filter(|&i| grid.as_slice()[i]).collect();
    (0..grid.len())
        .map(|i| {
            let c = grid.coords(i);
            sites
                .iter()
                .map(|&s| {
                    let s = grid.coords(s);
                    (0..3).map(|k| u128::from(w[k]).pow(2) * (c[k].abs_diff(s[k]) as u128).pow(2)).sum()
                })
                .min()
        })
        .collect()
}

fn check_int(grid: &Grid3<bool>, w: [u32; 3]) {
    let (dist, near) = edt_weighted_int(grid.as_slice(), grid.dims(), |&o| o, w).expect("a weighted EDT of the grid");
    let wf = w.map(f64::from);
    for (i, want) in brute_int(grid, w).into_iter().enumerate() {
        match want {
            None => {
                assert_eq!(dist[i], u64::MAX, "voxel {:?}", grid.coords(i));
                assert_eq!(near[i], NO_SITE);
            }
            Some(want) => {
                assert_eq!(u128::from(dist[i]), want, "voxel {:?} dims {:?} w {w:?}", grid.coords(i), grid.dims());
                let site = near[i] as usize;
                assert!(grid.as_slice()[site], "nearest of {:?} is no obstacle", grid.coords(i));
                assert_eq!(weighted(grid, i, site, wf), want as f64, "nearest of {:?}", grid.coords(i));
            }
        }
    }
}

fn check_real(grid: &Grid3<bool>, w: [f64; 3]) {
    let (dist, near) = edt_weighted_real(grid.as_slice(), grid.dims(), |&o| o, w).expect("a weighted EDT of the grid");
    let sites: Vec<usize> = (0..grid.len()).filter(|&i| grid.as_slice()[i]).collect();
    for i in 0..grid.len() {
        let want = sites.iter().map(|&s| weighted(grid, i, s, w)).fold(f64::INFINITY, f64::min);
        if sites.is_empty() {
            assert_eq!(dist[i], f64::INFINITY);
            assert_eq!(near[i], NO_SITE);
            continue;
        }
        let tol = 1e-12 * want.max(1.0);
        assert!((dist[i] - want).abs() <= tol, "voxel {:?}: {} vs {want}", grid.coords(i), dist[i]);
        let site = near[i] as usize;
        assert!(grid.as_slice()[site]);
        assert!((weighted(grid, i, site, w) - want).abs() <= tol, "nearest of {:?}", grid.coords(i));
    }
}

#[test]
fn integer_weights_on_edge_cases() {
    for dims in [[1, 1, 1], [7, 1, 1], [1, 9, 1], [1, 1, 6], [5, 4, 3], [17, 3, 1]] {
        for fill in [0.0, 1.0, 0.05] {
            let grid = random_grid(dims, fill, 7).expect("a random grid");
            for w in [[1, 1, 1], [3, 1, 2], [1, 7, 1], [2, 2, 5]] {
                check_int(&grid, w);
            }
        }
    }
}

#[test]
fn unit_integer_weights_equal_the_isotropic_transform() {
    let grid = random_grid([33, 21, 14], 0.02, 11).expect("a random grid");
    let iso = edt_with(&grid, |&o| o, ScanLayout::default()).expect("the isotropic EDT");
    let (dist, _) =
        edt_weighted_int(grid.as_slice(), grid.dims(), |&o| o, [1, 1, 1]).expect("a weighted EDT of the grid");
    assert!(dist.iter().zip(iso.dist_sq_vox()).all(|(&a, &b)| a == u64::from(b)));
}

#[test]
fn rejects_bad_weights_and_sizes() {
    let grid = [false; 8];
    assert!(edt_weighted_int(&grid, [2, 2, 2], |&o| o, [1, 0, 1]).is_err());
    assert!(edt_weighted_real(&grid, [2, 2, 2], |&o| o, [1.0, f64::NAN, 1.0]).is_err());
    assert!(edt_weighted_real(&grid, [2, 2, 2], |&o| o, [1.0, -1.0, 1.0]).is_err());
    assert!(edt_weighted_real(&grid, [2, 2, 2], |&o| o, [1e300, 1.0, 1.0]).is_err());
    assert!(edt_weighted_int(&grid, [2, 2, 3], |&o| o, [1, 1, 1]).is_err());
    assert!(edt_weighted_int(&grid, [8, 1, 1], |&o| o, [u32::MAX, 1, 1]).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 48,
        rng_seed: proptest::test_runner::RngSeed::Fixed(17),
        ..ProptestConfig::default()
    })]

    #[test]
    fn integer_weights_match_brute_force(
        nx in 1usize..14, ny in 1usize..12, nz in 1usize..9,
        fill in 0.0f64..0.15, seed in any::<u64>(),
        w in prop::array::uniform3(1u32..9),
    ) {
        let grid = random_grid([nx, ny, nz], fill, seed).expect("a random grid");
        check_int(&grid, w);
    }

    #[test]
    fn real_weights_match_brute_force(
        nx in 1usize..14, ny in 1usize..12, nz in 1usize..9,
        fill in 0.0f64..0.15, seed in any::<u64>(),
        w in prop::array::uniform3(0.01f64..10.0),
    ) {
        let grid = random_grid([nx, ny, nz], fill, seed).expect("a random grid");
        check_real(&grid, w);
    }
}
