//! Queries planners make of the global map, in metres and the world frame:
//! distance and its gradient by trilinear interpolation between voxel
//! centres, single or batched (in parallel), a point's occupancy state, and
//! a dense box of voxel distances.
//!
//! A distance beyond the cutoff reads as `max_distance_m` and is flagged
//! `saturated`. With `signed`, a voxel that is an obstacle reads as minus
//! the distance from its centre to the nearest non-obstacle voxel centre,
//! so the zero crossing lies halfway between an obstacle and free space.

use crate::CpuError;
use edtmap_core::{CoreError, GlobalMap, VoxelIndex, VoxelState, FAR_DIST_SQ};
use rayon::prelude::*;

/// Where a point lies in the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PointState {
    /// In no block the sensors have touched (or not a finite point).
    Outside,
    /// In a mapped block but never observed.
    Unknown,
    /// Observed free.
    Free,
    /// Observed occupied, or a fixed obstacle.
    Occupied,
}

/// The answer to a distance query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Distance {
    /// Distance to the nearest obstacle, metres (NaN for a non-finite point).
    pub distance_m: f64,
    /// Gradient of the distance, metres per metre (zero where flat or unknown).
    pub gradient: [f64; 3],
    /// State of the voxel holding the point.
    pub state: PointState,
    /// Whether that voxel was ever observed.
    pub observed: bool,
    /// Whether a voxel used had no obstacle within the cutoff, so the
    /// distance is a lower bound.
    pub saturated: bool,
}

/// State of the voxel holding world point `p` (metres).
pub fn point_state(map: &GlobalMap, p: [f64; 3]) -> PointState {
    VoxelIndex::containing(p, map.voxel_size_m()).map_or(PointState::Outside, |v| voxel_state(map, v))
}

/// State of world voxel `v`.
pub fn voxel_state(map: &GlobalMap, v: VoxelIndex) -> PointState {
    if map.fixed.contains(v) {
        return PointState::Occupied;
    }
    match map.occupancy.get(v.block()) {
        None => PointState::Outside,
        Some(b) => match map.log_odds.state(b.log_odds[v.offset_in_block()]) {
            VoxelState::Unknown => PointState::Unknown,
            VoxelState::Free => PointState::Free,
            VoxelState::Occupied => PointState::Occupied,
        },
    }
}

/// Distance of voxel `v`'s centre, metres, and whether it is saturated.
pub fn voxel_distance(map: &GlobalMap, v: VoxelIndex, signed: bool) -> (f64, bool) {
    let vs = map.voxel_size_m();
    let (d, _) = map.entry(v);
    if signed && d == 0 {
        let (inside, saturated) = distance_to_free(map, v);
        return (-inside * vs, saturated);
    }
    if d == FAR_DIST_SQ {
        (map.params.max_distance_m, true)
    } else {
        (f64::from(d).sqrt() * vs, false)
    }
}

/// Distance and gradient at world point `p`, interpolated between the
/// eight voxel centres around it.
pub fn distance(map: &GlobalMap, p: [f64; 3], signed: bool) -> Distance {
    let vs = map.voxel_size_m();
    let Some(v) = VoxelIndex::containing(p, vs) else {
        return Distance { distance_m: f64::NAN, gradient: [0.0; 3], state: PointState::Outside, observed: false, saturated: false };
    };
    let state = voxel_state(map, v);
    let observed = matches!(map.state(v), VoxelState::Free | VoxelState::Occupied);
    let u = p.map(|c| c / vs - 0.5);
    let base = u.map(|c| c.floor());
    let f = [0, 1, 2].map(|a| u[a] - base[a]);
    let mut corner = [[[0.0; 2]; 2]; 2];
    let mut saturated = false;
    for (k, slot) in corner.iter_mut().flatten().flatten().enumerate() {
        let (dx, dy, dz) = ((k >> 2) & 1, (k >> 1) & 1, k & 1);
        let c = VoxelIndex([base[0] as i32 + dx as i32, base[1] as i32 + dy as i32, base[2] as i32 + dz as i32]);
        let (d, s) = voxel_distance(map, c, signed);
        saturated |= s;
        *slot = d;
    }
    let (value, gradient) = trilinear(&corner, f);
    Distance { distance_m: value, gradient: gradient.map(|g| g / vs), state, observed, saturated }
}

/// [`distance`] of every point, in parallel; same order as `points`.
pub fn distances(map: &GlobalMap, points: &[[f64; 3]], signed: bool) -> Vec<Distance> {
    points.par_iter().map(|&p| distance(map, p, signed)).collect()
}

/// Trilinear value and gradient (per unit of `f`) of `c[x][y][z]` at `f`.
fn trilinear(c: &[[[f64; 2]; 2]; 2], f: [f64; 3]) -> (f64, [f64; 3]) {
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let plane = |x: usize| {
        let (y0, y1) = (lerp(c[x][0][0], c[x][0][1], f[2]), lerp(c[x][1][0], c[x][1][1], f[2]));
        (lerp(y0, y1, f[1]), y1 - y0, lerp(c[x][0][1] - c[x][0][0], c[x][1][1] - c[x][1][0], f[1]))
    };
    let (p0, dy0, dz0) = plane(0);
    let (p1, dy1, dz1) = plane(1);
    (lerp(p0, p1, f[0]), [p1 - p0, lerp(dy0, dy1, f[0]), lerp(dz0, dz1, f[0])])
}

/// Distance in voxels from obstacle voxel `v` to the nearest voxel that is
/// not an obstacle, searched out to the cutoff; saturated if none.
fn distance_to_free(map: &GlobalMap, v: VoxelIndex) -> (f64, bool) {
    let obstacles = map.obstacles();
    let reach = map.cutoff.reach;
    let mut best = u64::MAX;
    for r in 1..=reach {
        if best <= (r as u64 - 1).pow(2) {
            break;
        }
        for dz in -r..=r {
            for dy in -r..=r {
                for dx in -r..=r {
                    if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                        continue;
                    }
                    let d = (dx * dx + dy * dy + dz * dz) as u64;
                    if d < best && !obstacles.contains(VoxelIndex([v.0[0] + dx, v.0[1] + dy, v.0[2] + dz])) {
                        best = d;
                    }
                }
            }
        }
    }
    if best == u64::MAX {
        (f64::from(reach), true)
    } else {
        ((best as f64).sqrt(), false)
    }
}

/// A dense box of voxel distances.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceBox {
    /// World index of the lowest corner voxel.
    pub origin: VoxelIndex,
    /// Voxels along x, y, z.
    pub dims: [usize; 3],
    /// Distance of each voxel centre, metres, x fastest; saturated voxels
    /// hold `max_distance_m`.
    pub distance_m: Vec<f32>,
    /// State of each voxel: 0 outside, 1 unknown, 2 free, 3 occupied.
    pub state: Vec<u8>,
}

/// Most voxels one box export may hold.
pub const MAX_BOX_VOXELS: usize = 1 << 28;

/// Every voxel overlapping the box `[min_m, max_m)` (metres).
pub fn distance_box(map: &GlobalMap, min_m: [f64; 3], max_m: [f64; 3], signed: bool) -> Result<DistanceBox, CpuError> {
    let vs = map.voxel_size_m();
    let bad = |reason| CoreError::InvalidParam { field: "box", value: format!("{min_m:?} .. {max_m:?}"), reason };
    if (0..3).any(|a| !min_m[a].is_finite() || !max_m[a].is_finite() || min_m[a] >= max_m[a]) {
        return Err(bad("corners must be finite with min below max on every axis").into());
    }
    let lo = VoxelIndex::containing(min_m, vs).ok_or(bad("corners must be finite"))?;
    // The last voxel overlapping [min, max) on each axis.
    let last = max_m.map(|m| (m / vs).ceil() - 1.0);
    if last.iter().any(|&l| !(l >= f64::from(i32::MIN) && l <= f64::from(i32::MAX))) {
        return Err(bad("corners must lie in the voxel index range").into());
    }
    let hi = VoxelIndex(last.map(|l| l as i32));
    let dims = [0, 1, 2].map(|a| (i64::from(hi.0[a]) - i64::from(lo.0[a]) + 1) as usize);
    if dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d)).is_none_or(|n| n > MAX_BOX_VOXELS) {
        return Err(bad("more than 2^28 voxels").into());
    }
    let [nx, ny, nz] = dims;
    let at = |i: usize| VoxelIndex([lo.0[0] + (i % nx) as i32, lo.0[1] + ((i / nx) % ny) as i32, lo.0[2] + (i / (nx * ny)) as i32]);
    let (distance_m, state) = (0..nx * ny * nz)
        .into_par_iter()
        .map(|i| {
            let v = at(i);
            (voxel_distance(map, v, signed).0 as f32, voxel_state(map, v) as u8)
        })
        .unzip();
    Ok(DistanceBox { origin: lo, dims, distance_m, state })
}
