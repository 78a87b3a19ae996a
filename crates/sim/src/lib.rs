//! Synthetic scenes for edtmap, deterministic and with exact geometry.
//!
//! * [`random_grid`] and [`pillar_field`] rasterise simple layouts straight
//!   into occupancy grids, for the EDT tests and benchmarks.
//! * [`Scene`] is one of the built-in worlds ([`SceneName`]): solid
//!   primitives ([`geometry`]), pedestrians walking on smooth paths and a
//!   sensor trajectory. It simulates the frames of any sensor model of
//!   `edtmap-core` by exact ray casting and gives the exact ground-truth
//!   occupancy of any local volume at any time.
//!
//! Everything follows the seed in [`SceneOptions`]: the layout, and the
//! range noise and dropout, which are drawn per ray from a hash of (seed,
//! frame, ray), so frames are identical however rayon schedules the rays.
//!
//! ```
//! use edtmap_sim::{Scene, SceneName, SceneOptions};
//! let scene = Scene::new(SceneName::Planar, &SceneOptions::default())?;
//! let frame = scene.frame(&scene.default_sensor(), 0)?;
//! assert_eq!(frame.stamp_s, 0.0);
//! # Ok::<(), edtmap_sim::SimError>(())
//! ```
#![warn(missing_docs)]

mod error;
pub mod geometry;
mod grids;
mod layouts;
mod noise;
mod pedestrian;
mod scene;
mod trajectory;

pub use error::SimError;
pub use geometry::Aabb;
pub use grids::{pillar_field, random_grid, PillarField};
pub use scene::{
    points_pattern, Scene, SceneName, SceneOptions, SceneSection, PLANAR_BEAMS, PLANAR_RANGE, WORLD_SHIFT_M,
};
