//! The backend conformance suite, written once and run against every
//! backend through the [`Backend`] trait ([`conformance_tests!`](crate::conformance_tests)
//! instantiates it in `crates/cpu/tests/conformance.rs` and
//! `crates/gpu/tests/conformance.rs`): each check compares a backend's
//! integer results with an independent oracle, bit for bit, so backends
//! that pass agree with each other exactly.

pub mod config_text;
mod projection;

pub use projection::{check_projection, check_projection_bits, projection_cases, ProjectionCase, ProjectionTally};

use edtmap::stages::IntegrationStage;
use edtmap_core::fixed_ray::{fixed_scale, setup_ray, walk, FixedRay, NO_HIT};
use edtmap_core::{Backend, Connectivity, IntegrationMode, Observations, OBS_HIT, OBS_MISS};
use edtmap_core::{
    BatchEdt, EdtField, EdtMap, FixedMap, GlobalParams, Grid3, LocalVolume, LogOdds, Obstacles, OccupancyMap,
    OccupancyParams, VoxelIndex, FAR_DIST_SQ, NO_SITE, UNREACHABLE_DIST_SQ,
};
use edtmap_sim::random_grid;

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
    let shapes = [
        [1, 1, 1],
        [7, 1, 1],
        [1, 9, 1],
        [1, 1, 11],
        [13, 6, 1],
        [16, 16, 16],
        [33, 17, 9],
        [5, 40, 21],
        [64, 3, 2],
        [20, 20, 70],
    ];
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

/// Rays of the ray-casting suite for volumes of several shapes: random
/// segments inside, through and outside the volume, returns and
/// no-returns, half of their coordinates on voxel faces and edges so that
/// the walk's tie rules matter. Returns (rays, scale, dims) per volume.
pub fn raycast_cases() -> Vec<(Vec<FixedRay>, u32, [usize; 3])> {
    let mut rng = SplitMix(77);
    let mut cases = Vec::new();
    for dims in [[1, 1, 1], [9, 1, 1], [16, 16, 16], [33, 20, 7], [200, 3, 2]] {
        let q = fixed_scale(dims).expect("small volume");
        let coord = |rng: &mut SplitMix, n: usize| {
            let span = n as i32 + 6;
            let base = f64::from(rng.below(span)) - 3.0;
            match rng.below(4) {
                0 => base,
                1 => base + 0.5,
                _ => base + f64::from(rng.below(1 << 20)) / f64::from(1 << 20),
            }
        };
        let rays = (0..3000)
            .map(|_| {
                let a = [0, 1, 2].map(|k| coord(&mut rng, dims[k]));
                let b = [0, 1, 2].map(|k| coord(&mut rng, dims[k]));
                let is_return = rng.below(3) != 0;
                let t = if is_return { 1.0 - f64::from(rng.below(100)) / 400.0 } else { 1.0 };
                let free_end = [0, 1, 2].map(|k| a[k] + (b[k] - a[k]) * t);
                setup_ray(a, free_end, b, is_return, dims, q)
            })
            .collect();
        cases.push((rays, q, dims));
    }
    cases
}

/// Observation bits of `rays` by the walk's definition
/// (`edtmap_core::fixed_ray::walk`), one byte per voxel.
pub fn raycast_reference(rays: &[FixedRay], q: u32, dims: [usize; 3]) -> Vec<u8> {
    let mut bits = vec![0u8; dims.iter().product()];
    for ray in rays {
        walk(ray, dims, q, |i| bits[i as usize] |= OBS_MISS);
        if ray.hit != NO_HIT && (ray.hit as usize) < bits.len() {
            bits[ray.hit as usize] |= OBS_HIT;
        }
    }
    bits
}

/// Runs the ray-casting suite on `backend` through
/// [`Backend::cast_rays`]: the voxels checked, or the first difference
/// from the walk's definition (a hit wins over a miss).
pub fn check_raycast(backend: &mut dyn Backend) -> Result<usize, String> {
    let mut checked = 0;
    for (rays, q, dims) in raycast_cases() {
        let volume = LocalVolume { origin: VoxelIndex([0, 0, 0]), dims, voxel_size_m: 0.1 };
        let obs = Observations::new(volume);
        backend.cast_rays(&rays, q, &obs).map_err(|e| format!("volume {dims:?}: {e}"))?;
        let want = raycast_reference(&rays, q, dims);
        for (i, &w) in want.iter().enumerate() {
            let resolved = if w & OBS_HIT != 0 { OBS_HIT } else { w & OBS_MISS };
            if obs.get(i) != resolved {
                return Err(format!("volume {dims:?} voxel {i}: observed {}, want {resolved}", obs.get(i)));
            }
        }
        checked += want.len();
    }
    Ok(checked)
}

/// Runs the integration suite on `backend` through
/// [`edtmap::stages::IntegrationStage`], in both modes, every
/// connectivity and cutoffs of 2 to 7 voxels: after every step the global
/// EDT must pass [`IntegrationWorld::check`] (every stored obstacle real,
/// at the stored distance, none nearer missed), and in exact mode equal
/// the truth everywhere. Returns the steps checked.
pub fn check_integration(backend: &mut dyn Backend) -> Result<usize, String> {
    let conns = [Connectivity::Six, Connectivity::Eighteen, Connectivity::TwentySix];
    let mut steps = 0;
    for mode in [IntegrationMode::Wavefront, IntegrationMode::Exact] {
        for seed in 0..12u64 {
            let connectivity = conns[seed as usize % 3];
            let cutoff_vox = 2 + seed % 6;
            let params = GlobalParams {
                mode,
                connectivity,
                max_distance_m: cutoff_vox as f64 * IntegrationWorld::VOXEL_M,
                ..Default::default()
            };
            let stage = IntegrationStage::new(&params, IntegrationWorld::VOXEL_M).map_err(|e| e.to_string())?;
            let mut world = IntegrationWorld::new(seed);
            let mut map = EdtMap::new();
            let mut batch = EdtField::empty();
            for step in 0..10 {
                let at = format!(
                    "{mode:?}, seed {seed}, {} neighbours, cutoff {cutoff_vox}, step {step}",
                    u8::from(connectivity)
                );
                let (window, mask) = world.step();
                backend.batch_edt(&mask, &mut batch).map_err(|e| format!("{at}: {e}"))?;
                stage
                    .merge_window(backend, &mut map, world.obstacles(), &window, &batch)
                    .map_err(|e| format!("{at}: {e}"))?;
                let worst = world.check(&map, &params).map_err(|e| format!("{at}: {e}"))?;
                if mode == IntegrationMode::Exact && worst != 0.0 {
                    return Err(format!("{at}: a distance {worst} voxels above the truth in exact mode"));
                }
                steps += 1;
            }
        }
    }
    Ok(steps)
}

/// The conformance suite as `#[test]` functions, one per check, for the
/// backend that `$make` (an expression giving `Option<B>`; `None` skips
/// the tests, for a machine without the device) makes afresh for each.
#[macro_export]
macro_rules! conformance_tests {
    ($make:expr) => {
        #[test]
        fn batch_edt_matches_the_separable_oracle() {
            let Some(mut backend) = $make else { return };
            let checked = $crate::check_batch_edt(&mut backend).unwrap_or_else(|e| panic!("{e}"));
            assert!(checked > 100_000);
        }

        #[test]
        fn ray_casting_matches_the_walk_definition() {
            let Some(mut backend) = $make else { return };
            let checked = $crate::check_raycast(&mut backend).unwrap_or_else(|e| panic!("{e}"));
            assert!(checked > 9_000);
        }

        #[test]
        fn projection_matches_the_definition() {
            let Some(mut backend) = $make else { return };
            let checked = $crate::check_projection(&mut backend).unwrap_or_else(|e| panic!("{e}"));
            assert!(checked > 100_000);
        }

        #[test]
        fn integration_matches_brute_force() {
            let Some(mut backend) = $make else { return };
            let steps = $crate::check_integration(&mut backend).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(steps, 240);
        }
    };
}

/// The world of the integration suite: a box of voxels whose occupancy
/// (set through log-odds, as the mapper leaves it) changes in a window
/// that jumps around, step after step; seeded, so every backend sees the
/// same sequence.
#[derive(Debug)]
pub struct IntegrationWorld {
    lo: LogOdds,
    map: OccupancyMap,
    fixed: FixedMap,
    /// Every obstacle voxel.
    pub obstacles: Vec<VoxelIndex>,
    rng: SplitMix,
}

impl IntegrationWorld {
    /// The lowest voxel of the box the windows move in.
    pub const MIN: [i32; 3] = [-20, -14, -9];
    /// The box's size in voxels.
    pub const DIMS: [i32; 3] = [36, 28, 14];
    /// The window's size in voxels.
    pub const WINDOW: [usize; 3] = [14, 12, 8];
    /// Voxel size, metres.
    pub const VOXEL_M: f64 = 0.1;

    /// An empty world whose steps follow `seed`.
    pub fn new(seed: u64) -> Self {
        let lo = OccupancyParams::default().log_odds().expect("default parameters are valid");
        IntegrationWorld {
            lo,
            map: OccupancyMap::new(),
            fixed: FixedMap::new(),
            obstacles: Vec::new(),
            rng: SplitMix(seed),
        }
    }

    /// The EDT's view of the occupancy.
    pub fn obstacles(&self) -> Obstacles<'_> {
        Obstacles { occupancy: &self.map, log_odds: &self.lo, fixed: &self.fixed, unknown_as_occupied: false }
    }

    fn set(&mut self, v: VoxelIndex, occupied: bool) {
        let value = if occupied { self.lo.max } else { self.lo.min };
        self.map.get_or_insert(v.block()).log_odds.set(v.offset_in_block(), value);
        self.obstacles.retain(|&o| o != v);
        if occupied {
            self.obstacles.push(v);
        }
    }

    /// One step: a window somewhere in the box, obstacles toggled inside
    /// it, and sometimes a short wall appearing or vanishing (so Voronoi
    /// cells change shape). Returns the window and its obstacle mask.
    pub fn step(&mut self) -> (LocalVolume, Grid3<bool>) {
        let rng = &mut self.rng;
        let origin =
            VoxelIndex([0, 1, 2].map(|a| Self::MIN[a] + rng.below(Self::DIMS[a] - Self::WINDOW[a] as i32 + 1)));
        let window = LocalVolume { origin, dims: Self::WINDOW, voxel_size_m: Self::VOXEL_M };
        let inside =
            |rng: &mut SplitMix| VoxelIndex([0, 1, 2].map(|a| origin.0[a] + rng.below(Self::WINDOW[a] as i32)));
        let mut toggles = Vec::new();
        for _ in 0..self.rng.below(12) {
            toggles.push((inside(&mut self.rng), None));
        }
        if self.rng.below(3) == 0 {
            let (v, occupied) = (inside(&mut self.rng), self.rng.below(2) == 0);
            for k in 0..6 {
                let w = VoxelIndex([v.0[0], v.0[1] + k, v.0[2]]);
                if window.local(w).is_some() {
                    toggles.push((w, Some(occupied)));
                }
            }
        }
        for (v, occupied) in toggles {
            let occupied = occupied.unwrap_or(!self.obstacles.contains(&v));
            self.set(v, occupied);
        }
        let obstacles = self.obstacles();
        let mask =
            Grid3::from_fn(window.dims, |x, y, z| obstacles.contains(window.world([x, y, z]))).expect("valid dims");
        (window, mask)
    }

    /// Brute-force squared distance of `v`, `FAR_DIST_SQ` beyond `max`; to
    /// the obstacles of `v`'s layer only where `planar`.
    pub fn truth(&self, v: VoxelIndex, max: u32, planar: bool) -> u32 {
        let in_reach = |o: &&VoxelIndex| !planar || o.0[2] == v.0[2];
        let best = self.obstacles.iter().filter(in_reach).map(|o| dist_sq(v, *o)).min().unwrap_or(u64::MAX);
        if best > u64::from(max) {
            FAR_DIST_SQ
        } else {
            best as u32
        }
    }

    /// Checks `edt` against brute force over the box and a margin: every
    /// stored obstacle is real and at the stored distance (and in the
    /// voxel's layer, on a planar map), no distance is below the truth. Returns the largest excess over the truth, voxels.
    pub fn check(&self, edt: &EdtMap, params: &GlobalParams) -> Result<f64, String> {
        let cutoff = params.cutoff(Self::VOXEL_M).map_err(|e| e.to_string())?;
        let r = cutoff.reach + 2;
        let reach = f64::from(cutoff.max_dist_sq).sqrt();
        let as_vox = |d: u32| if d == FAR_DIST_SQ { reach } else { f64::from(d).sqrt() };
        let mut worst: f64 = 0.0;
        for z in Self::MIN[2] - r..Self::MIN[2] + Self::DIMS[2] + r {
            for y in Self::MIN[1] - r..Self::MIN[1] + Self::DIMS[1] + r {
                for x in Self::MIN[0] - r..Self::MIN[0] + Self::DIMS[0] + r {
                    let v = VoxelIndex([x, y, z]);
                    let truth = self.truth(v, cutoff.max_dist_sq, cutoff.planar);
                    let (stored, nearest) = edt.entry(v);
                    if stored != FAR_DIST_SQ {
                        if !self.obstacles.contains(&nearest) {
                            return Err(format!("{v:?}: stored obstacle {nearest:?} is not one"));
                        }
                        if cutoff.planar && nearest.0[2] != v.0[2] {
                            return Err(format!("{v:?}: stored obstacle {nearest:?} is not in its layer"));
                        }
                        if dist_sq(v, nearest) != u64::from(stored) {
                            return Err(format!(
                                "{v:?}: stored distance {stored} is not that of its obstacle {nearest:?}"
                            ));
                        }
                    }
                    if stored < truth && !(truth == FAR_DIST_SQ && stored == FAR_DIST_SQ) {
                        return Err(format!("{v:?}: stored {stored} below the truth {truth}"));
                    }
                    worst = worst.max(as_vox(stored) - as_vox(truth));
                }
            }
        }
        Ok(worst)
    }
}

fn dist_sq(a: VoxelIndex, b: VoxelIndex) -> u64 {
    (0..3).map(|i| (i64::from(a.0[i]) - i64::from(b.0[i])).pow(2) as u64).sum()
}

/// SplitMix64: a small seeded generator, the same on every platform (for
/// the suite and the tests that draw cases as it does).
#[derive(Debug)]
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: i32) -> i32 {
        (self.next_u64() % n as u64) as i32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn oracle_distances_are_the_true_nearest_distances() {
        for grid in batch_edt_grids().into_iter().filter(|g| g.len() <= 6000) {
            let edt = separable_oracle(&grid);
            let sites: Vec<[usize; 3]> =
                (0..grid.len()).filter(|&i| grid.as_slice()[i]).map(|i| grid.coords(i)).collect();
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
