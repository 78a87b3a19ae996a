//! What the node publishes, built from a map snapshot: the ESDF cloud of
//! the window, the occupied voxels, a horizontal slice as a cloud and as a
//! 2D occupancy grid, and the frame statistics.

use super::types::{
    DiagnosticArray, DiagnosticStatus, Header, KeyValue, MapMetaData, OccupancyGrid, PointCloud2, Pose, Time,
    Transform, Vector3,
};
use edtmap::query::{voxel_distance, voxel_state};
use edtmap::{BlockKey, GlobalMap, LocalVolume, PointState, VoxelIndex, BLOCK_VOXELS};

/// The voxels of `volume` block by block: `f(voxel)` for each voxel of
/// each allocated occupancy block the volume overlaps.
fn window_voxels(map: &GlobalMap, volume: &LocalVolume, mut f: impl FnMut(VoxelIndex)) {
    for key in volume.blocks() {
        if map.occupancy().get(key).is_none() {
            continue;
        }
        let [xs, ys, zs] = volume.block_span(key);
        for z in zs.clone() {
            for y in ys.clone() {
                for x in xs.clone() {
                    f(volume.world([x, y, z]));
                }
            }
        }
    }
}

/// `/edtmap/esdf_pointcloud`: x, y, z, distance (metres) of every observed
/// voxel of the window within the cutoff (nvblox's convention) whose
/// centre's height is within `[z_m[0], z_m[1]]`.
pub(crate) fn esdf_cloud(map: &GlobalMap, volume: &LocalVolume, z_m: [f64; 2], header: Header) -> PointCloud2 {
    let vs = map.voxel_size_m();
    let mut points = Vec::new();
    window_voxels(map, volume, |v| {
        if matches!(voxel_state(map, v), PointState::Free | PointState::Occupied) {
            let (d, saturated) = voxel_distance(map, v, false);
            let c = v.centre(vs);
            if !saturated && (z_m[0]..=z_m[1]).contains(&c[2]) {
                points.extend([c[0] as f32, c[1] as f32, c[2] as f32, d as f32]);
            }
        }
    });
    PointCloud2::from_f32_fields(header, &["x", "y", "z", "distance"], &points)
}

/// `/edtmap/occupied_pointcloud`: x, y, z of the occupied voxels of the
/// window, or of the whole map when `volume` is `None`.
pub(crate) fn occupied_cloud(map: &GlobalMap, volume: Option<&LocalVolume>, header: Header) -> PointCloud2 {
    let vs = map.voxel_size_m();
    let mut points = Vec::new();
    let mut push = |v: VoxelIndex| {
        if voxel_state(map, v) == PointState::Occupied {
            let c = v.centre(vs);
            points.extend([c[0] as f32, c[1] as f32, c[2] as f32]);
        }
    };
    match volume {
        Some(volume) => window_voxels(map, volume, push),
        None => {
            let mut keys: Vec<BlockKey> = map.occupancy().iter().map(|(k, _)| k).collect();
            keys.sort_by_key(|k| k.0);
            for key in keys {
                (0..BLOCK_VOXELS).for_each(|o| push(key.voxel(o)));
            }
        }
    }
    PointCloud2::from_f32_fields(header, &["x", "y", "z"], &points)
}

/// The window's layer at `height_m` (clamped into the window): its z index.
fn slice_z(volume: &LocalVolume, height_m: f64) -> i32 {
    let z = (height_m / volume.voxel_size_m).floor() as i64;
    let lo = i64::from(volume.origin.0[2]);
    z.clamp(lo, lo + volume.dims[2] as i64 - 1) as i32
}

/// `/edtmap/distance_slice` and `/edtmap/occupancy_grid`: the window's
/// horizontal layer at `height_m`; the cloud holds every observed voxel
/// with its distance (the cutoff where none is nearer), the grid -1
/// unknown, 0 free, 100 occupied.
pub(crate) fn slice(
    map: &GlobalMap,
    volume: &LocalVolume,
    height_m: f64,
    header: Header,
) -> (PointCloud2, OccupancyGrid) {
    let vs = map.voxel_size_m();
    let z = slice_z(volume, height_m);
    let [nx, ny, _] = volume.dims;
    let mut points = Vec::new();
    let mut cells = Vec::with_capacity(nx * ny);
    for y in 0..ny {
        for x in 0..nx {
            let v = VoxelIndex([volume.origin.0[0] + x as i32, volume.origin.0[1] + y as i32, z]);
            let state = voxel_state(map, v);
            cells.push(match state {
                PointState::Occupied => 100,
                PointState::Free => 0,
                PointState::Unknown | PointState::Outside => -1,
            });
            if matches!(state, PointState::Free | PointState::Occupied) {
                let (d, _) = voxel_distance(map, v, false);
                let c = v.centre(vs);
                points.push([c[0] as f32, c[1] as f32, c[2] as f32, d as f32]);
            }
        }
    }
    let flat: Vec<f32> = points.into_iter().flatten().collect();
    let corner = VoxelIndex([volume.origin.0[0], volume.origin.0[1], z]);
    let origin = Pose {
        translation: Vector3 {
            x: f64::from(corner.0[0]) * vs,
            y: f64::from(corner.0[1]) * vs,
            z: (f64::from(z) + 0.5) * vs,
        },
        ..Transform::default()
    };
    let info = MapMetaData {
        map_load_time: Time::from_ns(header.stamp_ns),
        resolution: vs as f32,
        width: nx as u32,
        height: ny as u32,
        origin,
    };
    (
        PointCloud2::from_f32_fields(header.clone(), &["x", "y", "z", "distance"], &flat),
        OccupancyGrid { header, info, data: cells },
    )
}

/// `/edtmap/frame_stats`: one status named `edtmap` with the given values.
pub(crate) fn frame_stats(
    stamp: Time,
    frame_id: &str,
    level: u8,
    message: String,
    values: Vec<(&str, String)>,
) -> DiagnosticArray {
    let values = values.into_iter().map(|(k, v)| KeyValue { key: k.into(), value: v }).collect();
    let status = DiagnosticStatus { level, name: "edtmap".into(), message, hardware_id: frame_id.into(), values };
    DiagnosticArray { header: Header { stamp_ns: stamp.ns(), frame_id: frame_id.into() }, status: vec![status] }
}

#[cfg(test)]
mod tests {
    use super::*;
    use edtmap::sensor::{Frame, Measurement, PointCloud, RangeLimits, Sensor};
    use edtmap::{Mapper, MapperParams};
    use nalgebra::Isometry3;

    /// A wall at x = 2 m seen from the origin: the cloud's distances are
    /// the distance to the wall's voxels, checked against brute force.
    #[test]
    fn the_esdf_cloud_holds_observed_voxels_within_the_cutoff_with_their_distance() {
        let vs = 0.1;
        let sensor = Sensor::Points(RangeLimits { min_m: 0.1, max_m: 20.0 });
        let mut mapper = Mapper::new(sensor, MapperParams::for_voxel_size(vs)).expect("mapper");
        let mut wall = Vec::new();
        for j in -10..=10 {
            for k in -5..=5 {
                wall.push([2.05f32, j as f32 * 0.1 + 0.05, k as f32 * 0.1 + 0.05]);
            }
        }
        let frame = Frame {
            stamp_s: 0.0,
            t_world_sensor: Isometry3::translation(0.0, 0.0, 0.0),
            measurement: Measurement::Points(PointCloud { points: wall.clone() }),
        };
        mapper.integrate_frame(&frame).expect("frame");
        let volume = *mapper.local_volume().expect("volume");
        let map = mapper.map();
        let occupied: Vec<VoxelIndex> = wall
            .iter()
            .filter_map(|p| VoxelIndex::containing([f64::from(p[0]), f64::from(p[1]), f64::from(p[2])], vs))
            .collect();
        let msg = esdf_cloud(map, &volume, [f64::MIN, f64::MAX], Header::default());
        assert_eq!(msg.point_step, 16);
        let values: Vec<f32> = msg.data.chunks(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        assert!(msg.width > 100, "{} points", msg.width);
        let cutoff = map.params().max_distance_m;
        for p in values.chunks(4) {
            let v = VoxelIndex::containing([f64::from(p[0]), f64::from(p[1]), f64::from(p[2])], vs).expect("finite");
            let brute = occupied
                .iter()
                .map(|o| (0..3).map(|a| f64::from(o.0[a] - v.0[a]).powi(2)).sum::<f64>().sqrt() * vs)
                .fold(f64::INFINITY, f64::min);
            assert!((f64::from(p[3]) - brute).abs() < 1e-5, "{p:?}: {} vs {brute}", p[3]);
            assert!(brute <= cutoff + 1e-9);
        }
        // A height band keeps exactly the voxels of the cloud within it.
        let band = [-0.1, 0.1];
        let banded = esdf_cloud(map, &volume, band, Header::default());
        let within: Vec<&[f32]> = values.chunks(4).filter(|p| (band[0]..=band[1]).contains(&f64::from(p[2]))).collect();
        let banded_values: Vec<f32> =
            banded.data.chunks(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        assert!(banded.width > 0 && banded.width < msg.width, "{} of {}", banded.width, msg.width);
        assert_eq!(banded_values, within.concat());
        let occ = occupied_cloud(map, Some(&volume), Header::default());
        assert_eq!(occ.width as usize, occupied.len());
        let (slice_cloud, grid) = slice(map, &volume, 0.05, Header::default());
        assert_eq!(grid.data.len(), volume.dims[0] * volume.dims[1]);
        assert_eq!(grid.data.iter().filter(|&&c| c == 100).count(), 21);
        assert!(slice_cloud.width > 0);
    }
}
