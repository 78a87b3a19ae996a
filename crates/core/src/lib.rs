//! The shared layer of edtmap: the types every backend and front end
//! works on, the [`Backend`] trait a device implements, and the host code
//! every backend shares.
//!
//! * Data: dense grids ([`Grid3`]), voxel states ([`VoxelState`]), the
//!   batch EDT's result ([`EdtField`]), the block maps and the layered
//!   [`GlobalMap`] (occupancy, global EDT, fixed obstacles).
//! * The device interface: [`Backend`], one method per device stage,
//!   implemented in full by `edtmap-cpu` and `edtmap-gpu`, which must
//!   agree on it bit for bit.
//! * Host code both backends use: ray set-up in fixed point
//!   ([`fixed_ray`]), the projection's per-voxel definition
//!   ([`projection`]), integration regions and write-back ([`region`]),
//!   frame observations and their fusion ([`Observations`], [`fuse()`]),
//!   the occupancy construction's definitions ([`construction`]), the
//!   exact integration's host side ([`exact`]), and the queries
//!   ([`query`]). The pipeline's stages, which run these on a backend,
//!   are the facade's (`edtmap::stages`).
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
pub mod construction;
mod edt;
mod edt_map;
mod error;
pub mod exact;
pub mod fixed_ray;
mod fuse;
mod global_map;
mod grid;
mod index;
pub mod layers;
pub mod memory;
mod observations;
mod obstacles;
mod occupancy;
pub mod projection;
pub mod query;
pub mod region;
pub mod sensor;
mod state;
mod volume;

pub use backend::{
    Backend, BackendError, BatchEdt, DeviceCounters, ExactCounts, IntegrationJob, IntegrationReport, IntegrationWork,
    WaveCounts,
};
pub use edt::{dist_sq_to_vox, EdtField, EdtParams, NO_SITE, UNREACHABLE_DIST_SQ};
pub use edt_map::{
    Connectivity, Cutoff, EdtBlock, EdtMap, EntryError, ForbiddenZone, GlobalParams, IntegrationMode,
    DEFAULT_MAX_DISTANCE_M, FAR_DIST_SQ, NO_OBSTACLE, NO_OFFSET,
};
pub use error::CoreError;
pub use fixed_ray::{cast_fixed, fixed_scale, prepare_rays, setup_ray, walk, FixedRay};
pub use fuse::{fuse, read_states, FuseReport};
pub use global_map::GlobalMap;
pub use grid::Grid3;
pub use index::{BlockKey, VoxelIndex, BLOCK_SIDE, BLOCK_VOXELS};
pub use memory::MemoryBudget;
pub use observations::Observations;
pub use obstacles::{FixedBlock, FixedMap, Obstacles, MAX_FIXED_BLOCKS};
pub use occupancy::{
    par_fill, BlockHeap, BlockMap, LogOdds, MapStamp, OccupancyBlock, OccupancyMap, OccupancyParams, SharedBlock,
    OBS_HIT, OBS_MISS, OBS_NONE, UNOBSERVED,
};
pub use projection::{
    decide_uncertain, mark_misses, ProjectJob, VoxelToSensor, PROJ_MISS, PROJ_NOT_MISS, PROJ_UNCERTAIN,
};
pub use region::Region;
pub use state::VoxelState;
pub use volume::{check_voxel_size, LocalVolume, VolumeParams};
