//! The backend conformance suite (`edtmap_conformance`) on the GPU,
//! through the `Backend` trait: the same oracles as the CPU, bit for bit.
//! Without an adapter the tests say so and pass, unless
//! `EDTMAP_REQUIRE_GPU=1` (CI sets it, with lavapipe installed), where a
//! missing adapter fails them.

mod common;

use edtmap_conformance::check_projection_bits;

edtmap_conformance::conformance_tests!(common::gpu_or_skip("GPU conformance"));

/// The device's own projection bytes, before the host decides: right
/// wherever it decides, and uncertain on few voxels.
#[test]
fn projection_kernel_leaves_few_voxels_uncertain() {
    let Some(mut gpu) = common::gpu_or_skip("GPU conformance") else { return };
    eprintln!("device: {}", edtmap_core::Backend::name(&gpu));
    let tally = check_projection_bits(|job, bits| gpu.project_bits(job, bits).map_err(|e| e.to_string()))
        .unwrap_or_else(|e| panic!("{e}"))
        .expect("the GPU projects depth images, planar scans and LiDAR scans itself");
    for (kind, (voxels, uncertain)) in
        [("depth", tally.depth), ("planar", tally.planar), ("lidar", tally.lidar), ("aligned", tally.aligned)]
    {
        let share = uncertain as f64 / voxels as f64;
        eprintln!("{kind}: {uncertain} of {voxels} voxels uncertain ({:.4} %)", 100.0 * share);
        // Aligned cases put whole layers of voxels on thresholds.
        assert!(kind == "aligned" || share < 0.01, "{kind}: too many uncertain voxels");
    }
}

/// The device counters see a batch EDT's traffic as it is: the mask up (a
/// bit per voxel, padded to a word, plus the parameter block), the field
/// down (8 bytes per voxel), four dispatches (the scan along x from the
/// mask, the scan along y, a transpose, the scan along z) in one submission,
/// and its device time, where the adapter has timestamps.
#[test]
fn device_counters_count_a_batch_edt() {
    use edtmap_core::{Backend, BatchEdt, EdtField, Grid3};
    let Some(mut gpu) = common::gpu_or_skip("device counters") else { return };
    let dims = [37, 21, 9];
    let n = 37 * 21 * 9;
    let mask = Grid3::from_fn(dims, |x, y, z| (7 * x + 3 * y + z) % 11 == 0).expect("grid");
    let before = gpu.device_counters().expect("a device backend counts");
    let mut out = EdtField::empty();
    gpu.batch_edt(&mask, &mut out).expect("batch EDT");
    let d = gpu.device_counters().expect("counters").since(before);
    assert_eq!(d.downloaded_bytes, 8 * n as u64);
    assert_eq!((d.dispatches, d.submissions), (4, 1));
    let bits = 4 * (n as u64).div_ceil(32);
    assert!(d.uploaded_bytes >= bits && d.uploaded_bytes <= bits + 4 * 256, "{d:?}");
    // Device time lands on the batch EDT's stage alone, where there are
    // timestamps at all.
    eprintln!("timestamps: {}, {d:?}", gpu.context().has_timestamps());
    assert_eq!(gpu.context().has_timestamps(), d.batch_edt_ns > 0, "{d:?}");
    assert_eq!((d.occupancy_ns, d.integrate_ns), (0, 0));
}
