//! Exact batch Euclidean distance transform of dense grids.

pub(crate) mod envelope;
mod passes;
mod shared;
mod weighted;
mod window;

pub use passes::{batch_edt, edt_into, edt_slice_into, edt_with, ScanLayout, DEFAULT_TILE_LANES};
pub use shared::SharedBuf;
pub use weighted::{edt_weighted_int, edt_weighted_real};
