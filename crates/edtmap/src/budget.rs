//! How much memory a mapper needs, known before it allocates any of it,
//! so that a window too large for the machine is refused with an error
//! rather than an abort in the middle of a frame.
//!
//! The figures are per voxel of the local window and, in wavefront mode,
//! of the region the global integration works on (the window grown by the
//! cutoff on every side), from the buffers the stages hold; they were checked against the
//! peak resident memory of `edtmap run` (see `bench/memory.sh`).

use edtmap_core::{LocalVolume, MemoryBudget};

use crate::{MapError, MapperParams};

/// Bytes per window voxel held by the frame's stages: observation bits
/// (1), voxel states (1), the obstacle mask (1), the batch EDT's squared
/// distances and nearest obstacles (8).
const LOCAL_BYTES_PER_VOXEL: u64 = 1 + 1 + 1 + 8;
/// Extra bytes per window voxel for the second batch EDT when unknown
/// voxels count as occupied (mask and field again).
const UNKNOWN_BATCH_BYTES_PER_VOXEL: u64 = 1 + 8;
/// Bytes per window voxel of the global map once the window is mapped:
/// log-odds (4), squared distance and nearest obstacle (4 + 12), the
/// per-voxel share of block headers and hash slots, and the frame's
/// scratch lists (changed voxels and blocks).
const MAP_BYTES_PER_VOXEL: u64 = 4 + 16 + 9;
/// Bytes per voxel of the integration region: old, current and stamp
/// words (3 × 8), a dirty flag (1), and the wavefront queues and packing
/// tables, which measured up to 15 bytes per voxel.
const REGION_BYTES_PER_VOXEL: u64 = 3 * 8 + 1 + 15;
/// Bytes per window voxel, once mapped, of the exact mode's kept passes
/// (offsets along x, and along x and y, 2 + 4); its working lists follow
/// the frame's changes, and it has no integration region.
const SEPARABLE_BYTES_PER_VOXEL: u64 = 2 + 4;

/// The peak bytes a mapper with `params` holds for one frame, and the
/// sizes that make it, for messages.
pub(crate) fn peak_bytes(params: &MapperParams) -> Result<(u64, String), MapError> {
    let volume = LocalVolume::centred(&params.volume, params.voxel_size_m, [0.0; 3])?;
    let reach = params.global.cutoff(params.voxel_size_m)?.reach;
    let window: u64 = volume.dims.iter().map(|&d| d as u64).product();
    let pad = 2 * (i64::from(reach) + 1);
    let region: u64 = volume.dims.iter().map(|&d| (d as i64 + pad).max(0) as u64).product();
    let mut per_window = LOCAL_BYTES_PER_VOXEL + MAP_BYTES_PER_VOXEL;
    if params.edt.unknown_as_occupied {
        per_window += UNKNOWN_BATCH_BYTES_PER_VOXEL;
    }
    let region_bytes = match params.global.mode {
        edtmap_core::IntegrationMode::Wavefront => region.saturating_mul(REGION_BYTES_PER_VOXEL),
        edtmap_core::IntegrationMode::Exact => {
            per_window += SEPARABLE_BYTES_PER_VOXEL;
            0
        }
    };
    let bytes = window.saturating_mul(per_window).saturating_add(region_bytes);
    let [nx, ny, nz] = volume.dims;
    let what = format!(
        "a local window of {nx}×{ny}×{nz} voxels ({} m at {} m voxels) with a {} m cutoff",
        fmt_size(params.volume.size_m),
        params.voxel_size_m,
        params.global.max_distance_m
    );
    Ok((bytes, what))
}

fn fmt_size(size: [f64; 3]) -> String {
    format!("{}×{}×{}", size[0], size[1], size[2])
}

/// Refuses `params` when one frame would need more memory than the
/// budget: `params.max_memory_bytes` if set, else what the system has.
pub(crate) fn check(params: &MapperParams) -> Result<(), MapError> {
    let budget = params.max_memory_bytes.map_or_else(MemoryBudget::from_system, MemoryBudget::with_limit);
    let (bytes, what) = peak_bytes(params)?;
    let limit = budget.limit_bytes().map_or_else(|| "no limit".into(), edtmap_core::memory::format_bytes);
    tracing::info!(
        "memory: {what} needs about {} per frame (budget {limit})",
        edtmap_core::memory::format_bytes(bytes)
    );
    budget.check(
        &what,
        bytes,
        "make [occupancy] local_size_m smaller or voxel_size_m (--voxel-size) larger, lower [global] max_distance_m, \
         or raise the budget with --max-memory / [memory] max",
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_past_the_budget_is_refused_before_allocating() {
        let mut params = MapperParams::for_voxel_size(0.01);
        params.max_memory_bytes = Some(1 << 30);
        let err = check(&params).expect_err("1000×1000×300 voxels do not fit in 1 GiB");
        let text = err.to_string();
        assert!(
            text.contains("1000×1000×300") && text.contains("voxel_size_m") && text.contains("--max-memory"),
            "{text}"
        );
        params.voxel_size_m = 0.2;
        check(&params).expect("50×50×15 voxels fit");
    }
}
