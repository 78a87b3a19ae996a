//! Signed distance to the surface of the obstacle voxels: the nearest
//! obstacle cube outside, the nearest free cube inside. The definition, and
//! why it is not interpolated, are in the docs of [`crate::query`].

use super::{Distance, PointState};
use crate::{GlobalMap, Obstacles, VoxelIndex, FAR_DIST_SQ};

/// The closest point (voxel units) to `u` of the cube of voxel `w`, which
/// spans `[w, w + 1)` on each axis.
fn closest_on_cube(u: [f64; 3], w: VoxelIndex) -> [f64; 3] {
    [0, 1, 2].map(|a| u[a].clamp(f64::from(w.0[a]), f64::from(w.0[a]) + 1.0))
}

fn dist_sq(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum()
}

/// The unit vector along the axis where `from` lies farthest from the
/// centre of voxel `w` (its outward face normal when `from` is on the
/// cube); the first such axis on a tie.
fn face_normal(from: [f64; 3], w: VoxelIndex) -> [f64; 3] {
    let off = [0, 1, 2].map(|a| from[a] - (f64::from(w.0[a]) + 0.5));
    let axis = (1..3).fold(0, |best, a| if off[a].abs() > off[best].abs() { a } else { best });
    let mut n = [0.0; 3];
    n[axis] = if off[axis] < 0.0 { -1.0 } else { 1.0 };
    n
}

/// The unit vector from `a` to `b`, or `fallback` when they coincide.
fn unit(a: [f64; 3], b: [f64; 3], fallback: [f64; 3]) -> [f64; 3] {
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let n = dist_sq(a, b).sqrt();
    if n > 0.0 {
        d.map(|c| c / n)
    } else {
        fallback
    }
}

/// The obstacle voxel whose cube is nearest `u` (voxel units, inside the
/// non-obstacle voxel `v`), from the EDT's nearest obstacles of `v` and its
/// 26 neighbours; `None` when none has one within the cutoff.
fn nearest_obstacle(map: &GlobalMap, u: [f64; 3], v: VoxelIndex) -> Option<(f64, VoxelIndex)> {
    let mut best: Option<(f64, VoxelIndex)> = None;
    for k in 0..27 {
        let n = VoxelIndex([v.0[0] + k % 3 - 1, v.0[1] + (k / 3) % 3 - 1, v.0[2] + k / 9 - 1]);
        let (d, site) = map.entry(n);
        if d == FAR_DIST_SQ {
            continue;
        }
        let d2 = dist_sq(u, closest_on_cube(u, site));
        if best.is_none_or(|(b, _)| d2 < b) {
            best = Some((d2, site));
        }
    }
    best
}

/// The non-obstacle voxel whose cube is nearest `u` (voxel units, inside
/// the obstacle voxel `v`), searched in the shells of voxels at Chebyshev
/// distance 1, 2, … from `v` out to `reach`; `None` when every voxel there
/// is an obstacle.
fn nearest_free(
    obstacles: &Obstacles<'_>,
    u: [f64; 3],
    v: VoxelIndex,
    reach: i32,
    planar: bool,
) -> Option<(f64, VoxelIndex)> {
    let mut best: Option<(f64, VoxelIndex)> = None;
    for r in 1..=reach.min(10_000) {
        // `u` lies in `v`'s cube, so every cube of shell `r` is at least
        // `r - 1` away.
        if best.is_some_and(|(b, _)| b <= f64::from(r - 1).powi(2)) {
            break;
        }
        for_shell(v, r, planar, |w| {
            if !obstacles.contains(w) {
                let d2 = dist_sq(u, closest_on_cube(u, w));
                if best.is_none_or(|(b, _)| d2 < b) {
                    best = Some((d2, w));
                }
            }
        });
    }
    best
}

/// Calls `f` on every voxel at Chebyshev distance exactly `r >= 1` from `v`
/// (in `v`'s layer only, when `planar`).
fn for_shell(v: VoxelIndex, r: i32, planar: bool, mut f: impl FnMut(VoxelIndex)) {
    let [x, y, z] = v.0;
    let layers = if planar { 0..=0 } else { -r..=r };
    for dz in layers {
        for dy in -r..=r {
            if dz.abs() == r || dy.abs() == r {
                (-r..=r).for_each(|dx| f(VoxelIndex([x + dx, y + dy, z + dz])));
            } else {
                f(VoxelIndex([x - r, y + dy, z + dz]));
                f(VoxelIndex([x + r, y + dy, z + dz]));
            }
        }
    }
}

/// Signed distance and gradient at world point `p` (metres), which lies in
/// voxel `v`; `v` must be at least the cutoff's reach plus one voxel inside
/// the `i32` index range (see [`super::MAX_QUERY_INDEX`]).
pub(super) fn signed_at(map: &GlobalMap, p: [f64; 3], v: VoxelIndex, state: PointState, observed: bool) -> Distance {
    let vs = map.voxel_size_m();
    let max = map.params().max_distance_m;
    let mut u = p.map(|c| c / vs);
    let planar = map.cutoff().planar;
    if planar {
        // Measured within the layer: from the point's place in it.
        u[2] = f64::from(v.0[2]) + 0.5;
    }
    let obstacles = map.obstacles();
    let inside = obstacles.contains(v);
    let found =
        if inside { nearest_free(&obstacles, u, v, map.cutoff().reach, planar) } else { nearest_obstacle(map, u, v) };
    let Some((d2, w)) = found else {
        let distance_m = if inside { -max } else { max };
        return Distance { distance_m, gradient: [0.0; 3], state, observed, saturated: true };
    };
    let q = closest_on_cube(u, w);
    let (magnitude, gradient) = if inside {
        // Towards the free cube: where the distance rises to zero.
        (d2.sqrt() * vs, unit(u, q, face_normal(u, w).map(|c| -c)))
    } else {
        (d2.sqrt() * vs, unit(q, u, face_normal(u, w)))
    };
    let saturated = magnitude >= max;
    let magnitude = magnitude.min(max);
    // No negative zero on the surface.
    let distance_m = if inside && magnitude > 0.0 { -magnitude } else { magnitude };
    Distance { distance_m, gradient, state, observed, saturated }
}
