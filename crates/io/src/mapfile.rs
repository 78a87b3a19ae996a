//! The `.edtmap` map file: a whole global map (occupancy, global EDT and
//! fixed obstacles) with the parameters needed to read it, saved and
//! loaded bit for bit.
//!
//! The layout is specified byte by byte in `docs/FORMAT.md`. In short: an
//! 8-byte magic, the format version, flags, the file's total length, the
//! voxel size, the parameters as TOML text, then three sections of blocks
//! (occupancy, EDT, fixed obstacles) in sorted key order, and a CRC-32 of
//! everything before it. The same map always gives the same bytes.
//!
//! Design choices:
//! * The parameters are TOML (the sections `[occupancy]` and `[global]` of
//!   the configuration), so a file stays readable with `head` and a field
//!   added later with a default still reads old files. The voxel size is a
//!   binary `f64`, exact.
//! * Block payloads are the blocks' raw little-endian values, with no
//!   compression: saving and loading are as fast as the disk, and `f32`
//!   log-odds (−∞ for unobserved voxels included) come back bit-identical.
//!   The EDT is stored as memory holds it, an `i16` offset to the nearest
//!   obstacle per axis (6 bytes a voxel); its squared distance is
//!   recomputed on load. Each block stores only its layers along z that
//!   hold something other than what a new block holds, named by a mask
//!   byte: a planar map's blocks store one layer of eight, and a 3D map's
//!   blocks at the edge of the cutoff or of the observed space fewer than
//!   eight. Version 1 files, which stored the squared distance and the
//!   obstacle's `i32` index (16 bytes a voxel), and version 2 files, which
//!   stored every layer, still load.
//! * Loading trusts nothing: the magic, version, length and checksum are
//!   checked before anything else is read, every count is checked against
//!   the bytes that remain before anything is allocated, and the contents
//!   must pass the same checks as a map being saved (valid parameters,
//!   sorted unique keys, EDT entries that agree with their nearest
//!   obstacle). Nothing here panics on any input. [`read_map`] reads the
//!   whole file into memory, so the checksum is verified before anything
//!   is parsed.
//! * [`write_map`] writes a temporary file in the target's folder, syncs it
//!   and renames it over the target, so a crash never leaves a half-written
//!   map under the map's name. Maps are streamed to disk, not built in
//!   memory first.
//!
//! ```
//! use edtmap_core::{BlockKey, GlobalMap, GlobalParams, OccupancyParams};
//! use edtmap_io::mapfile::{read_map, write_map};
//!
//! let mut map = GlobalMap::new(0.1, OccupancyParams::default(), GlobalParams::default())?;
//! map.occupancy_mut().get_or_insert(BlockKey([0, 0, 0])).log_odds.set(0, 0.85);
//! let path = std::env::temp_dir().join(format!("edtmap_doc_{}.edtmap", std::process::id()));
//! write_map(&path, &map)?;
//! let back = read_map(&path)?;
//! assert_eq!(back.occupancy().get(BlockKey([0, 0, 0])), map.occupancy().get(BlockKey([0, 0, 0])));
//! # std::fs::remove_file(&path).ok();
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod check;
mod decode;
mod encode;
mod layout;

use std::path::Path;

use edtmap_core::GlobalMap;
use thiserror::Error;

use crate::IoError;

/// The format version this build writes; it reads versions 1 to this one.
pub const MAP_FORMAT_VERSION: u32 = 3;

/// The first 8 bytes of every map file. The CR LF pair makes a file that
/// went through a text-mode line-ending conversion fail the magic check.
pub const MAP_MAGIC: [u8; 8] = *b"EDTMAP\r\n";

/// Checks `map` as [`encode_map`] and [`decode_map`] do: block keys in the
/// index range, log-odds that are finite or unobserved, EDT entries within
/// the cutoff that agree with their nearest obstacle (the parameters and
/// the one voxel size are checked when a [`GlobalMap`] is made).
pub fn check_map(map: &GlobalMap) -> Result<(), MapFileError> {
    check::check_contents(map)
}

/// What is wrong with a map file's bytes, or with a map about to be saved.
/// [`read_map`] and [`write_map`] wrap it in [`IoError::MapFile`] with the
/// file's path.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum MapFileError {
    /// The bytes do not start with [`MAP_MAGIC`] (or there are none).
    #[error("not an edtmap map file ({0})")]
    NotMapFile(String),
    /// The file's format version is newer than this build reads.
    #[error("written by a newer edtmap: format version {found}, this build reads up to {supported}")]
    NewerVersion {
        /// The version in the file.
        found: u32,
        /// [`MAP_FORMAT_VERSION`].
        supported: u32,
    },
    /// The file ends inside its fixed-size header.
    #[error("truncated: {actual} bytes, shorter than the {header}-byte header")]
    TruncatedHeader {
        /// Bytes present.
        actual: u64,
        /// Bytes of header needed to read the file's length.
        header: u64,
    },
    /// The file is shorter than the length its header states.
    #[error("truncated: {expected} bytes expected, {actual} present")]
    Truncated {
        /// The length the header states, bytes.
        expected: u64,
        /// Bytes present.
        actual: u64,
    },
    /// The trailing CRC-32 does not match the bytes before it.
    #[error("corrupt: checksum mismatch (stored {stored:#010x}, computed {computed:#010x})")]
    Checksum {
        /// The checksum stored in the file.
        stored: u32,
        /// The checksum of the bytes read.
        computed: u32,
    },
    /// The bytes are framed correctly but their contents are inconsistent:
    /// duplicate or unsorted keys, counts that do not add up, an EDT entry
    /// that disagrees with its nearest obstacle, a NaN log-odds, ...
    #[error("corrupt: {0}")]
    Corrupt(String),
    /// The parameters are unreadable or fail validation; names the field.
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
}

impl MapFileError {
    fn at(self, path: &Path) -> IoError {
        IoError::MapFile { path: path.to_path_buf(), error: self }
    }
}

/// The bytes of `map` in the `.edtmap` format. Fails, writing nothing, when
/// the contents do not pass [`check_map`].
pub fn encode_map(map: &GlobalMap) -> Result<Vec<u8>, MapFileError> {
    let prepared = encode::Prepared::new(map)?;
    let mut out = Vec::with_capacity(usize::try_from(prepared.total_len()).unwrap_or(0));
    // Writing into a Vec cannot fail: it grows or aborts.
    prepared.write(&mut out).expect("writing into a Vec never fails");
    Ok(out)
}

/// The map held by `bytes`, a whole `.edtmap` file.
pub fn decode_map(bytes: &[u8]) -> Result<GlobalMap, MapFileError> {
    decode::decode(bytes)
}

/// Saves `map` at `path`, replacing any file there only once the new one is
/// complete and synced. Fails, leaving `path` untouched, when the contents
/// do not pass [`check_map`] or the file cannot be written.
pub fn write_map(path: &Path, map: &GlobalMap) -> Result<(), IoError> {
    let prepared = encode::Prepared::new(map).map_err(|e| e.at(path))?;
    crate::files::write_atomic_with(path, |w| prepared.write(w))
}

/// Loads the map saved at `path`.
pub fn read_map(path: &Path) -> Result<GlobalMap, IoError> {
    let bytes = crate::files::read_input(path, u64::MAX)?;
    decode_map(&bytes).map_err(|e| e.at(path))
}

#[cfg(test)]
mod tests {
    use super::*;
    use edtmap_core::{
        BlockKey, Connectivity, EdtMap, FixedMap, ForbiddenZone, GlobalParams, IntegrationMode, OccupancyMap,
        OccupancyParams,
    };

    fn small_params() -> (f64, OccupancyParams, GlobalParams) {
        let vs = 0.1 + 0.2; // not exactly 0.3: the binary f64 must come back as is
        let global_params = GlobalParams {
            max_distance_m: 1.0 / 3.0,
            connectivity: Connectivity::Eighteen,
            mode: IntegrationMode::Exact,
            forbidden: vec![ForbiddenZone { min_m: [-1.0, 0.1, 0.2], max_m: [0.7, 0.2 + 1e-7, 3.0e5] }],
            planar: false,
        };
        let occupancy_params = OccupancyParams { prob_hit: 0.7000000000000001, ..Default::default() };
        (vs, occupancy_params, global_params)
    }

    fn small_map() -> GlobalMap {
        let (vs, occupancy_params, global_params) = small_params();
        let mut map = GlobalMap::from_layers(
            vs,
            occupancy_params,
            global_params,
            OccupancyMap::new(),
            EdtMap::new(),
            FixedMap::new(),
        )
        .expect("valid");
        map.occupancy_mut().get_or_insert(BlockKey([-1, 2, 3])).log_odds.set(7, -0.25);
        map.fixed_obstacles_mut().get_or_insert(BlockKey([0, 0, 0])).bits[3] = 1 << 40;
        map
    }

    #[test]
    fn params_come_back_exactly() {
        let map = small_map();
        let bytes = encode_map(&map).expect("valid");
        let back = decode_map(&bytes).expect("round trip");
        assert_eq!(back.voxel_size_m().to_bits(), map.voxel_size_m().to_bits());
        assert_eq!(back.occupancy_params(), map.occupancy_params());
        assert_eq!(back.params(), map.params());
    }

    #[test]
    fn stated_length_is_the_written_length() {
        let map = small_map();
        let prepared = encode::Prepared::new(&map).expect("valid");
        let bytes = encode_map(&map).expect("valid");
        assert_eq!(bytes.len() as u64, prepared.total_len());
        assert_eq!(bytes[..8], MAP_MAGIC);
    }

    #[test]
    fn invalid_zone_is_refused_before_writing() {
        // A map with a bad zone cannot be made, so it can never be written.
        let (vs, occupancy_params, mut global_params) = small_params();
        global_params.forbidden[0].max_m[1] = 0.0;
        let err = GlobalMap::from_layers(
            vs,
            occupancy_params,
            global_params,
            OccupancyMap::new(),
            EdtMap::new(),
            FixedMap::new(),
        )
        .expect_err("bad zone");
        assert!(err.to_string().contains("forbidden"), "{err}");
    }
}
