//! Slices of the latest local volume: occupancy states and the EDT.

use std::path::{Path, PathBuf};

use anyhow::Result;
use edtmap::{VoxelIndex, VoxelState, FAR_DIST_SQ};

use crate::backend::CliMapper;
use crate::report::FrameRecord;
use edtmap_io::plot::{Chart, Series, SeriesStyle};
use edtmap_io::picture::{viridis, write_slice_png, write_states_png, Slice, SliceStyle};
use edtmap_io::ply::{write_ply, ColouredPoint};

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

/// Writes `occupied.ply` (every occupied voxel of the global map, coloured
/// by height) and `edt.ply` (every observed voxel of the latest local
/// volume within the cutoff, coloured by its global distance, 0 to
/// `max_distance_m`) into `out`.
pub(crate) fn write_plys(mapper: &CliMapper, out: &Path) -> Result<Vec<PathBuf>> {
    let map = mapper.map();
    let vs = map.voxel_size_m();
    let centre = |v: VoxelIndex| v.0.map(|c| ((c as f64 + 0.5) * vs) as f32);
    let mut occupied = Vec::new();
    for (key, block) in map.occupancy.iter() {
        for (offset, &value) in block.log_odds.iter().enumerate() {
            if map.log_odds.state(value) == VoxelState::Occupied {
                occupied.push(centre(key.voxel(offset)));
            }
        }
    }
    let (lo, hi) = occupied.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| (lo.min(p[2]), hi.max(p[2])));
    let by_height: Vec<ColouredPoint> =
        occupied.iter().map(|&xyz| ColouredPoint { xyz, rgb: viridis(if hi > lo { (xyz[2] - lo) / (hi - lo) } else { 0.0 }) }).collect();
    let occ_path = out.join("occupied.ply");
    write_ply(&occ_path, &by_height, "edtmap occupied voxels, coloured by height")?;
    let mut edt_points = Vec::new();
    if let Some(volume) = mapper.local_volume() {
        let max_m = map.params.max_distance_m as f32;
        for (i, state) in mapper.local_states().as_slice().iter().enumerate() {
            if *state == VoxelState::Unknown {
                continue;
            }
            let v = volume.world(volume_coords(volume.dims, i));
            let (dist_sq, _) = map.edt.entry(v);
            if dist_sq != FAR_DIST_SQ {
                let d = (f64::from(dist_sq).sqrt() * vs) as f32;
                edt_points.push(ColouredPoint { xyz: centre(v), rgb: viridis(d / max_m) });
            }
        }
    }
    let edt_path = out.join("edt.ply");
    let comment = format!("edtmap EDT of the last local volume, coloured by distance 0 to {} m", map.params.max_distance_m);
    write_ply(&edt_path, &edt_points, &comment)?;
    Ok(vec![occ_path, edt_path])
}

/// Coordinates of linear index `i` in a volume of `dims`.
fn volume_coords(dims: [usize; 3], i: usize) -> [usize; 3] {
    [i % dims[0], (i / dims[0]) % dims[1], i / (dims[0] * dims[1])]
}

/// Writes `timing.png`: each stage's time per frame (occupancy, batch
/// EDT, integration, whole frame), in ms.
pub(crate) fn write_timing_plot(frames: &[FrameRecord], backend: &str, out: &Path) -> Result<PathBuf> {
    let series = |name: &str, get: fn(&FrameRecord) -> f64| {
        Series::new(name, frames.iter().map(|f| (f.index as f64, get(f))), SeriesStyle::Line)
    };
    let chart = Chart::new(format!("time per frame ({backend})"))
        .x_label("frame")
        .y_label("ms")
        .series(series("occupancy", |f| f.ogm_ms))
        .series(series("batch EDT", |f| f.batch_edt_ms))
        .series(series("integration", |f| f.integrate_ms))
        .series(series("total", |f| f.total_ms));
    let path = out.join("timing.png");
    chart.write_png(&path)?;
    Ok(path)
}
