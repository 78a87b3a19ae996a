//! edtmap: occupancy mapping and exact Euclidean distance transforms for
//! robot motion planning, following the GIE-mapping pipeline (paper Fig. 1):
//! sensor frame → occupancy → batch EDT of the local volume → global
//! integration → queries.
//!
//! [`Mapper`] runs the pipeline one [`sensor::Frame`] at a time:
//! occupancy by ray casting or volumetric projection, fused into an
//! unbounded log-odds map of 8³ blocks (paper §IV-A), then the exact batch
//! EDT of the local volume around the sensor (§IV-B). [`config::Config`]
//! reads the whole setup from a TOML file.
//!
//! The batch EDT is also available on its own:
//!
//! ```
//! use edtmap::{cpu, EdtParams, Grid3, VoxelState};
//!
//! let states = Grid3::from_fn([8, 8, 8], |x, y, z| {
//!     if (x, y, z) == (4, 4, 4) { VoxelState::Occupied } else { VoxelState::Free }
//! }).unwrap();
//! let edt = cpu::edt::batch_edt(&states, &EdtParams::default()).unwrap();
//! assert_eq!(edt.distance_vox(states.linear([4, 4, 7])), 3.0);
//! ```
#![warn(missing_docs)]

pub mod config;
pub mod eval;
mod error;
mod mapper;

pub use edtmap_core::*;
/// The CPU backend (rayon), the reference implementation.
pub use edtmap_cpu as cpu;
pub use error::MapError;
pub use mapper::{FrameStats, Mapper, MapperParams};
