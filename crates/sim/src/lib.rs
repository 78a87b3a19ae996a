//! Synthetic scenes for edtmap: deterministic occupancy grids built from
//! simple geometry, for the demo, tests and benchmarks. Every generator
//! takes a seed and gives the same grid for the same seed.
#![warn(missing_docs)]

pub mod geometry;
mod grids;

pub use grids::{pillar_field, random_grid, PillarField};
