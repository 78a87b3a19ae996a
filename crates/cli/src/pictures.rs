//! Slices of the latest local volume: occupancy states and the EDT.

use std::path::{Path, PathBuf};

use anyhow::Result;
use edtmap::VoxelState;

use crate::backend::CliMapper;
use edtmap_io::picture::{write_slice_png, write_states_png, Slice, SliceStyle};

/// Writes `occupancy_slice.png` and `edt_slice.png` of the horizontal slice
/// of the local volume at height `z_m` into `out`.
pub(crate) fn write_slices(mapper: &CliMapper, z_m: f64, out: &Path) -> Result<Vec<PathBuf>> {
    let Some(volume) = mapper.local_volume() else { return Ok(Vec::new()) };
    let vs = volume.voxel_size_m;
    let [nx, ny, nz] = volume.dims;
    let z = ((z_m / vs).floor() as i64 - volume.origin.0[2] as i64).clamp(0, nz as i64 - 1) as usize;
    let height = (volume.origin.0[2] as f64 + z as f64 + 0.5) * vs;
    let plane = z * nx * ny..(z + 1) * nx * ny;
    let states = &mapper.local_states().as_slice()[plane.clone()];
    let occ_path = out.join("occupancy_slice.png");
    let title = format!("occupancy z={height:.2} m");
    write_states_png(&occ_path, nx, ny, states, &title)?;
    let edt = mapper.local_edt();
    let dist: Vec<f32> = plane
        .zip(states)
        .map(|(i, s)| if *s == VoxelState::Unknown { f32::NAN } else { edt.distance_vox(i) * vs as f32 })
        .collect();
    let edt_path = out.join("edt_slice.png");
    let style = SliceStyle { title: format!("local edt z={height:.2} m (grey: unknown)"), unit: "m".into(), max_value: None };
    write_slice_png(&edt_path, Slice { width: nx, height: ny, values: &dist }, &style)?;
    Ok(vec![occ_path, edt_path])
}
