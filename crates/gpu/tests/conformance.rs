//! The backend conformance suite (`edtmap_sim::conformance`) on the GPU:
//! the same oracles as the CPU, bit for bit. Without an adapter the tests
//! say so and pass, unless `EDTMAP_REQUIRE_GPU=1` (CI sets it, with
//! lavapipe installed), where a missing adapter fails them.

use edtmap_gpu::GpuBackend;
use edtmap_sim::conformance::{check_batch_edt, check_raycast};

/// The backend, or None (and a note) where there is no adapter.
fn backend() -> Option<GpuBackend> {
    match GpuBackend::new() {
        Ok(b) => Some(b),
        Err(e) if std::env::var("EDTMAP_REQUIRE_GPU").is_ok_and(|v| v == "1") => panic!("EDTMAP_REQUIRE_GPU=1 but {e}"),
        Err(e) => {
            eprintln!("skipping GPU conformance: {e}");
            None
        }
    }
}

#[test]
fn batch_edt_matches_the_separable_oracle() {
    let Some(mut gpu) = backend() else { return };
    eprintln!("device: {}", edtmap_core::Backend::name(&gpu));
    let checked = check_batch_edt(&mut gpu).unwrap_or_else(|e| panic!("{e}"));
    assert!(checked > 100_000);
}

#[test]
fn ray_casting_matches_the_walk_definition() {
    let Some(mut gpu) = backend() else { return };
    let checked = check_raycast(&mut gpu).unwrap_or_else(|e| panic!("{e}"));
    assert!(checked.is_some_and(|n| n > 9_000), "the GPU casts rays itself");
}
