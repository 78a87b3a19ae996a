//! The CPU backend of edtmap: every device stage of the pipeline
//! ([`edtmap_core::Backend`]) on all cores with rayon, and the distance
//! queries. It is the reference the other backends are tested against.
//!
//! # Batch EDT (paper §IV-B, Algorithm 1)
//! [`edt::edt_with`] computes the exact squared Euclidean distance and the
//! nearest obstacle of every voxel of a dense 2D or 3D grid with three
//! separable scans: a two-way sweep along `x` (the paper's `INITSCAN`), then
//! the lower envelope of parabolas (Felzenszwalb–Huttenlocher, the same
//! envelope as Meijster et al.) along `y` and along `z` (`AUXSCAN`). Each
//! scan carries the nearest obstacle's linear index, so no search is needed
//! afterwards.
//!
//! The paper transposes the volume between scans so that GPU threads read
//! coalesced memory. The CPU counterpart is to gather a *tile* of
//! neighbouring lines, so every cache line loaded is used by all lanes,
//! scan them from a small contiguous buffer and scatter the results back
//! ([`edt::ScanLayout::TiledEnvelope`]). The default,
//! [`edt::ScanLayout::Tiled`], also replaces the envelope by an exact
//! windowed minimum vectorised across the tile's lanes wherever the
//! distances are short, which is most of the last scan and much of the
//! second; `ScanLayout::PerLine` (one strided line at a time) is the
//! paper's uncoalesced baseline, kept for the benchmarks.
#![warn(missing_docs)]

mod awake;
mod backend;
pub mod edt;
mod error;
pub mod integrate;

pub use backend::CpuBackend;
pub use error::CpuError;
