//! 3D digital differential analyser (Amanatides & Woo, 1987) in `f64`: the
//! voxels a segment passes through, in order, clipped to a box of voxels.
//!
//! The occupancy stage no longer uses it: it walks rays in exact fixed point
//! ([`edtmap_core::fixed_ray`]), which every backend reproduces bit for bit.
//! This walk remains for callers with arbitrary `f64` segments.

use edtmap_core::fixed_ray::clip_segment;

/// Calls `visit(coords, linear)` for every voxel of the box `[0, dims)`
/// that the segment `a → b` passes through, in order from `a`, except `b`'s
/// own voxel when `skip_last` and `b` lies in the box; `linear` is `x + nx (y + ny z)`. Coordinates
/// are in voxel units relative to the box's lowest corner. Returns how many
/// voxels the walk crossed and, when it reached `b` (the box did not clip
/// the segment's end), `b`'s voxel.
pub fn traverse(a: [f64; 3], b: [f64; 3], dims: [usize; 3], skip_last: bool, mut visit: impl FnMut([usize; 3], usize)) -> Walk {
    let Some((t0, t1)) = clip_segment(a, b, dims) else { return Walk { visited: 0, end: None } };
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let cell_at = |t: f64| [0, 1, 2].map(|k| ((a[k] + t * d[k]).floor().max(0.0) as usize).min(dims[k] - 1));
    let (cell, last) = (cell_at(t0), cell_at(t1));
    let plane = [1, dims[0], dims[0] * dims[1]];
    // Per axis: step (as a wrapping add), linear stride, next crossing and
    // crossing interval, as separate scalars so they stay in registers:
    // indexing small arrays by the chosen axis went through memory and put
    // a store-to-load round trip on every step.
    let axis = |k: usize| -> (usize, usize, f64, f64) {
        if d[k] > 0.0 {
            (1, plane[k], ((cell[k] + 1) as f64 - a[k]) / d[k], 1.0 / d[k])
        } else if d[k] < 0.0 {
            (usize::MAX, plane[k].wrapping_neg(), (cell[k] as f64 - a[k]) / d[k], -1.0 / d[k])
        } else {
            (0, 0, f64::INFINITY, f64::INFINITY)
        }
    };
    let ((sx, wx, mut tx, dx), (sy, wy, mut ty, dy), (sz, wz, mut tz, dz)) = (axis(0), axis(1), axis(2));
    let [mut cx, mut cy, mut cz] = cell;
    // The walk crosses exactly this many voxel faces; counting them replaces
    // a comparison with t1 and a step limit in the loop.
    let crossings: usize = (0..3).map(|k| cell[k].abs_diff(last[k])).sum();
    let mut linear = cx + plane[1] * cy + plane[2] * cz;
    for visited in 0..crossings {
        let (px, py) = (tx <= ty && tx <= tz, ty < tx && ty <= tz);
        let pz = !(px || py);
        visit([cx, cy, cz], linear);
        // Branch-free step along the chosen axis: the axis a ray crosses
        // next is unpredictable.
        cx = cx.wrapping_add(sx & mask(px));
        cy = cy.wrapping_add(sy & mask(py));
        cz = cz.wrapping_add(sz & mask(pz));
        linear = linear.wrapping_add((wx & mask(px)) | (wy & mask(py)) | (wz & mask(pz)));
        tx += if px { dx } else { 0.0 };
        ty += if py { dy } else { 0.0 };
        tz += if pz { dz } else { 0.0 };
        // Rounding at a near-tie may aim past the box: stop there.
        if cx >= dims[0] || cy >= dims[1] || cz >= dims[2] {
            return Walk { visited: visited + 1, end: None };
        }
    }
    if !(skip_last && t1 >= 1.0) {
        visit([cx, cy, cz], linear);
    }
    Walk { visited: crossings + 1, end: (t1 >= 1.0).then_some(([cx, cy, cz], linear)) }
}

/// The outcome of [`traverse`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Walk {
    /// Voxels visited.
    pub visited: usize,
    /// Coordinates and linear index of the segment end's voxel, when the
    /// walk reached it inside the box.
    pub end: Option<([usize; 3], usize)>,
}

/// All ones when `b`, else zero.
#[inline(always)]
fn mask(b: bool) -> usize {
    (b as usize).wrapping_neg()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_aligned_segment_visits_each_voxel_once() {
        let mut seen = Vec::new();
        let walk = traverse([0.5, 0.5, 0.5], [4.5, 0.5, 0.5], [8, 2, 2], false, |c, i| {
            assert_eq!(i, c[0] + 8 * (c[1] + 2 * c[2]));
            seen.push(c)
        });
        assert_eq!(seen, (0..5).map(|x| [x, 0, 0]).collect::<Vec<_>>());
        assert_eq!(walk, Walk { visited: 5, end: Some(([4, 0, 0], 4)) });
    }

    #[test]
    fn segments_outside_the_box_visit_nothing() {
        let none = Walk { visited: 0, end: None };
        assert_eq!(traverse([-3.0, 0.5, 0.5], [-1.0, 0.5, 0.5], [4, 4, 4], false, |_, _| {}), none);
        assert_eq!(traverse([f64::NAN, 0.5, 0.5], [1.0, 0.5, 0.5], [4, 4, 4], false, |_, _| {}), none);
    }

    #[test]
    fn clipped_segment_starts_at_the_box() {
        let mut seen = Vec::new();
        traverse([-5.5, 1.5, 1.5], [1.5, 1.5, 1.5], [4, 4, 4], false, |c, _| seen.push(c));
        assert_eq!(seen, vec![[0, 1, 1], [1, 1, 1]]);
        let clipped = traverse([1.5, 1.5, 1.5], [9.5, 1.5, 1.5], [4, 4, 4], false, |_, _| {});
        assert_eq!(clipped, Walk { visited: 3, end: None });
    }
}
