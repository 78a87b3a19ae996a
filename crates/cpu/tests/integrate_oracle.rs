//! The global EDT after every step of random occupancy changes in a window
//! that moves over the map, against a brute-force EDT of the whole map.

use edtmap::stages::IntegrationStage;
use edtmap_conformance::IntegrationWorld;
use edtmap_core::{Connectivity, EdtMap, GlobalParams, IntegrationMode};
use edtmap_cpu::edt::{edt_with, ScanLayout};
use edtmap_cpu::CpuBackend;
use proptest::prelude::*;

/// Runs `steps` steps of the world of `seed`; returns the worst excess.
fn run(seed: u64, params: &GlobalParams, steps: usize) -> Result<f64, TestCaseError> {
    let mut world = IntegrationWorld::new(seed);
    let mut edt = EdtMap::new();
    let stage = IntegrationStage::new(params, IntegrationWorld::VOXEL_M).expect("valid");
    let mut cpu = CpuBackend::default();
    let mut worst: f64 = 0.0;
    for _ in 0..steps {
        let (window, mask) = world.step();
        let batch = edt_with(&mask, |&o| o, ScanLayout::default()).expect("batch");
        stage.merge_window(&mut cpu, &mut edt, world.obstacles(), &window, &batch).expect("integrate");
        worst = worst.max(world.check(&edt, params).map_err(TestCaseError::fail)?);
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
        let worst = run(seed, &params(IntegrationMode::Exact, c, cutoff as f64 * IntegrationWorld::VOXEL_M), 12)?;
        prop_assert_eq!(worst, 0.0);
    }

    /// A planar map: distances within each layer, none across layers,
    /// with obstacles toggled in every layer of the box.
    #[test]
    fn planar_exact_mode_is_exact_in_every_layer(seed in any::<u64>(), cutoff in 2usize..8) {
        let p = GlobalParams { planar: true, ..params(IntegrationMode::Exact, Connectivity::TwentySix, cutoff as f64 * IntegrationWorld::VOXEL_M) };
        let worst = run(seed, &p, 12)?;
        prop_assert_eq!(worst, 0.0);
    }

    #[test]
    fn wavefront_stays_within_its_bound(seed in any::<u64>(), conn in 0usize..3, cutoff in 2usize..8) {
        let c = [Connectivity::Six, Connectivity::Eighteen, Connectivity::TwentySix][conn];
        let worst = run(seed, &params(IntegrationMode::Wavefront, c, cutoff as f64 * IntegrationWorld::VOXEL_M), 12)?;
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
    // worst excess per connectivity over many sequences, for docs/how-it-works.md.
    for c in [Connectivity::Six, Connectivity::Eighteen, Connectivity::TwentySix] {
        let mut worst: f64 = 0.0;
        for seed in 0..30 {
            worst = worst.max(run(seed, &params(IntegrationMode::Wavefront, c, 1.0), 10).expect("checks hold"));
        }
        println!("connectivity {}: worst excess {worst:.4} voxels", u8::from(c));
    }
}
