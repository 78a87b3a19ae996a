//! What every GPU test shares: opening the backend.

use edtmap_gpu::GpuBackend;

/// The GPU backend, or None (and a note) where there is no adapter; with
/// `EDTMAP_REQUIRE_GPU=1` (CI, with lavapipe installed) a missing adapter
/// fails the test instead.
pub(crate) fn gpu_or_skip(what: &str) -> Option<GpuBackend> {
    match GpuBackend::new() {
        Ok(b) => Some(b),
        Err(e) if std::env::var("EDTMAP_REQUIRE_GPU").is_ok_and(|v| v == "1") => panic!("EDTMAP_REQUIRE_GPU=1 but {e}"),
        Err(e) => {
            eprintln!("skipping {what}: {e}");
            None
        }
    }
}
