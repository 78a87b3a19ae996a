//! Core types shared by every edtmap backend and front end.
//!
//! The crate holds plain data and no algorithms: dense grids
//! ([`Grid3`]), voxel states ([`VoxelState`]), the result of a batch
//! Euclidean distance transform ([`EdtField`]) and its parameters
//! ([`EdtParams`]). Backends (`edtmap-cpu`, later `edtmap-gpu`) compute on
//! these types and must agree on them bit for bit.
//!
//! # Conventions
//! * A dense grid has dimensions `[nx, ny, nz]` with `x` varying fastest:
//!   the linear index of voxel `(x, y, z)` is `x + nx * (y + ny * z)`. A C-order
//!   array of shape `(a0, a1, a2)` is the grid `[a2, a1, a0]`; a 2D array of
//!   shape `(a0, a1)` is the grid `[a1, a0, 1]`.
//! * Distances are integer squared distances in voxel units
//!   (`dist_sq_vox`); a voxel with no obstacle anywhere in the grid holds
//!   [`UNREACHABLE_DIST_SQ`] and no nearest obstacle.
#![warn(missing_docs)]

pub mod backend;
mod edt;
mod error;
pub mod fixed_ray;
mod global;
mod global_map;
mod grid;
mod index;
pub mod memory;
mod obstacles;
mod occupancy;
pub mod projection;
pub mod sensor;
mod state;
mod volume;

pub use backend::{Backend, BackendError, BatchEdt, IntegrateReport, WaveCounts, WavefrontJob};
pub use edt::{dist_sq_to_vox, EdtField, EdtParams, NO_SITE, UNREACHABLE_DIST_SQ};
pub use error::CoreError;
pub use fixed_ray::{fixed_scale, setup_ray, walk, FixedRay};
pub use global::{Connectivity, Cutoff, EdtBlock, EdtMap, ForbiddenZone, GlobalParams, IntegrationMode, DEFAULT_MAX_DISTANCE_M, FAR_DIST_SQ, NO_OBSTACLE};
pub use global_map::GlobalMap;
pub use grid::Grid3;
pub use memory::MemoryBudget;
pub use obstacles::{Obstacles, StaticBlock, StaticMap, MAX_STATIC_BLOCKS};
pub use index::{BlockKey, VoxelIndex, BLOCK_SIDE, BLOCK_VOXELS};
pub use projection::{ProjectJob, VoxelToSensor, PROJ_MISS, PROJ_NOT_MISS, PROJ_UNCERTAIN};
pub use occupancy::{BlockMap, LogOdds, OccupancyBlock, OccupancyMap, OccupancyParams, OBS_HIT, OBS_MISS, OBS_NONE, UNOBSERVED};
pub use volume::{check_voxel_size, LocalVolume, VolumeParams};
pub use state::VoxelState;
