//! The surface a frame's beams hit, voxelised: the ground truth for recall.

use super::Scene;
use edtmap_core::sensor::{Frame, Sensor};
use edtmap_core::LocalVolume;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

impl Scene {
    /// Marks in `out` (one bool per voxel of `volume`, x fastest) the voxels
    /// holding a surface point that one of `frame`'s beams hits in the exact
    /// scene, whatever the frame's noise or dropout. These are the surfaces
    /// the sensor saw, so a map should hold them as obstacles.
    pub fn seen_surface(&self, sensor: &Sensor, frame: &Frame, volume: &LocalVolume, out: &mut Vec<bool>) {
        out.clear();
        out.resize(volume.len(), false);
        let mut rays = Vec::new();
        // Every beam, with or without a return in the frame.
        sensor.rays(&frame.measurement, true, &mut rays);
        let pose = &frame.t_world_sensor;
        let origin = pose.translation.vector;
        let max_m = sensor.max_range_m(&frame.measurement) as f64;
        let depth = matches!(sensor, Sensor::Depth(_));
        let hits: Vec<usize> = rays
            .par_iter()
            .filter_map(|ray| {
                // A camera's range limit applies to depth (z), not to range.
                let limit = if depth { max_m / (ray.dir[2] as f64).max(1e-6) } else { max_m };
                let dir = pose.rotation * Vector3::new(ray.dir[0] as f64, ray.dir[1] as f64, ray.dir[2] as f64);
                let d = self.ray_distance(origin.into(), dir.into(), frame.stamp_s, limit)?;
                let p = Point3::from(origin + dir * d);
                let v = edtmap_core::VoxelIndex::containing(p.coords.into(), volume.voxel_size_m)?;
                volume.local(v).map(|c| volume.linear(c))
            })
            .collect();
        for i in hits {
            out[i] = true;
        }
    }
}
