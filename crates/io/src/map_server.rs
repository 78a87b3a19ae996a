//! 2D occupancy maps as ROS's `map_server` (ROS 1) and `nav2_map_server`
//! (ROS 2) load them: a binary PGM image (`P5`, one byte a cell) and a
//! YAML file naming it and placing it in the world.
//!
//! The image is what `map_saver` writes in `trinary` mode: 0 (black) for
//! occupied cells, 254 for free ones and 205 (grey) for unknown ones. Row
//! 0 of the image is the top of the map (the largest y), so the last row
//! is the one whose cells start at `origin`'s y. A loader reads a cell's
//! occupancy probability as `(255 - value) / 255` (`negate: 0`): above
//! `occupied_thresh` occupied, below `free_thresh` free, unknown between.
//! `free_thresh` is 0.196, the value ROS 1's `map_saver` writes: grey
//! reads as `50 / 255 = 0.19608`, just above it, so unknown cells load
//! unknown; with a `free_thresh` of 0.25 (a common default) they would load
//! free.

use std::io::Write;
use std::path::{Path, PathBuf};

use edtmap_core::VoxelState;

use crate::files::{check_distinct_outputs, write_atomic, write_atomic_with};
use crate::IoError;

/// Pixel value of an occupied cell (black).
pub const OCCUPIED_PIXEL: u8 = 0;
/// Pixel value of a free cell (white, as `map_saver` writes it).
pub const FREE_PIXEL: u8 = 254;
/// Pixel value of an unknown cell (grey).
pub const UNKNOWN_PIXEL: u8 = 205;
/// `occupied_thresh` written in the YAML: cells darker than this
/// probability load occupied.
pub const OCCUPIED_THRESH: f64 = 0.65;
/// `free_thresh` written in the YAML: cells lighter than this probability
/// load free (see the module docs for why not 0.25).
pub const FREE_THRESH: f64 = 0.196;

/// A 2D grid of occupancy states to write as a map_server map.
#[derive(Debug, Clone, Copy)]
pub struct OccupancyGrid2d<'a> {
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// States, row `y` at `states[y * width..]`, `y` upwards (row 0 is the
    /// lowest y, the bottom of the map).
    pub states: &'a [VoxelState],
    /// Edge length of a cell, metres.
    pub resolution_m: f64,
    /// World x and y of the lower left corner of cell (0, 0), metres.
    pub origin_m: [f64; 2],
}

/// The image beside map_server YAML `yaml`: its name with extension `.pgm`.
pub fn image_path(yaml: &Path) -> PathBuf {
    yaml.with_extension("pgm")
}

/// The pixel value of a state (see the module docs).
pub fn pixel(state: VoxelState) -> u8 {
    match state {
        VoxelState::Occupied => OCCUPIED_PIXEL,
        VoxelState::Free => FREE_PIXEL,
        VoxelState::Unknown => UNKNOWN_PIXEL,
    }
}

/// Writes `grid` as the map_server pair: the image at [`image_path`] of
/// `yaml`, then `yaml` naming it (by file name, so the pair can be moved
/// together). Each file is written atomically. Returns the image's path.
pub fn write_map_server(yaml: &Path, grid: &OccupancyGrid2d<'_>) -> Result<PathBuf, IoError> {
    let image = image_path(yaml);
    check_distinct_outputs(&[("the YAML", yaml), ("its image", &image)])?;
    check_grid(yaml, grid)?;
    let name = image.file_name().and_then(|n| n.to_str()).ok_or_else(|| IoError::BadData {
        path: image.clone(),
        reason: "the image's file name is not UTF-8, so the YAML cannot name it: choose a UTF-8 name".into(),
    })?;
    write_atomic_with(&image, |out| {
        write!(
            out,
            "P5\n# edtmap map_server map, {} m per cell\n{} {}\n255\n",
            grid.resolution_m, grid.width, grid.height
        )?;
        let mut row = vec![0u8; grid.width];
        for y in (0..grid.height).rev() {
            for (p, &s) in row.iter_mut().zip(&grid.states[y * grid.width..(y + 1) * grid.width]) {
                *p = pixel(s);
            }
            out.write_all(&row)?;
        }
        Ok(())
    })?;
    write_atomic(yaml, yaml_text(name, grid).as_bytes())?;
    Ok(image)
}

/// Refuses a grid whose size, cell size or origin cannot be written.
fn check_grid(yaml: &Path, grid: &OccupancyGrid2d<'_>) -> Result<(), IoError> {
    let bad = |reason: String| Err(IoError::BadData { path: yaml.to_path_buf(), reason });
    if grid.width == 0 || grid.height == 0 || grid.width.checked_mul(grid.height) != Some(grid.states.len()) {
        return bad(format!(
            "a map of {} x {} cells needs that many states, got {}",
            grid.width,
            grid.height,
            grid.states.len()
        ));
    }
    if !(grid.resolution_m.is_finite() && grid.resolution_m > 0.0) || grid.origin_m.iter().any(|o| !o.is_finite()) {
        return bad(format!(
            "resolution {} m and origin {:?} m must be finite, the resolution positive",
            grid.resolution_m, grid.origin_m
        ));
    }
    Ok(())
}

/// The YAML naming image `name` (quoted, so that any file name reads
/// back); lengths to the nanometre.
fn yaml_text(name: &str, grid: &OccupancyGrid2d<'_>) -> String {
    let quoted: String =
        name.chars().flat_map(|c| if c == '"' || c == '\\' { vec!['\\', c] } else { vec![c] }).collect();
    // To the nanometre: `-96 * 0.2` reads -19.2, not -19.200000000000003.
    let nm = |m: f64| (m * 1e9).round() / 1e9;
    let ([x, y], resolution) = (grid.origin_m.map(nm), nm(grid.resolution_m));
    format!(
        "image: \"{quoted}\"\nmode: trinary\nresolution: {resolution}\norigin: [{x}, {y}, 0.0]\nnegate: 0\noccupied_thresh: {OCCUPIED_THRESH}\nfree_thresh: {FREE_THRESH}\n"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_load_back_as_their_states() {
        // A loader's reading of each pixel value (module docs).
        let load = |value: u8| {
            let p = (255.0 - f64::from(value)) / 255.0;
            if p > OCCUPIED_THRESH {
                VoxelState::Occupied
            } else if p < FREE_THRESH {
                VoxelState::Free
            } else {
                VoxelState::Unknown
            }
        };
        for s in [VoxelState::Unknown, VoxelState::Free, VoxelState::Occupied] {
            assert_eq!(load(pixel(s)), s);
        }
    }

    #[test]
    fn image_rows_run_from_the_top_of_the_map() {
        let dir = tempfile::tempdir().expect("tempdir");
        let yaml = dir.path().join("floor \"1\".yaml");
        // 3 x 2 cells: row y = 0 (bottom) occupied, free, unknown.
        let states = [
            VoxelState::Occupied,
            VoxelState::Free,
            VoxelState::Unknown,
            VoxelState::Free,
            VoxelState::Free,
            VoxelState::Free,
        ];
        let grid = OccupancyGrid2d { width: 3, height: 2, states: &states, resolution_m: 0.05, origin_m: [-1.5, 2.0] };
        let image = write_map_server(&yaml, &grid).expect("written");
        let bytes = std::fs::read(&image).expect("image");
        let body = &bytes[bytes.len() - 6..];
        assert!(bytes.starts_with(b"P5\n"));
        assert_eq!(body, [FREE_PIXEL, FREE_PIXEL, FREE_PIXEL, OCCUPIED_PIXEL, FREE_PIXEL, UNKNOWN_PIXEL]);
        let text = std::fs::read_to_string(&yaml).expect("yaml");
        assert!(
            text.contains("image: \"floor \\\"1\\\".pgm\"\n") && text.contains("origin: [-1.5, 2, 0.0]\n"),
            "{text}"
        );
        assert!(
            text.contains("resolution: 0.05\n") && text.contains("mode: trinary\n") && text.contains("negate: 0\n")
        );
        // A grid of the wrong size is refused, naming the file.
        let short = OccupancyGrid2d { states: &states[..5], ..grid };
        let err = write_map_server(&yaml, &short).expect_err("5 states for 6 cells").to_string();
        assert!(err.contains("floor") && err.contains("3 x 2"), "{err}");
    }
}
