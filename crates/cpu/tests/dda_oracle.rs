//! The ray walk the occupancy stage uses (`edtmap_core::fixed_ray`: the
//! segment set up in `f64`, its ends quantized to 1/q voxel, then walked in
//! exact integers) against a brute-force segment/voxel intersection of the
//! quantized segment it walks.

use edtmap_core::fixed_ray::{fixed_scale, setup_ray, walk_cells, RAY_WALK};
use proptest::prelude::*;

/// A segment `a → b` in voxel units.
type Segment = ([f64; 3], [f64; 3]);

/// The voxels the walk visits for the segment `a → b` in the box
/// `[0, dims)`, and the segment it actually walks (clipped to the box and
/// quantized), in voxel units; no segment when it misses the box.
fn walked(a: [f64; 3], b: [f64; 3], dims: [usize; 3]) -> (Vec<[usize; 3]>, Option<Segment>) {
    let q = fixed_scale(dims).expect("small box");
    let ray = setup_ray(a, b, b, false, dims, q);
    let mut seen = Vec::new();
    walk_cells(&ray, dims, q, |c, _| seen.push(c.map(|v| v as usize)));
    let quantized = (ray.flags & RAY_WALK != 0)
        .then(|| (ray.start.map(|v| f64::from(v) / f64::from(q)), ray.end.map(|v| f64::from(v) / f64::from(q))));
    (seen, quantized)
}

/// Length of the part of segment `a → b` inside the closed cube `lo .. lo+1`
/// grown by `grow`, or `None` if they do not meet.
fn overlap(a: [f64; 3], b: [f64; 3], lo: [usize; 3], grow: f64) -> Option<f64> {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        let d = b[k] - a[k];
        let (min, max) = (lo[k] as f64 - grow, lo[k] as f64 + 1.0 + grow);
        if d == 0.0 {
            if a[k] < min || a[k] > max {
                return None;
            }
            continue;
        }
        let (p, q) = ((min - a[k]) / d, (max - a[k]) / d);
        t0 = t0.max(p.min(q));
        t1 = t1.min(p.max(q));
    }
    let len = ((0..3).map(|k| (b[k] - a[k]).powi(2)).sum::<f64>()).sqrt();
    (t0 <= t1).then_some((t1 - t0) * len)
}

fn check(a: [f64; 3], b: [f64; 3], dims: [usize; 3]) -> Result<(), TestCaseError> {
    let (seen, quantized) = walked(a, b, dims);
    // The walk follows the quantized segment; a segment that misses the box
    // (or only grazes it after quantization) visits nothing.
    let (a, b) = quantized.unwrap_or((a, a));
    for w in seen.windows(2) {
        let steps: usize = (0..3).map(|k| w[0][k].abs_diff(w[1][k])).sum();
        prop_assert_eq!(steps, 1, "consecutive voxels {:?} are not face neighbours", w);
    }
    let mut sorted = seen.clone();
    sorted.sort_unstable();
    sorted.dedup();
    prop_assert_eq!(sorted.len(), seen.len(), "a voxel was visited twice");
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let c = [x, y, z];
                let visited = sorted.binary_search(&c).is_ok();
                // Crossed: through the interior (quantized ends can put a
                // segment on a face, where either side may be walked).
                if overlap(a, b, c, -1e-9).is_some_and(|l| l > 1e-7) {
                    prop_assert!(visited, "voxel {:?} crossed by the segment was missed", c);
                }
                if visited {
                    prop_assert!(overlap(a, b, c, 1e-9).is_some(), "voxel {:?} off the segment was visited", c);
                }
            }
        }
    }
    Ok(())
}

fn point(span: f64) -> impl Strategy<Value = [f64; 3]> {
    [-span..12.0 + span, -span..12.0 + span, -span..9.0 + span]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn dda_visits_exactly_the_crossed_voxels(a in point(4.0), b in point(4.0)) {
        check(a, b, [12, 12, 9])?;
    }

    #[test]
    fn dda_handles_axis_parallel_segments(a in point(2.0), len in -15.0f64..15.0, axis in 0usize..3) {
        let mut b = a;
        b[axis] += len;
        check(a, b, [12, 12, 9])?;
    }
}

/// Segments along grid lines touch two voxels with positive length; the DDA
/// picks one. Every visited voxel must touch the segment, and every point of
/// the segment (inside the box) must lie in a visited voxel.
fn check_degenerate(a: [f64; 3], b: [f64; 3], dims: [usize; 3]) {
    // Ends on grid lines are exact in fixed point: the walked segment is `a → b`.
    let (seen, _) = walked(a, b, dims);
    for c in &seen {
        assert!(overlap(a, b, *c, 1e-9).is_some(), "voxel {c:?} off the segment");
    }
    for i in 0..=1000 {
        let t = i as f64 / 1000.0;
        let p: [f64; 3] = [0, 1, 2].map(|k| a[k] + t * (b[k] - a[k]));
        let inside = (0..3).all(|k| p[k] >= 0.0 && p[k] <= dims[k] as f64);
        let covered =
            seen.iter().any(|c| (0..3).all(|k| p[k] >= c[k] as f64 - 1e-9 && p[k] <= c[k] as f64 + 1.0 + 1e-9));
        assert!(!inside || covered, "point {p:?} not covered by {seen:?}");
    }
}

#[test]
fn dda_on_grid_lines_covers_the_segment() {
    check_degenerate([0.0, 0.0, 0.0], [5.0, 5.0, 5.0], [6, 6, 6]);
    check_degenerate([2.0, 1.0, 0.5], [2.0, 5.0, 0.5], [6, 6, 6]);
    check_degenerate([6.0, 6.0, 6.0], [0.0, 0.0, 0.0], [6, 6, 6]);
}
