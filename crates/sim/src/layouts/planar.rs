//! `planar`: a drone with a 2D LiDAR on a cluttered indoor floor (paper §VI).
//!
//! A 20 × 20 m floor with outer walls, an L-shaped partition, two wall
//! stubs and random boxes and cylinders, all 2–2.6 m tall so the scan plane
//! cuts them. The drone flies a 13 × 13 m rounded square at 1 m height and
//! 1.5 m/s, at least 1 m from any clutter.

use super::{block, cm, scatter, KeepOut, Layout};
use crate::geometry::{Cylinder, Ground, Primitive};
use crate::trajectory::{Heading, Path, Route};
use edtmap_core::sensor::Sensor;
use rand::rngs::StdRng;
use rand::SeedableRng;

const HALF_M: f64 = 10.0;
const WALL_M: f64 = 0.2;
const BOXES: usize = 30;
const CYLINDERS: usize = 25;

pub(super) fn build(seed: u64) -> Layout {
    let mut rng = StdRng::seed_from_u64(seed);
    let trajectory = Route {
        path: Path::rounded_rect([-6.5, -6.5], [13.0, 13.0], 2.5),
        speed_mps: 1.5,
        start_s: 0.0,
        height_m: 1.0,
        bob_m: 0.0,
        bob_cycles: 0.0,
        heading: Heading::AlongPath,
    };
    let keep = KeepOut::new(&trajectory, 1.0);
    let mut statics = vec![Ground { height_m: 0.0 }.into()];
    statics.extend(walls());
    let h = HALF_M - 0.4;
    statics.extend(scatter(&mut rng, BOXES, &keep, |r| {
        let (x, y) = (cm(r, -h..h), cm(r, -h..h));
        let (w, d) = (cm(r, 0.3..1.2), cm(r, 0.3..1.2));
        block([x, y, 0.0], [x + w, y + d, cm(r, 2.0..2.6)])
    }));
    statics.extend(scatter(&mut rng, CYLINDERS, &keep, |r| {
        let centre_xy = [cm(r, -h..h), cm(r, -h..h)];
        Cylinder { centre_xy, radius_m: cm(r, 0.15..0.5), z_min: 0.0, z_max: cm(r, 2.0..2.6) }.into()
    }));
    Layout {
        statics,
        walkers: Vec::new(),
        trajectory,
        sensor: Sensor::Planar,
        frame_period_s: 0.1,
        default_frames: 120,
    }
}

/// Outer walls, an L-shaped partition inside the loop and two stubs.
fn walls() -> Vec<Primitive> {
    let (a, t, z) = (HALF_M, WALL_M, 2.6);
    vec![
        block([-a - t, -a - t, 0.0], [a + t, -a, z]),
        block([-a - t, a, 0.0], [a + t, a + t, z]),
        block([-a - t, -a, 0.0], [-a, a, z]),
        block([a, -a, 0.0], [a + t, a, z]),
        block([-3.0, 1.0, 0.0], [2.0, 1.0 + t, z]),
        block([2.0 - t, -3.0, 0.0], [2.0, 1.0, z]),
        block([8.3, 3.0, 0.0], [a, 3.0 + t, z]),
        block([-2.0, -a, 0.0], [-2.0 + t, -8.3, z]),
    ]
}
