//! The global EDT after every step of random occupancy changes in a window
//! that moves over the map, against a brute-force EDT of the whole map.

use edtmap_core::{
    Connectivity, EdtMap, GlobalParams, IntegrationMode, LocalVolume, LogOdds, OccupancyMap, OccupancyParams, Obstacles,
    StaticMap, VoxelIndex, FAR_DIST_SQ,
};
use edtmap_cpu::edt::{edt_with, ScanLayout};
use edtmap_cpu::integrate::Integrator;
use proptest::prelude::*;

const WORLD_MIN: [i32; 3] = [-20, -14, -9];
const WORLD_DIMS: [i32; 3] = [36, 28, 14];
const WINDOW_DIMS: [usize; 3] = [14, 12, 8];
const VOXEL_M: f64 = 0.1;

struct SplitMix(u64);
impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: i32) -> i32 {
        (self.next() % n as u64) as i32
    }
}

/// The world: occupancy set through log-odds, as the mapper leaves it.
struct World {
    lo: LogOdds,
    map: OccupancyMap,
    fixed: StaticMap,
    obstacles: Vec<VoxelIndex>,
}

impl World {
    fn new() -> Self {
        let lo = OccupancyParams::default().log_odds().expect("defaults");
        World { lo, map: OccupancyMap::new(VOXEL_M).expect("size"), fixed: StaticMap::new(VOXEL_M).expect("size"), obstacles: Vec::new() }
    }
    fn obstacles(&self) -> Obstacles<'_> {
        Obstacles { occupancy: &self.map, log_odds: &self.lo, fixed: &self.fixed, unknown_as_occupied: false }
    }
    fn set(&mut self, v: VoxelIndex, occupied: bool) {
        let value = if occupied { self.lo.max } else { self.lo.min };
        self.map.get_or_insert(v.block()).log_odds[v.offset_in_block()] = value;
        self.obstacles.retain(|&o| o != v);
        if occupied {
            self.obstacles.push(v);
        }
    }
    /// One step: a window somewhere in the world, obstacles toggled inside it.
    fn step(&mut self, rng: &mut SplitMix) -> LocalVolume {
        let origin = VoxelIndex([0, 1, 2].map(|a| WORLD_MIN[a] + rng.below(WORLD_DIMS[a] - WINDOW_DIMS[a] as i32 + 1)));
        let window = LocalVolume { origin, dims: WINDOW_DIMS, voxel_size_m: VOXEL_M };
        let inside = |rng: &mut SplitMix| VoxelIndex([0, 1, 2].map(|a| origin.0[a] + rng.below(WINDOW_DIMS[a] as i32)));
        for _ in 0..rng.below(12) {
            let v = inside(rng);
            self.set(v, !self.obstacles.contains(&v));
        }
        if rng.below(3) == 0 {
            // A short wall appears or vanishes, so Voronoi cells change shape.
            let (v, occupied) = (inside(rng), rng.below(2) == 0);
            for k in 0..6 {
                let w = VoxelIndex([v.0[0], v.0[1] + k, v.0[2]]);
                if window.local(w).is_some() {
                    self.set(w, occupied);
                }
            }
        }
        window
    }
    /// Brute-force truncated squared distance of `v`.
    fn truth(&self, v: VoxelIndex, max: u32) -> u32 {
        let best = self.obstacles.iter().map(|o| dist_sq(v, *o)).min().unwrap_or(u64::MAX);
        if best > u64::from(max) { FAR_DIST_SQ } else { best as u32 }
    }
}

fn dist_sq(a: VoxelIndex, b: VoxelIndex) -> u64 {
    (0..3).map(|i| (i64::from(a.0[i]) - i64::from(b.0[i])).pow(2) as u64).sum()
}

/// Largest excess (voxels) of the stored distance over the truth, checking
/// on the way that every stored obstacle is real and at the stored distance.
fn check(world: &World, edt: &EdtMap, params: &GlobalParams) -> Result<f64, TestCaseError> {
    let cutoff = params.cutoff(VOXEL_M).expect("valid");
    let r = cutoff.reach + 2;
    let mut worst: f64 = 0.0;
    for z in WORLD_MIN[2] - r..WORLD_MIN[2] + WORLD_DIMS[2] + r {
        for y in WORLD_MIN[1] - r..WORLD_MIN[1] + WORLD_DIMS[1] + r {
            for x in WORLD_MIN[0] - r..WORLD_MIN[0] + WORLD_DIMS[0] + r {
                let v = VoxelIndex([x, y, z]);
                let truth = world.truth(v, cutoff.max_dist_sq);
                let (stored, nearest) = edt.entry(v);
                if stored != FAR_DIST_SQ {
                    prop_assert!(world.obstacles.contains(&nearest), "{v:?}: stored obstacle {nearest:?} is not one");
                    prop_assert_eq!(dist_sq(v, nearest), u64::from(stored), "{:?}: stored distance is not that of its obstacle", v);
                }
                prop_assert!(stored >= truth || truth == FAR_DIST_SQ && stored == FAR_DIST_SQ, "{v:?}: stored {stored} below the truth {truth}");
                let reach = f64::from(cutoff.max_dist_sq).sqrt();
                let as_vox = |d: u32| if d == FAR_DIST_SQ { reach } else { f64::from(d).sqrt() };
                worst = worst.max(as_vox(stored) - as_vox(truth));
            }
        }
    }
    Ok(worst)
}

fn run(seed: u64, params: &GlobalParams, steps: usize) -> Result<f64, TestCaseError> {
    let mut rng = SplitMix(seed);
    let mut world = World::new();
    let mut edt = EdtMap::new(VOXEL_M).expect("size");
    let mut integrator = Integrator::new(params, VOXEL_M).expect("valid");
    let mut worst: f64 = 0.0;
    for _ in 0..steps {
        let window = world.step(&mut rng);
        let obstacles = world.obstacles();
        let mask = edtmap_core::Grid3::from_fn(window.dims, |x, y, z| obstacles.contains(window.world([x, y, z]))).expect("dims");
        let batch = edt_with(&mask, |&o| o, ScanLayout::default()).expect("batch");
        integrator.integrate(&mut edt, &obstacles, &window, &batch).expect("integrate");
        worst = worst.max(check(&world, &edt, params)?);
    }
    Ok(worst)
}

fn params(mode: IntegrationMode, connectivity: Connectivity, max_distance_m: f64) -> GlobalParams {
    GlobalParams { mode, connectivity, max_distance_m, ..Default::default() }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn exact_mode_is_exact(seed in any::<u64>(), conn in 0usize..3, cutoff in 2usize..8) {
        let c = [Connectivity::Six, Connectivity::Eighteen, Connectivity::TwentySix][conn];
        let worst = run(seed, &params(IntegrationMode::Exact, c, cutoff as f64 * VOXEL_M), 12)?;
        prop_assert_eq!(worst, 0.0);
    }

    #[test]
    fn wavefront_stays_within_its_bound(seed in any::<u64>(), conn in 0usize..3, cutoff in 2usize..8) {
        let c = [Connectivity::Six, Connectivity::Eighteen, Connectivity::TwentySix][conn];
        let worst = run(seed, &params(IntegrationMode::Wavefront, c, cutoff as f64 * VOXEL_M), 12)?;
        // Measured worst excess over 90 sequences (`wavefront_error_report`):
        // 0.17 voxels with 6 neighbours, 0.05 with 18, none with 26. The bounds
        // leave room for sequences the report did not draw; the error comes
        // only from Voronoi cells the neighbourhood does not connect.
        let bound = match c { Connectivity::Six => 0.5, Connectivity::Eighteen => 0.25, Connectivity::TwentySix => 0.25 };
        prop_assert!(worst <= bound, "excess {worst} voxels over the bound {bound}");
    }
}

#[test]
#[ignore = "a measurement (20 s): cargo test -p edtmap-cpu --test integrate_oracle -- --ignored --nocapture"]
fn wavefront_error_report() {
    // Not an assertion of the bound (the property test does that): prints the
    // worst excess per connectivity over many sequences, for the README.
    for c in [Connectivity::Six, Connectivity::Eighteen, Connectivity::TwentySix] {
        let mut worst: f64 = 0.0;
        for seed in 0..30 {
            worst = worst.max(run(seed, &params(IntegrationMode::Wavefront, c, 1.0), 10).expect("checks hold"));
        }
        println!("connectivity {}: worst excess {worst:.4} voxels", u8::from(c));
    }
}
