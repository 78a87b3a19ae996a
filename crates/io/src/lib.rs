//! File formats of edtmap.
//!
//! * [`npy`]: dense grids in NumPy's `.npy` format (the `edtmap edt`
//!   command). The header is parsed by the `npyz` crate; the data is read as
//!   raw element bytes, so any bool or integer dtype of either byte order
//!   is accepted (an element is an obstacle when any of its bytes is
//!   nonzero). C and Fortran order are both supported; outputs keep the
//!   input's order.
//! * [`dataset`] and [`depth_folder`]: recordings in folders as sensor
//!   frames with poses: 3DMatch and TUM RGB-D depth images, and PCD, PLY or
//!   KITTI `.bin` point clouds, posed per file, by KITTI `poses.txt` or by
//!   a TUM trajectory ([`trajectory`], interpolated at each frame's time).
//! * ROS 1 bags and ROS 2 MCAP files are read and written by the
//!   `edtmap-ros` crate, so that saving a map needs none of their
//!   dependencies.
//! * [`ply`]: PLY point clouds, read (ascii and binary) and written.
//! * [`pcd`]: point clouds in PCL's PCD format ([`read_pcd`]), ascii or
//!   binary data, float32 or float64 coordinates.
//! * [`mapfile`]: the versioned `.edtmap` map file ([`write_map`],
//!   [`read_map`]): occupancy, global EDT, fixed obstacles and parameters,
//!   saved bit for bit, checksummed, written atomically.
//! * [`map_server`]: 2D occupancy maps for ROS navigation (`map_server`,
//!   `nav2_map_server`): a PGM image and the YAML that places it.
//! * Pictures and charts are drawn by the `edtmap-viz` crate, which writes
//!   them through [`files`]; nothing here draws.
//!
//! * [`files`]: the one way inputs are opened (regular files only, with a
//!   size cap) and outputs written (atomically, never through a link).
//!
//! Every error names the file and the problem; nothing here panics on bad
//! input.
#![warn(missing_docs)]

pub mod dataset;
pub mod depth_folder;
mod error;
pub mod files;
mod folder;
pub mod map_server;
pub mod mapfile;
pub mod npy;
pub mod pcd;
pub mod ply;
pub mod trajectory;

pub use error::IoError;
pub use mapfile::{check_map, read_map, write_map};
pub use pcd::read_pcd;
pub use trajectory::Trajectory;
