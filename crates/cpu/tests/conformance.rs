//! The backend conformance suite (`edtmap_sim::conformance`) on the CPU,
//! with every scan layout: all must give the same integer results.

use edtmap_cpu::edt::ScanLayout;
use edtmap_cpu::CpuBackend;
use edtmap_core::{LocalVolume, VoxelIndex, OBS_HIT, OBS_MISS, OBS_NONE, PROJ_UNCERTAIN};
use edtmap_cpu::occupancy::{cast_fixed, decide_uncertain, project_volume, Observations, OgmOptions};
use edtmap_sim::conformance::{check_batch_edt, check_projection, projection_cases, raycast_cases, raycast_reference};

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

#[test]
fn projection_matches_the_definition() {
    // The CPU backend leaves projection to the occupancy stage's own loop.
    assert_eq!(check_projection(&mut CpuBackend::default()), Ok(None));
    let mut rays = Vec::new();
    for (n, case) in projection_cases(6, 6).iter().enumerate() {
        let job = case.job();
        let geom = job.voxel_to_sensor();
        // The host's decision of voxels a backend left uncertain.
        let mut bits = vec![PROJ_UNCERTAIN; case.volume.len()];
        assert_eq!(decide_uncertain(&job, &mut bits), bits.len());
        // The CPU's loop, returns scattered as hits too.
        let opts = OgmOptions { free_margin_m: case.free_margin_m, clear_no_return: case.clear_no_return, planar_half_thickness_m: case.planar_half_thickness_m, ..OgmOptions::for_voxel_size(case.volume.voxel_size_m) };
        let obs = Observations::new(case.volume);
        project_volume(&obs, &case.sensor, &case.frame, &opts, &mut rays);
        let [nx, ny, _] = case.volume.dims;
        for (i, &b) in bits.iter().enumerate() {
            let c = [i % nx, (i / nx) % ny, i / (nx * ny)];
            let miss = job.is_miss(&geom, c);
            assert_eq!(b, if miss { OBS_MISS } else { OBS_NONE }, "case {n} voxel {c:?}: decided");
            let got = obs.get(i);
            assert!(got == OBS_HIT || got == b, "case {n} voxel {c:?}: projected {got}, defined {b}");
        }
    }
}
