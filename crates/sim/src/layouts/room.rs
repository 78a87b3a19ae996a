//! `room`: a furnished room scanned by a hand-held depth camera
//! (Cow-and-Lady-like).
//!
//! A 6 × 5 × 2.7 m room (floor, ceiling and walls as 0.2 m boxes) with a
//! table and chairs, shelves, a sofa, a cabinet, a lamp, a ball, a bin, a
//! cow made of spheres and a standing lady. The camera circles the centre
//! at 1.5 m radius and 0.6 m/s, 1.35–1.55 m high, always looking at the
//! middle of the room; the seed nudges the loose furniture.

use super::{block, cm, Layout};
use crate::geometry::{Cylinder, Primitive, Sphere};
use crate::trajectory::{Heading, Path, Route};
use edtmap_core::sensor::{PinholeCamera, RangeLimits, Sensor};
use rand::rngs::StdRng;
use rand::SeedableRng;

/// Inner half extents (x, y) and height of the room, metres.
const HALF: [f64; 2] = [3.0, 2.5];
const HEIGHT_M: f64 = 2.7;
const WALL_M: f64 = 0.2;

pub(super) fn build(seed: u64) -> Layout {
    let mut rng = StdRng::seed_from_u64(seed);
    let trajectory = Route {
        path: Path::new([1.5, 0.0], 90f64.to_radians()).turn(1.5, 360.0),
        speed_mps: 0.6,
        start_s: 0.0,
        height_m: 1.45,
        bob_m: 0.1,
        bob_cycles: 2.0,
        heading: Heading::LookAt([0.0, 0.0, 0.6]),
    };
    let mut statics = shell();
    statics.extend(table(jitter(&mut rng, 0.15)));
    statics.extend(shelves());
    statics.extend(sofa());
    statics.extend(cow());
    statics.extend(small_things(&mut rng));
    let camera = PinholeCamera {
        fx: 277.0,
        fy: 277.0,
        cx: 159.5,
        cy: 119.5,
        width: 320,
        height: 240,
        range: RangeLimits { min_m: 0.3, max_m: 5.0 },
    };
    Layout {
        statics,
        walkers: Vec::new(),
        trajectory,
        sensor: Sensor::Depth(camera),
        frame_period_s: 0.1,
        default_frames: 150,
    }
}

fn jitter(rng: &mut StdRng, m: f64) -> [f64; 2] {
    [cm(rng, -m..m), cm(rng, -m..m)]
}

/// Floor, ceiling and four walls.
fn shell() -> Vec<Primitive> {
    let ([x, y], h, t) = (HALF, HEIGHT_M, WALL_M);
    vec![
        block([-x - t, -y - t, -t], [x + t, y + t, 0.0]),
        block([-x - t, -y - t, h], [x + t, y + t, h + t]),
        block([-x - t, -y, 0.0], [-x, y, h]),
        block([x, -y, 0.0], [x + t, y, h]),
        block([-x - t, -y - t, 0.0], [x + t, -y, h]),
        block([-x - t, y, 0.0], [x + t, y + t, h]),
    ]
}

/// A 1.2 × 0.8 m table 0.76 m high with two chairs, centred at `c`.
fn table(c: [f64; 2]) -> Vec<Primitive> {
    let [cx, cy] = c;
    let mut out = vec![block([cx - 0.6, cy - 0.4, 0.72], [cx + 0.6, cy + 0.4, 0.76])];
    for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
        let (lx, ly) = (cx + sx * 0.53, cy + sy * 0.33);
        out.push(block([lx - 0.03, ly - 0.03, 0.0], [lx + 0.03, ly + 0.03, 0.72]));
    }
    for side in [-1.0, 1.0] {
        let y = cy + side * 0.65;
        out.push(block([cx - 0.2, y - 0.2, 0.0], [cx + 0.2, y + 0.2, 0.45]));
        out.push(block([cx - 0.2, y + side * 0.17 - 0.03, 0.45], [cx + 0.2, y + side * 0.17 + 0.03, 0.9]));
    }
    out
}

/// A 1.6 m wide, 0.4 m deep, 1.9 m tall shelf against the +y wall, with
/// a few things on its boards.
fn shelves() -> Vec<Primitive> {
    let (x0, x1, y1) = (-2.2, -0.6, HALF[1]);
    let y0 = y1 - 0.4;
    let mut out = vec![
        block([x0, y0, 0.0], [x0 + 0.03, y1, 1.9]),
        block([x1 - 0.03, y0, 0.0], [x1, y1, 1.9]),
        block([x0, y1 - 0.02, 0.0], [x1, y1, 1.9]),
    ];
    for z in [0.05, 0.5, 0.95, 1.4, 1.87] {
        out.push(block([x0, y0, z], [x1, y1, z + 0.03]));
    }
    out.push(Sphere { centre: [-1.9, 2.25, 0.65], radius_m: 0.12 }.into());
    out.push(Cylinder { centre_xy: [-1.2, 2.3], radius_m: 0.08, z_min: 0.98, z_max: 1.25 }.into());
    out.push(block([-1.0, 2.15, 1.43], [-0.7, 2.45, 1.7]));
    out
}

/// A three-seat sofa against the −x wall.
fn sofa() -> Vec<Primitive> {
    let x = -HALF[0];
    vec![
        block([x, -1.1, 0.0], [x + 0.85, 1.1, 0.42]),
        block([x, -1.1, 0.42], [x + 0.2, 1.1, 0.85]),
        block([x, -1.1, 0.42], [x + 0.85, -0.9, 0.62]),
        block([x, 0.9, 0.42], [x + 0.85, 1.1, 0.62]),
    ]
}

/// A cow of spheres on cylinder legs, in the (+x, −y) corner.
fn cow() -> Vec<Primitive> {
    let y = -1.8;
    let mut out: Vec<Primitive> = vec![
        Sphere { centre: [1.9, y, 0.8], radius_m: 0.38 }.into(),
        Sphere { centre: [2.3, y, 0.85], radius_m: 0.4 }.into(),
        Sphere { centre: [2.6, y, 0.8], radius_m: 0.36 }.into(),
        Sphere { centre: [1.5, y - 0.05, 1.05], radius_m: 0.2 }.into(),
        Sphere { centre: [1.33, y - 0.05, 0.98], radius_m: 0.12 }.into(),
    ];
    for (lx, ly) in [(1.85, y + 0.15), (1.85, y - 0.15), (2.55, y + 0.15), (2.55, y - 0.15)] {
        out.push(Cylinder { centre_xy: [lx, ly], radius_m: 0.07, z_min: 0.0, z_max: 0.6 }.into());
    }
    out
}

/// The lady, a cabinet, a lamp, a ball and a bin.
fn small_things(rng: &mut StdRng) -> Vec<Primitive> {
    let ball = jitter(rng, 0.2);
    let bin = jitter(rng, 0.1);
    vec![
        Cylinder { centre_xy: [2.3, 1.4], radius_m: 0.18, z_min: 0.0, z_max: 1.45 }.into(),
        Sphere { centre: [2.3, 1.4, 1.58], radius_m: 0.12 }.into(),
        block([2.55, 0.2, 0.0], [HALF[0], 0.8, 1.0]),
        Cylinder { centre_xy: [-2.6, 2.1], radius_m: 0.03, z_min: 0.0, z_max: 1.5 }.into(),
        Sphere { centre: [-2.6, 2.1, 1.62], radius_m: 0.18 }.into(),
        Sphere { centre: [0.9 + ball[0], -1.0 + ball[1], 0.15], radius_m: 0.15 }.into(),
        Cylinder { centre_xy: [2.6 + bin[0], -0.4 + bin[1]], radius_m: 0.15, z_min: 0.0, z_max: 0.45 }.into(),
    ]
}
