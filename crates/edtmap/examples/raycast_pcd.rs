//! Ray casting throughput on a real point cloud, the edtmap half of
//! `bench/raycast.sh` (OctoMap's `insertPointCloud` is the other half).
//!
//! ```text
//! cargo run --release -p edtmap --example raycast_pcd -- SCAN.pcd --voxel-size 0.1 --max-range 30 --repeat 7
//! ```
//! Each repeat starts from an empty map, as the OctoMap harness starts from
//! an empty tree, and times the whole insertion: rays from the points, the
//! 3D DDA into the local volume, and the log-odds fusion into the block map.
//! Points beyond the maximum range clear space up to it, as in OctoMap.
//! Prints one JSON line.

use edtmap::cpu::CpuBackend;
use edtmap::fuse;
use edtmap::sensor::{Frame, Measurement, RangeLimits, Sensor};
use edtmap::stages::{Construction, OccupancyStage, OgmOptions};
use edtmap::{LocalVolume, OccupancyMap, OccupancyParams, VolumeParams};
use nalgebra::Isometry3;
use std::time::Instant;

struct Args {
    pcd: String,
    voxel_size_m: f64,
    max_range_m: f32,
    repeat: usize,
}

fn parse_args() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let mut args = Args { pcd: String::new(), voxel_size_m: 0.1, max_range_m: 30.0, repeat: 7 };
    while let Some(a) = it.next() {
        let mut value = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match a.as_str() {
            "--voxel-size" => args.voxel_size_m = value(&a)?.parse().map_err(|e| format!("--voxel-size: {e}"))?,
            "--max-range" => args.max_range_m = value(&a)?.parse().map_err(|e| format!("--max-range: {e}"))?,
            "--repeat" => args.repeat = value(&a)?.parse().map_err(|e| format!("--repeat: {e}"))?,
            _ if args.pcd.is_empty() && !a.starts_with("--") => args.pcd = a,
            _ => return Err(format!("unexpected argument {a}")),
        }
    }
    if args.pcd.is_empty() || args.repeat == 0 {
        return Err("usage: raycast_pcd SCAN.pcd [--voxel-size M] [--max-range M] [--repeat N≥1]".into());
    }
    Ok(args)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = parse_args()?;
    let cloud = edtmap_io::read_pcd(std::path::Path::new(&args.pcd))?;
    let points = cloud.points.len();
    let range = RangeLimits { min_m: 0.0, max_m: args.max_range_m };
    // The local volume spans every ray: ±max range across, the cloud's
    // height range (within ±max range) vertically.
    let (zlo, zhi) = cloud
        .points
        .iter()
        .filter(|p| p.iter().all(|c| c.is_finite()))
        .fold((0.0f32, 0.0f32), |(lo, hi), p| (lo.min(p[2]), hi.max(p[2])));
    let (zlo, zhi) = (zlo.max(-args.max_range_m) as f64, zhi.min(args.max_range_m) as f64);
    let edge = 2.0 * args.max_range_m as f64 + 2.0 * args.voxel_size_m;
    let params = VolumeParams {
        size_m: [edge, edge, zhi - zlo + 2.0 * args.voxel_size_m],
        fixed_height_m: Some((zlo + zhi) / 2.0),
    };
    let volume = LocalVolume::centred(&params, args.voxel_size_m, [0.0; 3])?;
    let sensor = Sensor::Points(range);
    let frame = Frame { stamp_s: 0.0, t_world_sensor: Isometry3::identity(), measurement: Measurement::Points(cloud) };
    sensor.check(&frame)?;
    // OctoMap frees every voxel before the return: no free margin.
    let opts = OgmOptions {
        construction: Construction::RayCasting,
        clear_no_return: true,
        free_margin_m: Some(0.0),
        ..OgmOptions::default()
    };
    let lo = OccupancyParams::default().log_odds()?;
    let mut stage = OccupancyStage::default();
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..args.repeat {
        let mut map = OccupancyMap::new();
        let t = Instant::now();
        let obs = stage.observe(&mut CpuBackend::default(), &sensor, &frame, volume, &opts)?;
        let report = fuse(&mut map, obs, &lo);
        times.push(t.elapsed().as_secs_f64() * 1e3);
        last = Some((map, report));
    }
    let (map, report) = last.ok_or("no repeat ran")?;
    let occupied = map
        .iter()
        .flat_map(|(_, b)| b.log_odds.iter())
        .filter(|&v| lo.state(v) == edtmap::VoxelState::Occupied)
        .count();
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "{{\"tool\":\"edtmap\",\"pcd\":\"{}\",\"voxel_size_m\":{},\"max_range_m\":{},\"points\":{points},\"repeats\":{},\"threads\":{},\"median_ms\":{:.3},\"min_ms\":{:.3},\"voxels_updated\":{},\"occupied_voxels\":{occupied},\"blocks\":{},\"local_dims\":{:?}}}",
        args.pcd.replace('\\', "\\\\").replace('"', "\\\""),
        args.voxel_size_m,
        args.max_range_m,
        args.repeat,
        rayon::current_num_threads(),
        sorted[sorted.len() / 2],
        sorted[0],
        report.voxels_updated,
        map.len(),
        volume.dims,
    );
    Ok(())
}
