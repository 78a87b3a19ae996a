//! `uav_pillars`: a drone among pillars with a 3D LiDAR (paper §V-A).
//!
//! A 40 × 40 m field of pillars (cylinders and boxes, 3–8 m tall) on flat
//! ground; the drone flies a 26 × 26 m rounded square through it at 2 m/s,
//! 1.5–2 m above the ground, and no pillar comes within 1 m of its path.

use super::{block, cm, scatter, KeepOut, Layout};
use crate::geometry::{Cylinder, Ground};
use crate::trajectory::{Heading, Path, Route};
use edtmap_core::sensor::{RangeLimits, Sensor, SpinningLidar};
use rand::rngs::StdRng;
use rand::SeedableRng;

const FIELD_HALF_M: f64 = 20.0;
const CYLINDERS: usize = 170;
const BOXES: usize = 40;

pub(super) fn build(seed: u64) -> Layout {
    let mut rng = StdRng::seed_from_u64(seed);
    let trajectory = Route {
        path: Path::rounded_rect([-13.0, -13.0], [26.0, 26.0], 5.0),
        speed_mps: 2.0,
        start_s: 0.0,
        height_m: 1.75,
        bob_m: 0.25,
        bob_cycles: 3.0,
        heading: Heading::AlongPath,
    };
    let keep = KeepOut::new(&trajectory, 1.0);
    let h = FIELD_HALF_M;
    let mut statics = vec![Ground { height_m: 0.0 }.into()];
    statics.extend(scatter(&mut rng, CYLINDERS, &keep, |r| {
        let radius_m = cm(r, 0.2..0.6);
        let centre_xy = [cm(r, -h..h), cm(r, -h..h)];
        Cylinder { centre_xy, radius_m, z_min: 0.0, z_max: cm(r, 3.0..8.0) }.into()
    }));
    statics.extend(scatter(&mut rng, BOXES, &keep, |r| {
        let (x, y) = (cm(r, -h..h), cm(r, -h..h));
        let (w, d) = (cm(r, 0.4..1.6), cm(r, 0.4..1.6));
        block([x, y, 0.0], [x + w, y + d, cm(r, 3.0..8.0)])
    }));
    let lidar = SpinningLidar::uniform(
        32,
        -15f64.to_radians(),
        15f64.to_radians(),
        900,
        RangeLimits { min_m: 0.2, max_m: 20.0 },
    );
    Layout {
        statics,
        walkers: Vec::new(),
        trajectory,
        sensor: Sensor::Lidar(lidar),
        frame_period_s: 0.1,
        default_frames: 120,
    }
}
