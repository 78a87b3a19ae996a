//! Queries planners make of the global map, in metres and the world frame:
//! distance and its gradient (unsigned by trilinear interpolation between
//! voxel centres, signed to the obstacle surface), single or batched (in
//! parallel), a point's occupancy state, and a dense box of voxel distances.
//!
//! On a planar map, distances are those of the point's layer of voxels:
//! interpolated in x and y, with no gradient along z, and a signed
//! distance measured within the layer.
//!
//! A distance beyond the cutoff reads as `max_distance_m` and is flagged
//! `saturated`. So does a point outside the mapped area with no obstacle
//! within the cutoff: a planner may read it as free but unknown, as its
//! state `Outside` says. The unsigned distance is measured between voxel centres
//! (zero at an obstacle voxel's centre) and interpolated trilinearly. With
//! `signed`, the distance is instead that to the surface of the obstacle
//! voxels, negative exactly inside them (below: why it is not
//! interpolated). A point farther than [`MAX_QUERY_INDEX`] voxels from the
//! origin on any axis, or not finite, has no voxel: its distance is NaN.
//!
//! # Signed distance
//!
//! The obstacle voxels (occupied or fixed; unknown voxels are free, as in
//! the EDT) are solid cubes, and their surface is the set of faces between
//! an obstacle voxel and one that is not. A point's signed distance is
//! measured to the closest point of that surface, not between voxel
//! centres:
//!
//! * **outside** (the point's voxel is not an obstacle): the distance to the
//!   nearest obstacle cube, found among the EDT's nearest obstacles of the
//!   point's voxel and its 26 neighbours; `>= 0`, zero only on the surface.
//!   The nearest obstacle by centre is nearly always the nearest cube; where
//!   it is not, the answer is a few hundredths of a voxel too long;
//! * **inside** (the point's voxel is an obstacle): minus the distance to the
//!   nearest cube that is not an obstacle, searched shell by shell out to
//!   the cutoff; `<= 0`, zero only on the surface.
//!
//! So the sign is exactly that of the point's voxel, and the gradient is
//! the unit vector from the closest surface point towards the point
//! (outside) or from the point towards it (inside): the direction in which
//! the signed distance grows. Where two surface points are equally close
//! (the medial axis) the first found is used, so the gradient is still of
//! unit length but jumps there; on the surface itself (distance zero) it is
//! the face's outward normal, the axis along which the point lies farthest
//! out of the obstacle cube.
//!
//! Trilinear interpolation of signed voxel values is not used because it
//! cannot give this: with centre-to-centre values on both sides the value
//! falls by two voxels over the one voxel between an obstacle centre and a
//! free one (gradient length 2), and at a concave corner (a free voxel with
//! three obstacle voxels among the eight around it) the interpolated zero
//! crossing lies inside the free voxel, so free points read negative.

mod signed;

use crate::{CoreError, GlobalMap, VoxelIndex, VoxelState, FAR_DIST_SQ};
use rayon::prelude::*;

/// Largest voxel index, in absolute value on any axis, that a distance
/// query visits: 2^30, which leaves the neighbours and the searches of a
/// query (out to the cutoff's reach, at most 10,000 voxels) inside `i32`.
pub const MAX_QUERY_INDEX: i32 = 1 << 30;

/// Largest coordinate, in absolute value (metres), that a distance query
/// answers at voxel size `voxel_size_m`: [`MAX_QUERY_INDEX`] voxels.
pub fn max_query_coordinate_m(voxel_size_m: f64) -> f64 {
    f64::from(MAX_QUERY_INDEX) * voxel_size_m
}

/// The voxel holding `p` if it lies within [`MAX_QUERY_INDEX`] voxels of
/// the origin on every axis (so its trilinear corners and searches do too).
fn query_voxel(p: [f64; 3], voxel_size_m: f64) -> Option<VoxelIndex> {
    VoxelIndex::containing(p, voxel_size_m).filter(|v| in_query_range(*v))
}

fn in_query_range(v: VoxelIndex) -> bool {
    v.0.iter().all(|&i| (-MAX_QUERY_INDEX..MAX_QUERY_INDEX).contains(&i))
}

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
    /// Distance to the nearest obstacle, metres: `max_distance_m` when
    /// saturated, NaN for a point that is not finite or lies beyond
    /// [`MAX_QUERY_INDEX`] voxels. Signed: negative inside obstacle voxels.
    pub distance_m: f64,
    /// Gradient of the distance, metres per metre. Unsigned: that of the
    /// trilinear interpolant (unit length in the open, shorter or longer
    /// next to obstacle voxels and where nearest obstacles change; zero
    /// where saturated). Signed: of unit length except where saturated
    /// (zero); see the module docs for ties and the surface itself.
    pub gradient: [f64; 3],
    /// State of the voxel holding the point.
    pub state: PointState,
    /// Whether that voxel was ever observed.
    pub observed: bool,
    /// Whether a voxel used had no obstacle within the cutoff, so the
    /// distance is a lower bound (`max_distance_m` where no voxel used had
    /// one). Signed: whether the distance reads the cutoff.
    pub saturated: bool,
}

/// State of the voxel holding world point `p` (metres).
pub fn point_state(map: &GlobalMap, p: [f64; 3]) -> PointState {
    VoxelIndex::containing(p, map.voxel_size_m()).map_or(PointState::Outside, |v| voxel_state(map, v))
}

/// State of world voxel `v`.
pub fn voxel_state(map: &GlobalMap, v: VoxelIndex) -> PointState {
    if map.fixed_obstacles().contains(v) {
        return PointState::Occupied;
    }
    match map.occupancy().get(v.block()) {
        None => PointState::Outside,
        Some(b) => match map.log_odds().state(b.log_odds[v.offset_in_block()]) {
            VoxelState::Unknown => PointState::Unknown,
            VoxelState::Free => PointState::Free,
            VoxelState::Occupied => PointState::Occupied,
        },
    }
}

/// Distance of voxel `v`'s centre, metres, and whether it is saturated.
/// Signed, it is [`distance`]'s at the centre (NaN, not saturated, for a
/// voxel beyond [`MAX_QUERY_INDEX`]).
pub fn voxel_distance(map: &GlobalMap, v: VoxelIndex, signed: bool) -> (f64, bool) {
    let vs = map.voxel_size_m();
    if signed {
        if !in_query_range(v) {
            return (f64::NAN, false);
        }
        let state = voxel_state(map, v);
        let d = signed::signed_at(map, v.centre(vs), v, state, true);
        return (d.distance_m, d.saturated);
    }
    let (d, _) = map.entry(v);
    if d == FAR_DIST_SQ {
        (map.params().max_distance_m, true)
    } else {
        (f64::from(d).sqrt() * vs, false)
    }
}

/// Distance and gradient at world point `p`: unsigned, interpolated
/// between the eight voxel centres around it; signed, to the surface of the
/// obstacle voxels (see the module docs).
pub fn distance(map: &GlobalMap, p: [f64; 3], signed: bool) -> Distance {
    let vs = map.voxel_size_m();
    let Some(v) = query_voxel(p, vs) else {
        return Distance {
            distance_m: f64::NAN,
            gradient: [0.0; 3],
            state: PointState::Outside,
            observed: false,
            saturated: false,
        };
    };
    let state = voxel_state(map, v);
    let observed = matches!(map.state(v), VoxelState::Free | VoxelState::Occupied);
    if signed {
        return signed::signed_at(map, p, v, state, observed);
    }
    let u = p.map(|c| c / vs - 0.5);
    let mut base = u.map(|c| c.floor());
    let mut f = [0, 1, 2].map(|a| u[a] - base[a]);
    // A planar map's distance is its layer's: both z corners in the
    // point's layer, so it is interpolated in x and y only, with no
    // gradient along z.
    let planar = map.cutoff().planar;
    if planar {
        (base[2], f[2]) = (f64::from(v.0[2]), 0.0);
    }
    let mut corner = [[[0.0; 2]; 2]; 2];
    let mut saturated = false;
    for (k, slot) in corner.iter_mut().flatten().flatten().enumerate() {
        let (dx, dy, dz) = ((k >> 2) & 1, (k >> 1) & 1, if planar { 0 } else { k & 1 });
        let c = VoxelIndex([base[0] as i32 + dx as i32, base[1] as i32 + dy as i32, base[2] as i32 + dz as i32]);
        let (d, s) = voxel_distance(map, c, false);
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
pub fn distance_box(map: &GlobalMap, min_m: [f64; 3], max_m: [f64; 3], signed: bool) -> Result<DistanceBox, CoreError> {
    let vs = map.voxel_size_m();
    let bad = |reason| CoreError::InvalidParam { field: "box", value: format!("{min_m:?} .. {max_m:?}"), reason };
    if (0..3).any(|a| !min_m[a].is_finite() || !max_m[a].is_finite() || min_m[a] >= max_m[a]) {
        return Err(bad("corners must be finite with min below max on every axis"));
    }
    let lo = VoxelIndex::containing(min_m, vs).ok_or(bad("corners must be finite"))?;
    // The last voxel overlapping [min, max) on each axis.
    let last = max_m.map(|m| (m / vs).ceil() - 1.0);
    if last.iter().any(|&l| !(l >= f64::from(i32::MIN) && l <= f64::from(i32::MAX))) {
        return Err(bad("corners must lie in the voxel index range"));
    }
    let hi = VoxelIndex(last.map(|l| l as i32));
    if !in_query_range(lo) || !in_query_range(hi) {
        return Err(bad("corners must lie within 2^30 voxels of the origin on every axis"));
    }
    let dims = [0, 1, 2].map(|a| (i64::from(hi.0[a]) - i64::from(lo.0[a]) + 1) as usize);
    if dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d)).is_none_or(|n| n > MAX_BOX_VOXELS) {
        return Err(bad("more than 2^28 voxels"));
    }
    let [nx, ny, nz] = dims;
    let at = |i: usize| {
        VoxelIndex([lo.0[0] + (i % nx) as i32, lo.0[1] + ((i / nx) % ny) as i32, lo.0[2] + (i / (nx * ny)) as i32])
    };
    let (distance_m, state) = (0..nx * ny * nz)
        .into_par_iter()
        .map(|i| {
            let v = at(i);
            (voxel_distance(map, v, signed).0 as f32, voxel_state(map, v) as u8)
        })
        .unzip();
    Ok(DistanceBox { origin: lo, dims, distance_m, state })
}
