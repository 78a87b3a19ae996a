//! 3D digital differential analyser (Amanatides & Woo, 1987): the voxels a
//! segment passes through, in order, clipped to a box of voxels.

/// Calls `visit` with the local coordinates of every voxel of the box
/// `[0, dims)` that the segment `a → b` passes through, in order from `a`.
/// Coordinates are in voxel units relative to the box's lowest corner.
/// Returns the number of voxels visited.
pub fn traverse(a: [f64; 3], b: [f64; 3], dims: [usize; 3], mut visit: impl FnMut([usize; 3])) -> usize {
    let Some((t0, t1)) = clip(a, b, dims) else { return 0 };
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let start = [0, 1, 2].map(|k| a[k] + t0 * d[k]);
    let mut cell = [0usize; 3];
    let mut step = [0i64; 3];
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for k in 0..3 {
        let c = (start[k].floor().max(0.0) as usize).min(dims[k] - 1);
        cell[k] = c;
        if d[k] > 0.0 {
            step[k] = 1;
            t_delta[k] = 1.0 / d[k];
            t_max[k] = ((c + 1) as f64 - a[k]) / d[k];
        } else if d[k] < 0.0 {
            step[k] = -1;
            t_delta[k] = -1.0 / d[k];
            t_max[k] = (c as f64 - a[k]) / d[k];
        }
    }
    let limit = dims.iter().sum::<usize>() + 3;
    let mut visited = 0;
    loop {
        visit(cell);
        visited += 1;
        let k = argmin(t_max);
        if t_max[k] > t1 || visited >= limit {
            return visited;
        }
        let next = cell[k] as i64 + step[k];
        if next < 0 || next >= dims[k] as i64 {
            return visited;
        }
        cell[k] = next as usize;
        t_max[k] += t_delta[k];
    }
}

#[inline(always)]
fn argmin(t: [f64; 3]) -> usize {
    if t[0] <= t[1] {
        if t[0] <= t[2] { 0 } else { 2 }
    } else if t[1] <= t[2] {
        1
    } else {
        2
    }
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
        traverse([0.5, 0.5, 0.5], [4.5, 0.5, 0.5], [8, 2, 2], |c| seen.push(c));
        assert_eq!(seen, (0..5).map(|x| [x, 0, 0]).collect::<Vec<_>>());
    }

    #[test]
    fn segments_outside_the_box_visit_nothing() {
        assert_eq!(traverse([-3.0, 0.5, 0.5], [-1.0, 0.5, 0.5], [4, 4, 4], |_| {}), 0);
        assert_eq!(traverse([f64::NAN, 0.5, 0.5], [1.0, 0.5, 0.5], [4, 4, 4], |_| {}), 0);
    }

    #[test]
    fn clipped_segment_starts_at_the_box() {
        let mut seen = Vec::new();
        traverse([-5.5, 1.5, 1.5], [1.5, 1.5, 1.5], [4, 4, 4], |c| seen.push(c));
        assert_eq!(seen, vec![[0, 1, 1], [1, 1, 1]]);
    }
}
