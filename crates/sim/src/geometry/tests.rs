//! Exact intersections against brute-force sampling.

use super::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const STEP: f64 = 1e-3;

fn solids() -> Vec<Primitive> {
    vec![
        Aabb::new([-0.3, -0.7, 0.1], [0.9, 0.4, 1.3]).into(),
        Cylinder { centre_xy: [0.2, -0.1], radius_m: 0.6, z_min: -0.4, z_max: 0.8 }.into(),
        Sphere { centre: [0.1, 0.3, 0.2], radius_m: 0.7 }.into(),
        Ground { height_m: -0.213 }.into(),
    ]
}

fn unit(rng: &mut StdRng) -> [f64; 3] {
    loop {
        let v: [f64; 3] = [0; 3].map(|_| rng.random_range(-1.0..1.0));
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if n > 0.1 && n <= 1.0 {
            return v.map(|c| c / n);
        }
    }
}

fn at(o: [f64; 3], d: [f64; 3], t: f64) -> [f64; 3] {
    [0, 1, 2].map(|i| o[i] + t * d[i])
}

/// The first sample along the ray that is inside the solid.
fn march(s: &Primitive, o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<f64> {
    let steps = (t_max / STEP) as usize;
    (1..=steps).map(|k| k as f64 * STEP).find(|&t| s.contains(at(o, d, t)))
}

#[test]
fn ray_hits_match_marching() {
    let mut rng = StdRng::seed_from_u64(11);
    for s in solids() {
        let mut hits = 0;
        for _ in 0..400 {
            // Origins outside the solid, aimed roughly at it.
            let o = [0; 3].map(|_| rng.random_range(-2.5..2.5));
            if s.contains(o) {
                continue;
            }
            let target = [0; 3].map(|_| rng.random_range(-0.5..0.5));
            let raw = [0, 1, 2].map(|i| target[i] - o[i] + rng.random_range(-0.3..0.3));
            let n = (raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2]).sqrt();
            let d = if n > 1e-6 { raw.map(|c| c / n) } else { unit(&mut rng) };
            let exact = s.ray_hit(o, d, 4.0);
            match (exact, march(&s, o, d, 4.0)) {
                (Some(te), Some(tb)) => {
                    hits += 1;
                    assert!(te <= tb + 1e-9 && te >= tb - STEP - 1e-9, "{s:?} {o:?} {d:?}: exact {te}, marched {tb}");
                }
                (None, Some(tb)) => panic!("{s:?} {o:?} {d:?}: missed, marched hit at {tb}"),
                // A graze thinner than the step: the exact point must be on the solid.
                (Some(te), None) => assert!(s.distance(at(o, d, te)) < 1e-9),
                (None, None) => {}
            }
        }
        assert!(hits > 100, "{s:?}: only {hits} hits");
    }
}

#[test]
fn axis_parallel_rays_are_exact() {
    let b = Primitive::from(Aabb::new([1.0, -1.0, -1.0], [2.0, 1.0, 1.0]));
    assert_eq!(b.ray_hit([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 5.0), Some(1.0));
    assert_eq!(b.ray_hit([0.0, 2.0, 0.0], [1.0, 0.0, 0.0], 5.0), None);
    assert_eq!(b.ray_hit([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.5), None);
    let c = Primitive::from(Cylinder { centre_xy: [0.0, 0.0], radius_m: 1.0, z_min: 0.0, z_max: 2.0 });
    assert_eq!(c.ray_hit([0.5, 0.0, 5.0], [0.0, 0.0, -1.0], 10.0), Some(3.0));
    assert_eq!(c.ray_hit([-3.0, 0.0, 1.0], [1.0, 0.0, 0.0], 10.0), Some(2.0));
    let g = Primitive::from(Ground { height_m: 0.0 });
    assert_eq!(g.ray_hit([0.0, 0.0, 2.0], [0.0, 0.0, -1.0], 10.0), Some(2.0));
    assert_eq!(g.ray_hit([0.0, 0.0, 2.0], [1.0, 0.0, 0.0], 10.0), None);
}

#[test]
fn rays_starting_inside_report_the_exit() {
    let s = Primitive::from(Sphere { centre: [0.0; 3], radius_m: 1.0 });
    let t = s.ray_hit([0.0; 3], [0.0, 1.0, 0.0], 5.0).expect("exit");
    assert!((t - 1.0).abs() < 1e-12);
}

/// Box samples on a grid that includes the faces.
fn samples(lo: [f64; 3], hi: [f64; 3], n: usize) -> impl Iterator<Item = [f64; 3]> {
    let f = move |a: usize, k: usize| lo[a] + (hi[a] - lo[a]) * k as f64 / (n - 1) as f64;
    (0..n * n * n).map(move |i| [f(0, i % n), f(1, (i / n) % n), f(2, i / (n * n))])
}

#[test]
fn box_tests_match_sampling() {
    let mut rng = StdRng::seed_from_u64(5);
    let n = 9;
    for s in solids() {
        let (mut yes, mut no) = (0, 0);
        for _ in 0..3000 {
            let lo = [0; 3].map(|_| rng.random_range(-1.3..1.3));
            let hi = lo.map(|c| c + rng.random_range(0.01..0.4));
            let exact = s.intersects_box(lo, hi);
            let spacing = [0, 1, 2].map(|a| (hi[a] - lo[a]) / (n - 1) as f64);
            let half_diag = 0.5 * (spacing[0].powi(2) + spacing[1].powi(2) + spacing[2].powi(2)).sqrt();
            let nearest = samples(lo, hi, n).map(|p| s.distance(p)).fold(f64::INFINITY, f64::min);
            if nearest == 0.0 {
                assert!(exact, "{s:?} misses [{lo:?}, {hi:?}] holding a solid sample");
            }
            if exact {
                assert!(nearest <= half_diag + 1e-12, "{s:?} meets [{lo:?}, {hi:?}] but samples are {nearest} away");
                yes += 1;
            } else {
                no += 1;
            }
        }
        assert!(yes > 200 && no > 200, "{s:?}: {yes} / {no}");
    }
}

#[test]
fn touching_boxes_count_as_intersecting() {
    let c = Primitive::from(Cylinder { centre_xy: [0.0, 0.0], radius_m: 1.0, z_min: 0.0, z_max: 1.0 });
    assert!(c.intersects_box([1.0, -0.1, 0.5], [1.5, 0.1, 0.7]));
    assert!(c.intersects_box([0.0, 0.0, 1.0], [0.1, 0.1, 1.2]));
    assert!(!c.intersects_box([0.75, 0.75, 0.2], [1.0, 1.0, 0.4]));
    let g = Primitive::from(Ground { height_m: 0.5 });
    assert!(g.intersects_box([0.0, 0.0, 0.5], [1.0, 1.0, 1.0]));
    assert!(!g.intersects_box([0.0, 0.0, 0.500001], [1.0, 1.0, 1.0]));
}

#[test]
fn bounds_hold_the_solid() {
    let mut rng = StdRng::seed_from_u64(3);
    for s in solids() {
        let b = s.bounds();
        for _ in 0..2000 {
            let p = [0; 3].map(|_| rng.random_range(-2.0..2.0));
            if s.contains(p) {
                assert_eq!(b.distance(p), 0.0, "{s:?} {p:?}");
            }
        }
        let moved = s.translated([1.0, 2.0, 3.0]);
        assert_eq!(moved.contains([1.1, 2.3, 3.2]), s.contains([0.1, 0.3, 0.2]));
    }
}
