//! edtmap: occupancy mapping and exact Euclidean distance transforms for
//! robot motion planning, following the GIE-mapping pipeline (paper Fig. 1):
//! sensor frame → occupancy → batch EDT of the local volume → global
//! integration → queries.
//!
//! [`Mapper`] runs the pipeline one [`sensor::Frame`] at a time:
//! occupancy by ray casting or volumetric projection, fused into an
//! unbounded log-odds map of 8³ blocks (paper §IV-A), then the exact batch
//! EDT of the local volume around the sensor (§IV-B), merged into the
//! unbounded global EDT (§IV-C) that [`Mapper::distance`] and friends query.
//! [`config::Config`] reads the whole setup from a TOML file; [`save_map`]
//! and [`load_map`] keep the whole map in a file.
//!
//! ```
//! use edtmap::sensor::{Frame, Measurement, PointCloud, RangeLimits, Sensor};
//! use edtmap::{Mapper, MapperParams, VoxelIndex, VoxelState};
//! use nalgebra::Isometry3;
//!
//! let sensor = Sensor::Points(RangeLimits { min_m: 0.1, max_m: 20.0 });
//! let mut mapper = Mapper::new(sensor, MapperParams::for_voxel_size(0.1))?;
//! let frame = Frame {
//!     stamp_s: 0.0,
//!     t_world_sensor: Isometry3::translation(0.0, 0.0, 1.0),
//!     measurement: Measurement::Points(PointCloud { points: vec![[2.05, 0.05, 0.05]] }),
//! };
//! let stats = mapper.integrate_frame(&frame)?;
//! assert_eq!(mapper.state(VoxelIndex([20, 0, 10])), VoxelState::Occupied);
//! assert_eq!(mapper.state(VoxelIndex([10, 0, 10])), VoxelState::Free);
//! assert!(stats.voxels_updated >= 19);
//! // The exact EDT of the 10 x 10 x 3 m volume around the sensor.
//! let volume = mapper.local_volume().expect("one frame integrated");
//! let here = volume.local(VoxelIndex([17, 0, 10])).expect("inside");
//! assert_eq!(mapper.local_edt().distance_vox(volume.linear(here)), 3.0);
//! // The global EDT, in metres: 5 voxels from the return, gradient away from it.
//! let d = mapper.distance([1.55, 0.05, 1.05]);
//! assert!((d.distance_m - 0.5).abs() < 1e-9 && d.observed && d.gradient[0] < 0.0);
//! # Ok::<(), edtmap::MapError>(())
//! ```
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

mod budget;
mod choice;
pub mod config;
mod error;
pub mod eval;
mod mapfile;
mod mapper;
mod shared;
pub mod stages;
mod threads;
mod update;

pub use choice::{open_backend, BackendChoice, DynBackend, OpenedBackend};
pub use edtmap_core::query::{Distance, DistanceBox, PointState};
pub use edtmap_core::*;
/// The CPU backend (rayon), the reference implementation.
pub use edtmap_cpu as cpu;
pub use error::MapError;
pub use mapfile::{load_map, save_map};
pub use mapper::{Cleared, FrameStats, Mapper, MapperParams, MapperSensor};
pub use shared::{SharedMapper, Snapshot};
pub use threads::FrameThreads;
