//! The backend conformance suite (`edtmap_sim::conformance`) on the CPU,
//! with every scan layout: all must give the same integer results.

use edtmap_cpu::edt::ScanLayout;
use edtmap_cpu::CpuBackend;
use edtmap_core::{LocalVolume, VoxelIndex, OBS_HIT, OBS_MISS};
use edtmap_cpu::occupancy::{cast_fixed, Observations};
use edtmap_sim::conformance::{check_batch_edt, raycast_cases, raycast_reference};

#[test]
fn batch_edt_matches_the_separable_oracle_in_every_layout() {
    let layouts = [
        ScanLayout::PerLine,
        ScanLayout::TiledEnvelope { lanes: 5 },
        ScanLayout::Tiled { lanes: 3 },
        ScanLayout::Tiled { lanes: 16 },
        ScanLayout::default(),
    ];
    for layout in layouts {
        let mut backend = CpuBackend { layout };
        let checked = check_batch_edt(&mut backend).unwrap_or_else(|e| panic!("{layout:?}: {e}"));
        assert!(checked > 100_000);
    }
}

#[test]
fn ray_casting_matches_the_walk_definition() {
    for (rays, q, dims) in raycast_cases() {
        let volume = LocalVolume { origin: VoxelIndex([0, 0, 0]), dims, voxel_size_m: 0.1 };
        let obs = Observations::new(volume);
        cast_fixed(&obs, &rays, q);
        let want = raycast_reference(&rays, q, dims);
        for (i, &w) in want.iter().enumerate() {
            // A voxel's observation: a hit wins over a miss.
            let resolved = if w & OBS_HIT != 0 { OBS_HIT } else { w & OBS_MISS };
            assert_eq!(obs.get(i), resolved, "volume {dims:?} voxel {i}");
        }
    }
}
