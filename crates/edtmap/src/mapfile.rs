//! Saving and loading the whole global map (format: `docs/FORMAT.md`).

use crate::MapError;
use edtmap_core::GlobalMap;
use edtmap_io::mapfile::{read_map, write_map};
use std::path::Path;

/// Writes `map` (occupancy, global EDT, fixed obstacles and their
/// parameters) to `path`, atomically: a failed save leaves no half file.
pub fn save_map(map: &GlobalMap, path: &Path) -> Result<(), MapError> {
    Ok(write_map(path, map)?)
}

/// Reads a map written by [`save_map`]; a corrupt, truncated or newer file
/// is an error naming it.
pub fn load_map(path: &Path) -> Result<GlobalMap, MapError> {
    Ok(read_map(path)?)
}
