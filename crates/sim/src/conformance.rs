//! The backend conformance suite, written once and run against every
//! backend (`crates/cpu/tests/conformance.rs`, `crates/gpu/tests/`): each
//! check compares a backend's integer results with an independent oracle,
//! bit for bit, so backends that pass agree with each other exactly.

use crate::random_grid;
use edtmap_core::{BatchEdt, EdtField, Grid3, NO_SITE, UNREACHABLE_DIST_SQ};

/// The batch EDT with the tie rule of `edtmap_core::backend` (scans along
/// x, y, z; each keeps the lowest position among its smallest values), by
/// brute force over each line: `O(voxels × line length)` per scan.
pub fn separable_oracle(grid: &Grid3<bool>) -> EdtField {
    let dims = grid.dims();
    let n = grid.len();
    let mut f: Vec<u64> = grid.as_slice().iter().map(|&o| if o { 0 } else { u64::MAX }).collect();
    let mut site: Vec<u32> = (0..n).map(|i| if grid.as_slice()[i] { i as u32 } else { NO_SITE }).collect();
    let strides = [1, dims[0], dims[0] * dims[1]];
    for axis in 0..3 {
        let len = dims[axis];
        let (mut next_f, mut next_site) = (vec![u64::MAX; n], vec![NO_SITE; n]);
        for i in 0..n {
            let pos = grid.coords(i)[axis];
            let line_start = i - pos * strides[axis];
            for j in 0..len {
                let k = line_start + j * strides[axis];
                if f[k] == u64::MAX {
                    continue;
                }
                let c = f[k] + (pos.abs_diff(j) as u64).pow(2);
                // Strictly lower only: j ascends, so ties keep the lowest.
                if c < next_f[i] {
                    next_f[i] = c;
                    next_site[i] = site[k];
                }
            }
        }
        f = next_f;
        site = next_site;
    }
    let dist = f.iter().map(|&d| if d == u64::MAX { UNREACHABLE_DIST_SQ } else { d as u32 }).collect();
    EdtField::from_parts(dims, dist, site).expect("dims come from a valid grid")
}

/// The grids of the batch EDT suite: random ones of many shapes and
/// densities, empty and full ones, and lattices full of ties.
pub fn batch_edt_grids() -> Vec<Grid3<bool>> {
    let mut grids = Vec::new();
    let shapes = [[1, 1, 1], [7, 1, 1], [1, 9, 1], [1, 1, 11], [13, 6, 1], [16, 16, 16], [33, 17, 9], [5, 40, 21], [64, 3, 2], [20, 20, 70]];
    for (k, &dims) in shapes.iter().enumerate() {
        for (d, density) in [0.0, 0.002, 0.02, 0.2, 0.7, 1.0].into_iter().enumerate() {
            let seed = 1000 + 10 * k as u64 + d as u64;
            grids.push(random_grid(dims, density, seed).expect("valid dims"));
        }
    }
    // Lattices: every voxel has several nearest obstacles at once.
    for (step, dims) in [(2, [9, 9, 9]), (3, [10, 7, 12]), (4, [17, 13, 9]), (5, [31, 31, 31])] {
        let lattice = Grid3::from_fn(dims, |x, y, z| x % step == 0 && y % step == 0 && z % step == 0);
        grids.push(lattice.expect("valid dims"));
        let planes = Grid3::from_fn(dims, |x, y, z| (x + 2 * y + 3 * z) % (2 * step) == 0);
        grids.push(planes.expect("valid dims"));
    }
    // Two obstacles at the ends of long lines, the envelope's long case.
    let ends = Grid3::from_fn([300, 2, 3], |x, y, z| (x == 0 && y == 0) || (x == 299 && z == 2));
    grids.push(ends.expect("valid dims"));
    grids
}

/// Runs the batch EDT suite on `backend`, one output field reused across
/// grids of different sizes (as a mapper does); returns the voxels checked
/// or the first difference from [`separable_oracle`].
pub fn check_batch_edt(backend: &mut dyn BatchEdt) -> Result<usize, String> {
    let mut out = EdtField::empty();
    let mut checked = 0;
    for grid in batch_edt_grids() {
        backend.batch_edt(&grid, &mut out).map_err(|e| format!("grid {:?}: {e}", grid.dims()))?;
        compare_edt(&grid, &out)?;
        checked += grid.len();
    }
    Ok(checked)
}

/// Compares `got` with [`separable_oracle`] of `grid`, bit for bit.
pub fn compare_edt(grid: &Grid3<bool>, got: &EdtField) -> Result<(), String> {
    let want = separable_oracle(grid);
    if got.dims() != want.dims() {
        return Err(format!("dims {:?}, want {:?}", got.dims(), want.dims()));
    }
    let pairs = got.dist_sq_vox().iter().zip(got.nearest()).zip(want.dist_sq_vox().iter().zip(want.nearest()));
    for (i, (g, w)) in pairs.enumerate() {
        if g != w {
            return Err(format!(
                "grid {:?} voxel {:?}: (dist², nearest) = {g:?}, want {w:?}",
                grid.dims(),
                grid.coords(i)
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn oracle_distances_are_the_true_nearest_distances() {
        for grid in batch_edt_grids().into_iter().filter(|g| g.len() <= 6000) {
            let edt = separable_oracle(&grid);
            let sites: Vec<[usize; 3]> = (0..grid.len()).filter(|&i| grid.as_slice()[i]).map(|i| grid.coords(i)).collect();
            for i in 0..grid.len() {
                let c = grid.coords(i);
                let sq = |s: &[usize; 3]| (0..3).map(|a| (c[a].abs_diff(s[a]) as u32).pow(2)).sum::<u32>();
                let want = sites.iter().map(sq).min().unwrap_or(UNREACHABLE_DIST_SQ);
                assert_eq!(edt.dist_sq_vox()[i], want, "grid {:?} voxel {c:?}", grid.dims());
                if let Some(s) = edt.nearest_coords(i) {
                    assert!(grid.as_slice()[grid.linear(s)]);
                    assert_eq!(sq(&s), want);
                }
            }
        }
    }

    #[test]
    fn oracle_breaks_ties_towards_lower_positions() {
        // Obstacles at x = 0 and x = 4 of one row: x = 2 takes x = 0.
        let grid = Grid3::from_fn([5, 1, 1], |x, _, _| x == 0 || x == 4).expect("valid dims");
        assert_eq!(separable_oracle(&grid).nearest()[2], 0);
        // Obstacles at y = 0 and y = 2 of a column: y = 1 takes y = 0.
        let grid = Grid3::from_fn([1, 3, 1], |_, y, _| y != 1).expect("valid dims");
        assert_eq!(separable_oracle(&grid).nearest()[1], 0);
    }
}
