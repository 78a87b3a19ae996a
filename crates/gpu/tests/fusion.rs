//! Fusion on the device against the CPU's `edtmap_core::fuse`: random rays
//! cast again and again over a scrolling volume (so log-odds reach their
//! clamps and blocks go in and out of the device's pool), with the host
//! map changed behind the device's back between frames (a voxel rewritten,
//! blocks dropped, a snapshot holding blocks). Each frame's map must be the
//! CPU's bit for bit, and its report the same.

mod common;

use edtmap_core::fixed_ray::prepare_rays;
use edtmap_core::sensor::SensorRay;
use edtmap_core::{fuse, Backend, BlockKey, LocalVolume, Observations, OccupancyMap, OccupancyParams, VoxelIndex};
use edtmap_cpu::CpuBackend;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

/// Every block of `map`, sorted, as bits.
fn snapshot(map: &OccupancyMap) -> Vec<(BlockKey, Vec<u32>)> {
    let mut blocks: Vec<(BlockKey, Vec<u32>)> =
        map.iter().map(|(k, b)| (k, b.log_odds.iter().map(|l| l.to_bits()).collect())).collect();
    blocks.sort_by_key(|b| b.0);
    blocks
}

#[test]
fn device_fusion_is_the_cpus_frame_after_frame() {
    let Some(mut gpu) = common::gpu_or_skip("device fusion") else { return };
    gpu.set_deferred_observations(true);
    let mut cpu = CpuBackend::default();
    let lo = OccupancyParams::default().log_odds().expect("defaults");
    let (mut cpu_map, mut gpu_map) = (OccupancyMap::new(), OccupancyMap::new());
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move |n: u64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state % n
    };
    let mut held = Vec::new();
    for frame in 0..40 {
        // A 36 x 30 x 20 volume (not block-aligned) drifting along x and back.
        let shift = [(frame % 12) * 3 - 10, -7, 2 - (frame % 3)];
        let vol = LocalVolume { origin: VoxelIndex(shift), dims: [36, 30, 20], voxel_size_m: 0.1 };
        let centre = [
            0.1 * (f64::from(shift[0]) + 18.0),
            0.1 * (f64::from(shift[1]) + 15.0),
            0.1 * (f64::from(shift[2]) + 10.0),
        ];
        let pose =
            Isometry3::from_parts(Translation3::new(centre[0], centre[1], centre[2]), UnitQuaternion::identity());
        // Few directions, so voxels are seen again and again.
        let rays: Vec<SensorRay> = (0..400)
            .map(|_| {
                let d = [0, 1, 2].map(|_| next(2001) as f32 / 1000.0 - 1.0);
                let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-3);
                SensorRay { dir: d.map(|c| c / n), range_m: 0.2 + next(150) as f32 / 100.0, hit: next(4) != 0 }
            })
            .collect();
        let mut fixed = Vec::new();
        let q = prepare_rays(&vol, &pose, &rays, 0.087, &mut fixed).expect("rays fit");
        let (cpu_obs, gpu_obs) = (Observations::new(vol), Observations::new(vol));
        cpu.cast_rays(&fixed, q, &cpu_obs).expect("cpu rays");
        gpu.cast_rays(&fixed, q, &gpu_obs).expect("gpu rays");
        let want = fuse(&mut cpu_map, &cpu_obs, &lo);
        let got = gpu.fuse(&mut gpu_map, &gpu_obs, &lo).expect("device fusion");
        assert_eq!(got, want, "frame {frame}: report");
        assert!(want.voxels_updated > 0, "frame {frame}: nothing observed");
        assert!(snapshot(&cpu_map) == snapshot(&gpu_map), "frame {frame}: maps differ");

        // Changes the device does not see, made to both maps alike.
        match frame % 4 {
            0 => {
                let keys: Vec<BlockKey> = cpu_map.iter().map(|(k, _)| k).collect();
                let k = keys[next(keys.len() as u64) as usize];
                let (o, v) = (next(512) as usize, next(100) as f32 / 10.0 - 5.0);
                cpu_map.get_or_insert(k).log_odds.set(o, v);
                gpu_map.get_or_insert(k).log_odds.set(o, v);
            }
            1 => {
                let x = next(4) as i32 - 1;
                cpu_map.remove_where(|k| k.0[0] == x);
                gpu_map.remove_where(|k| k.0[0] == x);
            }
            2 => held.push(gpu_map.clone()),
            _ => held.clear(),
        }
    }
    // The clamps were reached: some voxel sits at each.
    let values: Vec<f32> = cpu_map.iter().flat_map(|(_, b)| b.log_odds.iter().collect::<Vec<_>>()).collect();
    assert!(values.contains(&lo.max) && values.contains(&lo.min), "clamps never reached");
}
