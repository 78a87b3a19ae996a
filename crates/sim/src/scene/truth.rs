//! Exact ground-truth occupancy of a local volume.
//!
//! Each solid is rasterised over the voxels of its bounding box only, and
//! each of those voxels is tested exactly (closed cube against closed
//! solid); z slices run in parallel.

use super::Scene;
use crate::geometry::Primitive;
use edtmap_core::LocalVolume;
use rayon::prelude::*;
use std::ops::Range;

impl Scene {
    /// Fills `out` with one flag per voxel of `volume` (local linear order,
    /// x fastest, as [`LocalVolume::linear`]): true iff the voxel's closed
    /// cube meets a solid at time `t_s`.
    pub fn ground_truth(&self, volume: &LocalVolume, t_s: f64, out: &mut Vec<bool>) {
        out.clear();
        out.resize(volume.len(), false);
        let solids: Vec<(Primitive, [Range<usize>; 3])> =
            self.solids_at(t_s).into_iter().filter_map(|s| voxel_span(&s, volume).map(|span| (s, span))).collect();
        let slice = volume.dims[0] * volume.dims[1];
        out.par_chunks_mut(slice).enumerate().for_each(|(z, flags)| {
            for (solid, [xs, ys, zs]) in &solids {
                if zs.contains(&z) {
                    rasterise(solid, volume, z, xs, ys, flags);
                }
            }
        });
    }
}

/// Marks the voxels of slice `z` within `xs × ys` that meet `solid`.
fn rasterise(
    solid: &Primitive,
    volume: &LocalVolume,
    z: usize,
    xs: &Range<usize>,
    ys: &Range<usize>,
    flags: &mut [bool],
) {
    let s = volume.voxel_size_m;
    let corner = |a: usize, local: usize| (volume.origin.0[a] as f64 + local as f64) * s;
    let (z_lo, z_hi) = (corner(2, z), corner(2, z + 1));
    for y in ys.clone() {
        let (y_lo, y_hi) = (corner(1, y), corner(1, y + 1));
        let row = &mut flags[y * volume.dims[0]..(y + 1) * volume.dims[0]];
        for x in xs.clone() {
            if !row[x] && solid.intersects_box([corner(0, x), y_lo, z_lo], [corner(0, x + 1), y_hi, z_hi]) {
                row[x] = true;
            }
        }
    }
}

/// Local voxel ranges that may meet `solid` (its bounds, widened by a voxel
/// for closed-cube contact and rounding, clipped to the volume); `None` if
/// empty.
fn voxel_span(solid: &Primitive, volume: &LocalVolume) -> Option<[Range<usize>; 3]> {
    let b = solid.bounds();
    let s = volume.voxel_size_m;
    let mut span = [0..0, 0..0, 0..0];
    for (a, range) in span.iter_mut().enumerate() {
        let origin = volume.origin.0[a] as f64;
        let n = volume.dims[a] as f64;
        // Infinite bounds clamp to the volume's edges.
        let lo = ((b.min[a] / s).floor() - 1.0 - origin).clamp(0.0, n);
        let hi = ((b.max[a] / s).floor() + 2.0 - origin).clamp(0.0, n);
        if lo >= hi {
            return None;
        }
        *range = lo as usize..hi as usize;
    }
    Some(span)
}
