//! 3D digital differential analyser (Amanatides & Woo, 1987): the voxels a
//! segment passes through, in order, clipped to a box of voxels.

/// Calls `visit(coords, linear, t_exit)` for every voxel of the box
/// `[0, dims)` that the segment `a → b` passes through, in order from `a`;
/// `linear` is `x + nx (y + ny z)` and `t_exit` the segment parameter
/// (0 at `a`, 1 at `b`) where the segment leaves the voxel. Coordinates are in voxel units relative to the
/// box's lowest corner. Returns the number of voxels visited and whether the
/// walk ended at `b` (false when the box clipped the segment's end).
pub fn traverse(a: [f64; 3], b: [f64; 3], dims: [usize; 3], mut visit: impl FnMut([usize; 3], usize, f64)) -> (usize, bool) {
    let Some((t0, t1)) = clip(a, b, dims) else { return (0, false) };
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let cell_at = |t: f64| [0, 1, 2].map(|k| ((a[k] + t * d[k]).floor().max(0.0) as usize).min(dims[k] - 1));
    let (mut cell, last) = (cell_at(t0), cell_at(t1));
    let plane = [1, dims[0], dims[0] * dims[1]];
    let mut stride = [0usize; 3];
    let mut step = [0usize; 3];
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for k in 0..3 {
        if d[k] > 0.0 {
            (step[k], stride[k]) = (1, plane[k]);
            t_delta[k] = 1.0 / d[k];
            t_max[k] = ((cell[k] + 1) as f64 - a[k]) / d[k];
        } else if d[k] < 0.0 {
            // Steps of -1 as wrapping additions.
            (step[k], stride[k]) = (usize::MAX, plane[k].wrapping_neg());
            t_delta[k] = -1.0 / d[k];
            t_max[k] = (cell[k] as f64 - a[k]) / d[k];
        }
    }
    // The walk crosses exactly this many voxel faces; counting them replaces
    // a comparison with t1 and a step limit in the loop.
    let crossings: usize = (0..3).map(|k| cell[k].abs_diff(last[k])).sum();
    let mut linear = cell[0] + plane[1] * cell[1] + plane[2] * cell[2];
    for visited in 0..crossings {
        let k = argmin(t_max);
        visit(cell, linear, t_max[k]);
        let next = cell[k].wrapping_add(step[k]);
        // Rounding at a near-tie may aim past the box: stop there.
        if next >= dims[k] {
            return (visited + 1, false);
        }
        cell[k] = next;
        linear = linear.wrapping_add(stride[k]);
        t_max[k] += t_delta[k];
    }
    visit(cell, linear, t1);
    (crossings + 1, t1 >= 1.0)
}

/// Index of the smallest of three values, without branches: the axis a ray
/// crosses next is unpredictable.
#[inline(always)]
fn argmin(t: [f64; 3]) -> usize {
    let a = usize::from(t[1] < t[0]);
    let m = if a == 1 { t[1] } else { t[0] };
    let b = usize::from(t[2] < m);
    a + b * (2 - a)
}

/// The parameter interval `[t0, t1] ⊆ [0, 1]` of the segment inside the
/// box, if any (slab method).
fn clip(a: [f64; 3], b: [f64; 3], dims: [usize; 3]) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        let d = b[k] - a[k];
        let hi = dims[k] as f64;
        if !(a[k].is_finite() && d.is_finite()) {
            return None;
        }
        if d == 0.0 {
            if a[k] < 0.0 || a[k] > hi {
                return None;
            }
            continue;
        }
        let (mut lo_t, mut hi_t) = ((0.0 - a[k]) / d, (hi - a[k]) / d);
        if lo_t > hi_t {
            std::mem::swap(&mut lo_t, &mut hi_t);
        }
        t0 = t0.max(lo_t);
        t1 = t1.min(hi_t);
    }
    (t0 <= t1).then_some((t0, t1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_aligned_segment_visits_each_voxel_once() {
        let mut seen = Vec::new();
        let (n, reached) = traverse([0.5, 0.5, 0.5], [4.5, 0.5, 0.5], [8, 2, 2], |c, i, _| {
            assert_eq!(i, c[0] + 8 * (c[1] + 2 * c[2]));
            seen.push(c)
        });
        assert_eq!(seen, (0..5).map(|x| [x, 0, 0]).collect::<Vec<_>>());
        assert_eq!((n, reached), (5, true));
    }

    #[test]
    fn segments_outside_the_box_visit_nothing() {
        assert_eq!(traverse([-3.0, 0.5, 0.5], [-1.0, 0.5, 0.5], [4, 4, 4], |_, _, _| {}), (0, false));
        assert_eq!(traverse([f64::NAN, 0.5, 0.5], [1.0, 0.5, 0.5], [4, 4, 4], |_, _, _| {}), (0, false));
    }

    #[test]
    fn clipped_segment_starts_at_the_box() {
        let mut seen = Vec::new();
        traverse([-5.5, 1.5, 1.5], [1.5, 1.5, 1.5], [4, 4, 4], |c, _, _| seen.push(c));
        assert_eq!(seen, vec![[0, 1, 1], [1, 1, 1]]);
        let (_, reached) = traverse([1.5, 1.5, 1.5], [9.5, 1.5, 1.5], [4, 4, 4], |_, _, _| {});
        assert!(!reached);
    }
}
