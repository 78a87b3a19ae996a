//! The Rust side of bench/capi.sh: the same wall, frames and query batches
//! as bench/capi_bench.c, through the Rust API (`Mapper::distances`,
//! `Mapper::distance`, `Mapper::integrate_frame`). Prints one line per
//! measurement: `rust <what> <batch> <ns per point> <ns per call>`.
//!
//!   cargo run --release -p edtmap-capi --example query_bench

use std::time::Instant;

use edtmap::config::Config;
use edtmap::cpu::CpuBackend;
use edtmap::sensor::{Frame, Measurement, PointCloud};
use edtmap::Mapper;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

const CONFIG: &str = r#"
[sensor]
kind = "points"
min_range_m = 0.3
max_range_m = 10.0
[occupancy]
voxel_size_m = 0.1
local_size_m = [10.0, 10.0, 4.0]
[global]
max_distance_m = 2.0
"#;

/// The wall of bench/capi_bench.c: x = 2.05 m, 300 × 200 points.
fn wall() -> Vec<[f32; 3]> {
    let mut points = Vec::new();
    for iz in 0..200 {
        for iy in 0..300 {
            points.push([
                2.05f32,
                (-3.0 + 0.02 * f64::from(iy) + 0.01) as f32,
                (-2.0 + 0.02 * f64::from(iz) + 0.01) as f32,
            ]);
        }
    }
    points
}

/// `n` query points from the C program's generator (a 64-bit LCG).
fn queries(n: usize) -> Vec<[f64; 3]> {
    let mut s: u64 = 12345;
    let mut next = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n).map(|_| [-1.0 + 4.0 * next(), -3.0 + 6.0 * next(), -2.0 + 4.0 * next()]).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let config = Config::parse(CONFIG, "query_bench")?;
    let (sensor, params) = config.mapper_params()?;
    let mut mapper = Mapper::new_on(CpuBackend::default(), sensor, params)?;
    let cloud = wall();
    let frames = 20;
    let t = Instant::now();
    for f in 0..frames {
        let pose = Isometry3::from_parts(Translation3::new(0.0, 0.02 * f64::from(f), 0.0), UnitQuaternion::identity());
        let frame = Frame {
            stamp_s: f64::from(f),
            t_world_sensor: pose,
            measurement: Measurement::Points(PointCloud { points: cloud.clone() }),
        };
        mapper.integrate_frame(&frame)?;
    }
    let per_frame = t.elapsed().as_nanos() as f64 / f64::from(frames);
    println!("rust integrate {} {:.1} {:.0}", cloud.len(), per_frame / cloud.len() as f64, per_frame);
    let all = queries(1_000_000);
    for batch in [1usize, 1000, 1_000_000] {
        let calls = (2_000_000 / batch).clamp(3, 200_000);
        let mut sink = 0.0;
        let t = Instant::now();
        for c in 0..calls {
            let start = (c * batch) % (all.len() - batch + 1);
            let pts = &all[start..start + batch];
            if batch == 1 {
                sink += mapper.distance(pts[0]).distance_m;
            } else {
                sink += mapper.distances(pts)[batch / 2].distance_m;
            }
        }
        let per_call = t.elapsed().as_nanos() as f64 / calls as f64;
        println!("rust query {batch} {:.2} {:.0}", per_call / batch as f64, per_call);
        std::hint::black_box(sink);
    }
    Ok(())
}
