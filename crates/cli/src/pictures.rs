//! Pictures of a run and of a saved map: slices of the latest local
//! volume (occupancy states and the EDT), top views of the whole map,
//! point clouds and the timing chart; `edtmap picture`.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use edtmap::{load_map, GlobalMap, LocalVolume, VoxelIndex, VoxelState, FAR_DIST_SQ};
use edtmap_viz::top_view;
use edtmap_viz::TopView;
use serde_json::{json, Value};

use crate::backend::CliMapper;
use crate::query::finite_metres;
use crate::report::FrameRecord;
use edtmap_io::ply::{write_ply, ColouredPoint};
use edtmap_viz::picture::{viridis, write_slice_png, write_states_png, MapAxes, Slice, SliceStyle};
use edtmap_viz::plot::{Chart, Series, SeriesStyle};

/// The occupancy slice `edtmap run` writes in `--out`.
pub(crate) const OCCUPANCY_SLICE: &str = "occupancy_slice.png";
/// The slice of the global EDT.
pub(crate) const EDT_SLICE: &str = "edt_slice.png";
/// Occupied voxels as a point cloud (`--ply`).
pub(crate) const OCCUPIED_PLY: &str = "occupied.ply";
/// The EDT as a point cloud (`--ply`).
pub(crate) const EDT_PLY: &str = "edt.ply";
/// The per-frame timing chart.
pub(crate) const TIMING_PLOT: &str = "timing.png";
/// Top view of the whole map: occupancy at the slices' height.
pub(crate) const MAP_TOP_OCCUPANCY: &str = "map_top_occupancy.png";
/// Top view of the whole map: the global EDT at the slices' height.
pub(crate) const MAP_TOP_DISTANCE: &str = "map_top_distance.png";
/// Top view of the whole map: each column's state through the heights.
pub(crate) const MAP_TOP_PROJECTION: &str = "map_top_projection.png";
/// Top view of the whole map: each column's least distance.
pub(crate) const MAP_TOP_CLEARANCE: &str = "map_top_clearance.png";
/// The top views of the whole map, as `edtmap run` and `edtmap picture` write them.
pub(crate) const MAP_PICTURES: [&str; 4] = [MAP_TOP_OCCUPANCY, MAP_TOP_DISTANCE, MAP_TOP_PROJECTION, MAP_TOP_CLEARANCE];
/// Every picture and cloud a run may write.
pub(crate) const OUT_PICTURES: [&str; 9] = [
    OCCUPANCY_SLICE,
    EDT_SLICE,
    TIMING_PLOT,
    OCCUPIED_PLY,
    EDT_PLY,
    MAP_TOP_OCCUPANCY,
    MAP_TOP_DISTANCE,
    MAP_TOP_PROJECTION,
    MAP_TOP_CLEARANCE,
];

/// The height of the pictured slices and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SliceHeight {
    /// Centre of the pictured layer of the local volume, metres.
    pub(crate) z_m: f64,
    /// `--slice-height`, `[output] slice_height_m` or `densest observed layer`.
    pub(crate) from: &'static str,
    /// The height asked for, if one was.
    pub(crate) requested_m: Option<f64>,
}

impl SliceHeight {
    /// `given` (`--slice-height`), else `configured` (`[output]
    /// slice_height_m`), else the layer of the latest local volume with the
    /// most observed voxels: a sensor's own height shows nothing of what a
    /// camera looking down saw. Logs the choice.
    pub(crate) fn choose(given: Option<f64>, configured: Option<f64>, mapper: &CliMapper) -> SliceHeight {
        let requested = given.map(|z| (z, "--slice-height")).or(configured.map(|z| (z, "[output] slice_height_m")));
        let Some(volume) = mapper.local_volume() else {
            let (z_m, from) = requested.unwrap_or((0.0, "no frame integrated"));
            return SliceHeight { z_m, from, requested_m: requested.map(|r| r.0) };
        };
        let (layer, from) = match requested {
            Some((z, from)) => (requested_layer(volume, z, from), from),
            None => {
                let (layer, observed) = densest_layer(mapper.local_states().as_slice(), volume.dims);
                let (z_m, plane) = (layer_centre(volume, layer), volume.dims[0] * volume.dims[1]);
                tracing::info!("slices at z = {z_m:.2} m: the layer of the local volume with the most observed voxels ({observed} of {plane}); --slice-height picks another");
                (layer, "densest observed layer")
            }
        };
        SliceHeight { z_m: layer_centre(volume, layer), from, requested_m: requested.map(|r| r.0) }
    }

    /// `report.json`'s `slice`.
    pub(crate) fn to_json(&self) -> Value {
        json!({ "z_m": self.z_m, "from": self.from, "requested_m": self.requested_m })
    }
}

/// The z layer of a volume of `dims` (x fastest) with the most voxels that
/// are not unknown, and their count: the lowest such layer on a tie, the
/// middle layer when nothing is observed.
pub(crate) fn densest_layer(states: &[VoxelState], dims: [usize; 3]) -> (usize, usize) {
    let plane = (dims[0] * dims[1]).max(1);
    let counts = states.chunks(plane).map(|layer| layer.iter().filter(|s| **s != VoxelState::Unknown).count());
    counts.enumerate().fold((dims[2] / 2, 0), |best, (z, n)| if n > best.1 { (z, n) } else { best })
}

/// The layer holding height `z_m`, the nearest one (with a warning) when
/// `z_m` is outside the volume.
fn requested_layer(volume: &LocalVolume, z_m: f64, from: &str) -> usize {
    let layer = layer_of(volume, z_m);
    let half = volume.voxel_size_m / 2.0;
    let (lo, hi) = (layer_centre(volume, 0) - half, layer_centre(volume, volume.dims[2] - 1) + half);
    if !(lo..=hi).contains(&z_m) {
        tracing::warn!("{from} {z_m} m is outside the last local volume (z from {lo:.2} to {hi:.2} m): picturing its nearest layer, z = {:.2} m", layer_centre(volume, layer));
    }
    layer
}

/// The layer of `volume` holding height `z_m`, clamped into the volume.
fn layer_of(volume: &LocalVolume, z_m: f64) -> usize {
    let z = (z_m / volume.voxel_size_m).floor() as i64 - i64::from(volume.origin.0[2]);
    z.clamp(0, volume.dims[2] as i64 - 1) as usize
}

/// Height of the centre of layer `z` of `volume`, metres.
fn layer_centre(volume: &LocalVolume, z: usize) -> f64 {
    (f64::from(volume.origin.0[2]) + z as f64 + 0.5) * volume.voxel_size_m
}

/// Writes `occupancy_slice.png` and `edt_slice.png` of the horizontal slice
/// of the local volume at height `z_m` into `out`, with axes in metres and
/// the slice's height.
pub(crate) fn write_slices(mapper: &CliMapper, z_m: f64, out: &Path) -> Result<Vec<PathBuf>> {
    let Some(volume) = mapper.local_volume() else { return Ok(Vec::new()) };
    let vs = volume.voxel_size_m;
    let [nx, ny, _] = volume.dims;
    let z = layer_of(volume, z_m);
    let [ox, oy, _] = volume.origin.0.map(f64::from);
    let axes =
        MapAxes { origin_m: [ox * vs, oy * vs], cell_m: vs, position: format!("z = {:.2} m", layer_centre(volume, z)) };
    let plane = z * nx * ny..(z + 1) * nx * ny;
    let states = &mapper.local_states().as_slice()[plane.clone()];
    let occ_path = out.join(OCCUPANCY_SLICE);
    write_states_png(&occ_path, nx, ny, states, "occupancy", Some(&axes))?;
    let edt = mapper.local_edt();
    let dist: Vec<f32> = plane
        .zip(states)
        .map(|(i, s)| if *s == VoxelState::Unknown { f32::NAN } else { edt.distance_vox(i) * vs as f32 })
        .collect();
    let edt_path = out.join(EDT_SLICE);
    let style =
        SliceStyle { title: "local EDT (grey: unknown)".into(), unit: "m".into(), max_value: None, axes: Some(axes) };
    write_slice_png(&edt_path, Slice { width: nx, height: ny, values: &dist }, &style)?;
    Ok(vec![occ_path, edt_path])
}

/// Arguments of `edtmap picture`.
#[derive(Args, Debug)]
pub(crate) struct PictureArgs {
    /// A map saved with `edtmap run --save`.
    map: PathBuf,
    /// Folder for the pictures, created if missing.
    #[arg(long, default_value = "edtmap-out")]
    out: PathBuf,
    /// Height of the occupancy and distance views, metres (default: the
    /// map's layer with the most observed voxels).
    #[arg(long, value_name = "Z", allow_negative_numbers = true, value_parser = finite_metres)]
    height: Option<f64>,
    /// Heights the projection and clearance views summarise, metres: every
    /// voxel layer overlapping [ZMIN, ZMAX) (default: every observed
    /// layer). Leave the floor and the ceiling out to see the walls.
    #[arg(long, value_name = "ZMIN,ZMAX", value_delimiter = ',', allow_hyphen_values = true)]
    band: Vec<f64>,
}

/// Writes the top views of a saved map (see [`write_map_views`]).
pub(crate) fn picture(args: &PictureArgs) -> Result<()> {
    let band = match args.band[..] {
        [] => None,
        [lo, hi] if lo.is_finite() && hi.is_finite() && lo < hi => Some((lo, hi)),
        _ => bail!("--band takes two finite heights in metres, the lower first: ZMIN,ZMAX (e.g. 0.1,1.8)"),
    };
    let map = load_map(&args.map)?;
    let vs = map.voxel_size_m();
    let z_m = match args.height {
        Some(z) => z,
        None => {
            let layer = top_view::densest_layer(&map).with_context(|| {
                format!("{} has no observed voxel: there is nothing to picture", args.map.display())
            })?;
            (f64::from(layer) + 0.5) * vs
        }
    };
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create --out {}", args.out.display()))?;
    let written = write_map_views(&map, z_m, band, &args.out)?;
    if written.is_empty() {
        bail!("{} holds no mapped block: there is nothing to picture", args.map.display());
    }
    for path in written {
        outln!("wrote {}", path.display());
    }
    Ok(())
}

/// Writes the top views of the whole map into `out` (module docs of
/// `edtmap_viz::top_view`): occupancy and distance in the layer holding
/// `z_m`, and the projection and clearance through the layers `band_m`
/// overlaps (`[min, max)` metres; default every observed layer). Nothing
/// for a map without blocks.
pub(crate) fn write_map_views(
    map: &GlobalMap,
    z_m: f64,
    band_m: Option<(f64, f64)>,
    out: &Path,
) -> Result<Vec<PathBuf>> {
    let vs = map.voxel_size_m();
    let layer = (z_m / vs).floor() as i32;
    let Some(at_height) = TopView::new(map, (layer, layer)) else { return Ok(Vec::new()) };
    let band = match band_m {
        Some((lo, hi)) => ((lo / vs).floor() as i32, (hi / vs).ceil() as i32 - 1),
        None => map.observed_z_range().unwrap_or((layer, layer)),
    };
    let through = TopView::new(map, band)
        .with_context(|| format!("the band of heights {band_m:?} m holds no layer of {vs} m voxels"))?;
    let height = format!("z = {:.2} m", (f64::from(layer) + 0.5) * vs);
    let span = format!("z {:.2} to {:.2} m", f64::from(band.0) * vs, f64::from(band.1 + 1) * vs);
    let max_m = map.params().max_distance_m as f32;
    let paths: Vec<PathBuf> = MAP_PICTURES.iter().map(|n| out.join(n)).collect();
    at_height.write_states_png(&paths[0], "map occupancy", &height)?;
    at_height.write_distance_png(&paths[1], "map EDT (grey: unknown)", &height, max_m)?;
    through.write_states_png(&paths[2], "map projection: obstacle at any height", &span)?;
    through.write_distance_png(&paths[3], "map clearance: least distance in column", &span, max_m)?;
    Ok(paths)
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
    for (key, block) in map.occupancy().iter() {
        for (offset, value) in block.log_odds.iter_stored() {
            if map.log_odds().state(value) == VoxelState::Occupied {
                occupied.push(centre(key.voxel(offset)));
            }
        }
    }
    let (lo, hi) = occupied.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| (lo.min(p[2]), hi.max(p[2])));
    let by_height: Vec<ColouredPoint> = occupied
        .iter()
        .map(|&xyz| ColouredPoint { xyz, rgb: viridis(if hi > lo { (xyz[2] - lo) / (hi - lo) } else { 0.0 }) })
        .collect();
    let occ_path = out.join(OCCUPIED_PLY);
    write_ply(&occ_path, &by_height, "edtmap occupied voxels, coloured by height")?;
    let mut edt_points = Vec::new();
    if let Some(volume) = mapper.local_volume() {
        let max_m = map.params().max_distance_m as f32;
        for (i, state) in mapper.local_states().as_slice().iter().enumerate() {
            if *state == VoxelState::Unknown {
                continue;
            }
            let v = volume.world(volume_coords(volume.dims, i));
            let (dist_sq, _) = map.edt().entry(v);
            if dist_sq != FAR_DIST_SQ {
                let d = (f64::from(dist_sq).sqrt() * vs) as f32;
                edt_points.push(ColouredPoint { xyz: centre(v), rgb: viridis(d / max_m) });
            }
        }
    }
    let edt_path = out.join(EDT_PLY);
    let comment =
        format!("edtmap EDT of the last local volume, coloured by distance 0 to {} m", map.params().max_distance_m);
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
    let mut chart = Chart::new(format!("time per frame ({backend})"))
        .x_label("frame")
        .y_label("ms")
        .series(series("occupancy", |f| f.ogm_ms));
    if frames.iter().all(|f| f.batch_edt_ms.is_some()) {
        chart = chart
            .series(series("batch EDT", |f| f.batch_edt_ms.unwrap_or(0.0)))
            .series(series("integration", |f| f.integrate_ms));
    } else {
        chart = chart.series(series("EDT update", |f| f.integrate_ms));
    }
    let chart = chart.series(series("total", |f| f.total_ms));
    let path = out.join(TIMING_PLOT);
    chart.write_png(&path)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The states of a ball of `radius_sq` (voxels²) around `centre` in a
    /// volume of `dims`: observed (occupied on its surface, free inside)
    /// within the ball, unknown outside.
    fn ball(dims: [usize; 3], centre: [i64; 3], radius_sq: i64) -> Vec<VoxelState> {
        (0..dims[0] * dims[1] * dims[2])
            .map(|i| {
                let p = volume_coords(dims, i).map(|c| c as i64);
                let d: i64 = (0..3).map(|a| (p[a] - centre[a]).pow(2)).sum();
                match d {
                    _ if d > radius_sq => VoxelState::Unknown,
                    _ if d == radius_sq => VoxelState::Occupied,
                    _ => VoxelState::Free,
                }
            })
            .collect()
    }

    #[test]
    fn densest_layer_of_a_ball_is_its_equator() {
        // A ball of radius 3 around (4, 4, 2): layer 2 holds the lattice
        // points of the disc x² + y² ≤ 9 (7 + 2·5 + 2·5 + 2·1 = 29), layers
        // 1 and 3 those of x² + y² ≤ 8 (25), and so on.
        let dims = [9, 9, 7];
        assert_eq!(densest_layer(&ball(dims, [4, 4, 2], 9), dims), (2, 29));
        // Unknown everywhere: the middle layer, nothing observed.
        assert_eq!(densest_layer(&vec![VoxelState::Unknown; 9 * 9 * 7], dims), (3, 0));
        // Two equal balls: the lower equator.
        let two: Vec<VoxelState> = ball(dims, [2, 2, 1], 1)
            .into_iter()
            .zip(ball(dims, [6, 6, 5], 1))
            .map(|(a, b)| if a == VoxelState::Unknown { b } else { a })
            .collect();
        assert_eq!(densest_layer(&two, dims), (1, 5));
    }

    #[test]
    fn layers_of_heights() {
        let volume = LocalVolume { origin: VoxelIndex([0, 0, -4]), dims: [4, 4, 8], voxel_size_m: 0.25 };
        assert_eq!(layer_of(&volume, -0.4), 2);
        assert_eq!(layer_centre(&volume, 2), -0.375);
        assert_eq!(layer_of(&volume, 100.0), 7);
        assert_eq!(layer_of(&volume, -100.0), 0);
    }
}
