//! The CPU backend of edtmap: every stage of the pipeline on all cores with
//! rayon. It is the reference the other backends are tested against.
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
//! coalesced memory. The CPU counterpart is [`edt::ScanLayout::Tiled`]:
//! a task gathers a tile of neighbouring lines, so every cache line it loads
//! is used by all lanes, scans them from a small contiguous buffer and
//! scatters the results back. `ScanLayout::PerLine` (one strided line at a
//! time) is kept for the comparison in the benchmarks.
#![warn(missing_docs)]

pub mod edt;
mod error;

pub use error::CpuError;
