//! The reference answers of the C and C++ API tests (tests/capi): the Rust
//! `Mapper`, configured from TOML with the values `edtmap_params_default`
//! gives, integrates the same wall cloud and answers the same queries;
//! written as `n` (u64), then n distances, 3 n gradients (f64), n states
//! (u8), little-endian. The tests compare their answers bit for bit.
//!
//!   cargo run -p edtmap-capi --example wall_reference -- OUT.bin

use edtmap::config::Config;
use edtmap::cpu::CpuBackend;
use edtmap::sensor::{Frame, Measurement, PointCloud};
use edtmap::{Mapper, PointState};
use nalgebra::Isometry3;

const CONFIG: &str = r#"
[sensor]
kind = "points"
min_range_m = 0.3
max_range_m = 10.0
clear_no_return = false

[occupancy]
voxel_size_m = 0.1
local_size_m = [10.0, 10.0, 4.0]

[global]
max_distance_m = 2.0
mode = "exact"
"#;

/// The wall: x = 2.05 m (the middle of voxel 20), 150 × 100 points 2 cm
/// apart (tests/capi/wall.h).
fn wall() -> Vec<[f32; 3]> {
    let mut points = Vec::new();
    for iz in 0..100 {
        for iy in 0..150 {
            points.push([
                2.05f32,
                (-1.5 + 0.02 * f64::from(iy) + 0.01) as f32,
                (-1.0 + 0.02 * f64::from(iz) + 0.01) as f32,
            ]);
        }
    }
    points
}

/// The query points (tests/capi/wall.h).
fn queries() -> Vec<[f64; 3]> {
    (0..200).map(|i| [-0.5 + 0.0137 * f64::from(i), 0.05 + 0.003 * f64::from(i), 0.05 - 0.002 * f64::from(i)]).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).ok_or("usage: wall_reference OUT.bin")?;
    let config = Config::parse(CONFIG, "wall_reference")?;
    let (sensor, params) = config.mapper_params()?;
    let mut mapper = Mapper::new_on(CpuBackend::default(), sensor, params)?;
    let frame = Frame {
        stamp_s: 0.0,
        t_world_sensor: Isometry3::identity(),
        measurement: Measurement::Points(PointCloud { points: wall() }),
    };
    mapper.integrate_frame(&frame)?;
    let q = queries();
    let answers: Vec<_> = q.iter().map(|&p| mapper.distance(p)).collect();
    let mut bytes = (q.len() as u64).to_le_bytes().to_vec();
    answers.iter().for_each(|a| bytes.extend(a.distance_m.to_le_bytes()));
    answers.iter().for_each(|a| a.gradient.iter().for_each(|g| bytes.extend(g.to_le_bytes())));
    answers.iter().for_each(|a| {
        bytes.push(match a.state {
            PointState::Outside => 0,
            PointState::Unknown => 1,
            PointState::Free => 2,
            PointState::Occupied => 3,
        })
    });
    std::fs::write(&out, bytes)?;
    println!("wrote {} answers to {out}", q.len());
    Ok(())
}
