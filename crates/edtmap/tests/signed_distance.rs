//! Signed distance against analytic scenes: gradients of about unit length where
//! the field is smooth (not (0, 0, 2) at an occupied voxel's centre, nor
//! 2.6 long in free space), and free points never negative.
//!
//! The signed distance is that to the surface of the obstacle voxels, so a
//! scene whose obstacles are voxel-aligned half-spaces or boxes has an exact
//! analytic answer, and a voxelised sphere one within half a voxel diagonal.
//! Every test asserts the sign exactly: negative if and only if the point's
//! voxel is an obstacle, computed here from the scene, not from the map.

use edtmap::cpu::edt::{edt_with, ScanLayout};
use edtmap::cpu::CpuBackend;
use edtmap::sensor::{RangeLimits, Sensor};
use edtmap::stages::IntegrationStage;
use edtmap::{
    Distance, ForbiddenZone, GlobalMap, GlobalParams, Grid3, IntegrationMode, LocalVolume, Mapper, MapperParams,
    OccupancyParams, VoxelIndex,
};

/// SplitMix64: a small seeded generator, the same on every platform.
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn point(&mut self, lo: [f64; 3], hi: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|a| lo[a] + (hi[a] - lo[a]) * self.unit())
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn sensor() -> Sensor {
    Sensor::Points(RangeLimits { min_m: 0.0, max_m: 10.0 })
}

/// A mapper over a map whose voxels `lo + dims` are observed: those whose
/// centre satisfies `obstacle` occupied, the rest free; its global EDT
/// computed exactly.
fn mapper_of(vs: f64, lo: [i32; 3], dims: [usize; 3], obstacle: impl Fn([f64; 3]) -> bool) -> Mapper {
    let params = GlobalParams { max_distance_m: 1.5, mode: IntegrationMode::Exact, ..Default::default() };
    let mut map = GlobalMap::new(vs, OccupancyParams::default(), params).expect("valid");
    let window = LocalVolume { origin: VoxelIndex(lo), dims, voxel_size_m: vs };
    let (min, max) = (map.log_odds().min, map.log_odds().max);
    let mask = Grid3::from_fn(dims, |x, y, z| obstacle(window.world([x, y, z]).centre(vs))).expect("dims");
    for (i, &o) in mask.as_slice().iter().enumerate() {
        let v = window.world(mask.coords(i));
        map.occupancy_mut().get_or_insert(v.block()).log_odds.set(v.offset_in_block(), if o { max } else { min });
    }
    let batch = edt_with(&mask, |&o| o, ScanLayout::default()).expect("batch");
    let stage = IntegrationStage::new(map.params(), vs).expect("valid");
    let (edt, obstacles) = map.edt_and_obstacles();
    stage.merge_window(&mut CpuBackend::default(), edt, obstacles, &window, &batch).expect("integrate");
    Mapper::with_map(sensor(), MapperParams::for_voxel_size(vs), map).expect("mapper")
}

/// The centre of the voxel holding `p`, computed from the coordinates.
fn centre_of(p: [f64; 3], vs: f64) -> [f64; 3] {
    p.map(|c| ((c / vs).floor() + 0.5) * vs)
}

fn assert_unit(p: [f64; 3], d: &Distance) {
    let n = norm(d.gradient);
    assert!((0.9..=1.1).contains(&n), "{p:?}: gradient {:?} of length {n}", d.gradient);
}

#[test]
fn floor_and_wall_corner_is_exact_and_free_points_are_positive() {
    // The room's failure: a floor (z < 0) meeting a wall (x < 0). Free points
    // near the concave edge read negative, and the floor's voxel centres had
    // gradient (0, 0, 2).
    let vs = 0.1;
    let mapper = mapper_of(vs, [-10, -10, -10], [30, 30, 30], |c| c[0] < 0.0 || c[2] < 0.0);
    let mut rng = Rng(7);
    for _ in 0..5000 {
        let p = rng.point([-0.3, -0.3, -0.3], [0.9, 0.9, 0.9]);
        let d = mapper.signed_distance(p);
        let c = centre_of(p, vs);
        let inside = c[0] < 0.0 || c[2] < 0.0;
        // Outside: the nearer of the two planes; inside: the distance to the
        // free quadrant x >= 0, z >= 0.
        let (truth, grad) = if inside {
            let out = [(-p[0]).max(0.0), (-p[2]).max(0.0)];
            let n = out[0].hypot(out[1]);
            (-n, [out[0] / n, 0.0, out[1] / n])
        } else if p[0] < p[2] {
            (p[0], [1.0, 0.0, 0.0])
        } else {
            (p[2], [0.0, 0.0, 1.0])
        };
        assert_eq!(d.distance_m < 0.0, inside, "{p:?}: {d:?}");
        assert!((d.distance_m - truth).abs() < 1e-9, "{p:?}: {} vs {truth}", d.distance_m);
        assert!(!d.saturated, "{p:?}");
        assert_unit(p, &d);
        // Away from the plane x = z (outside) the nearest face is unique.
        if inside || (p[0] - p[2]).abs() > vs {
            let err = norm([0, 1, 2].map(|a| d.gradient[a] - grad[a]));
            assert!(err < 1e-9, "{p:?}: gradient {:?} vs {grad:?}", d.gradient);
        }
    }
    // An occupied voxel centre of the floor, away from the wall: half a voxel
    // inside, gradient straight up.
    let d = mapper.signed_distance([0.55, 0.25, -0.05]);
    assert!(
        (d.distance_m + 0.05).abs() < 1e-9 && norm([d.gradient[0], d.gradient[1], d.gradient[2] - 1.0]) < 1e-9,
        "{d:?}"
    );
}

#[test]
fn box_from_a_forbidden_zone_matches_the_analytic_box() {
    // Corners on voxel faces (exact in binary), so the obstacle voxels are
    // exactly the box.
    let vs = 0.125;
    let (lo, hi) = ([-0.5, -0.375, 0.25], [0.5, 0.625, 1.0]);
    let mut params = MapperParams::for_voxel_size(vs);
    params.global.max_distance_m = 1.5;
    params.global.forbidden = vec![ForbiddenZone { min_m: lo, max_m: hi }];
    let mapper = Mapper::new(sensor(), params).expect("mapper");
    let mut rng = Rng(2024);
    let (mut saturated, mut inside_points) = (0, 0);
    for _ in 0..20_000 {
        let p = rng.point([-2.2, -2.0, -1.5], [2.2, 2.4, 2.7]);
        let d = mapper.signed_distance(p);
        // Per axis: how far outside the box (positive) or inside (negative).
        let out = [0, 1, 2].map(|a| (lo[a] - p[a]).max(p[a] - hi[a]));
        let inside = out.iter().all(|&o| o < 0.0);
        let truth = if inside { out.iter().copied().fold(f64::MIN, f64::max) } else { norm(out.map(|o| o.max(0.0))) };
        assert_eq!(d.distance_m < 0.0, inside, "{p:?}: {d:?}");
        if d.saturated {
            // The EDT's cutoff is between voxel centres: within two voxels of it.
            assert!(d.distance_m == 1.5 && truth > 1.5 - 2.0 * vs, "{p:?}: saturated at {truth}: {d:?}");
            saturated += 1;
            continue;
        }
        assert!(truth < 1.5 + 2.0 * vs, "{p:?}: {truth} beyond the cutoff but not saturated: {d:?}");
        assert!((d.distance_m - truth).abs() < 0.05 * vs, "{p:?}: {} vs {truth}", d.distance_m);
        assert_unit(p, &d);
        let grad = if inside {
            // The nearest face, when the next nearest is a voxel farther.
            let mut order = [0, 1, 2];
            order.sort_by(|&a, &b| out[b].total_cmp(&out[a]));
            if out[order[0]] - out[order[1]] < vs {
                continue;
            }
            let a = order[0];
            let mut g = [0.0; 3];
            g[a] = if p[a] - lo[a] < hi[a] - p[a] { -1.0 } else { 1.0 };
            inside_points += 1;
            g
        } else {
            // From the closest point of the box: unique outside a convex box.
            let q = [0, 1, 2].map(|a| p[a].clamp(lo[a], hi[a]));
            let n = norm([0, 1, 2].map(|a| p[a] - q[a]));
            [0, 1, 2].map(|a| (p[a] - q[a]) / n)
        };
        let cos: f64 = (0..3).map(|a| d.gradient[a] * grad[a]).sum();
        assert!(cos > 0.99, "{p:?}: gradient {:?} vs {grad:?}", d.gradient);
    }
    assert!(saturated > 1000 && inside_points > 50, "{saturated} saturated, {inside_points} inside points checked");
}

#[test]
fn sphere_is_within_half_a_voxel_diagonal_and_signs_are_exact() {
    let vs = 0.1;
    let (c, r) = ([0.02, -0.03, 0.01], 0.6);
    let radial = |p: [f64; 3]| norm([p[0] - c[0], p[1] - c[1], p[2] - c[2]]);
    let mapper = mapper_of(vs, [-20, -20, -20], [40, 40, 40], |p| radial(p) <= r);
    // The obstacle voxels hold every point within r - h√3 of the centre and
    // none beyond r + h√3 (h half a voxel), so the distance to their surface
    // is within h√3 of the sphere's; a few hundredths of a voxel more where
    // the nearest obstacle by centre is not the nearest cube.
    let tol = vs * (0.5 * 3f64.sqrt() + 0.05);
    let mut rng = Rng(99);
    let (mut inside_points, mut aligned) = (0, 0);
    for _ in 0..20_000 {
        let p = rng.point([-1.3; 3], [1.3; 3]);
        if radial(p) > 1.3 {
            // Keep within the cutoff (1.5 m) of the surface.
            continue;
        }
        let d = mapper.signed_distance(p);
        let truth = radial(p) - r;
        let inside = radial(centre_of(p, vs)) <= r;
        assert_eq!(d.distance_m < 0.0, inside, "{p:?}: {d:?}");
        assert!(!d.saturated && (d.distance_m - truth).abs() <= tol, "{p:?}: {} vs {truth}", d.distance_m);
        assert_unit(p, &d);
        inside_points += usize::from(inside);
        // Three voxels or more from the surface (and, inside, from the
        // centre, the medial point), the gradient points along the radius up
        // to the staircase: its line from `p` meets the surface within two
        // voxels of the radial foot (one-voxel steps, corners sticking out).
        if truth.abs() >= 3.0 * vs && radial(p) >= 3.0 * vs {
            let dir = [0, 1, 2].map(|a| (p[a] - c[a]) / radial(p));
            let cos: f64 = (0..3).map(|a| d.gradient[a] * dir[a]).sum();
            let lateral = (1.0 - cos.min(1.0).powi(2)).sqrt() * truth.abs();
            assert!(cos > 0.0 && lateral <= 2.0 * vs, "{p:?}: gradient {:?} vs radial {dir:?}", d.gradient);
            aligned += 1;
        }
    }
    assert!(inside_points > 500 && aligned > 4000, "{inside_points} inside, {aligned} checked for direction");
}
