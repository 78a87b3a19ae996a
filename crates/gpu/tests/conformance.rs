//! The backend conformance suite (`edtmap_sim::conformance`) on the GPU,
//! through the `Backend` trait: the same oracles as the CPU, bit for bit.
//! Without an adapter the tests say so and pass, unless
//! `EDTMAP_REQUIRE_GPU=1` (CI sets it, with lavapipe installed), where a
//! missing adapter fails them.

mod common;

use edtmap_sim::conformance::check_projection_bits;

edtmap_sim::conformance_tests!(common::gpu_or_skip("GPU conformance"));

/// The device's own projection bytes, before the host decides: right
/// wherever it decides, and uncertain on few voxels.
#[test]
fn projection_kernel_leaves_few_voxels_uncertain() {
    let Some(mut gpu) = common::gpu_or_skip("GPU conformance") else { return };
    eprintln!("device: {}", edtmap_core::Backend::name(&gpu));
    let tally = check_projection_bits(|job, bits| gpu.project_bits(job, bits).map_err(|e| e.to_string()))
        .unwrap_or_else(|e| panic!("{e}"))
        .expect("the GPU projects depth images and planar scans itself");
    for (kind, (voxels, uncertain)) in [("depth", tally.depth), ("planar", tally.planar), ("aligned", tally.aligned)] {
        let share = uncertain as f64 / voxels as f64;
        eprintln!("{kind}: {uncertain} of {voxels} voxels uncertain ({:.4} %)", 100.0 * share);
        // Aligned cases put whole layers of voxels on thresholds.
        assert!(kind == "aligned" || share < 0.01, "{kind}: too many uncertain voxels");
    }
}
