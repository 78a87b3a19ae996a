//! `ugv_corridor`: a ground robot in narrow corridors with walking
//! pedestrians, 16-ring LiDAR (UGV-Corridor).
//!
//! A rectangular loop of 2.6 m wide corridors (walls 2.5 m tall, 0.2 m
//! thick) around an inner room with a door. The robot drives the loop
//! counter-clockwise at 1 m/s, 0.3 m right of the centre line, sensor 0.6 m
//! above the floor; the default run takes it round one corner. Four
//! pedestrians (r = 0.25 m, 1.7 m tall) pace the inner lanes at ~1.2 m/s,
//! one stepping out of the inner room's door.

use super::{block, Layout};
use crate::geometry::{Ground, Primitive};
use crate::pedestrian::Pedestrian;
use crate::trajectory::{Heading, Path, Route};
use edtmap_core::sensor::{RangeLimits, Sensor, SpinningLidar};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::f64::consts::TAU;

/// Centre-line rectangle of the corridor loop, metres.
const LOOP: [f64; 2] = [18.0, 10.0];
/// Half the corridor width, metres.
const HALF_WIDTH_M: f64 = 1.3;
const WALL_M: f64 = 0.2;
const WALL_HEIGHT_M: f64 = 2.5;
/// The inner room's door: x range in its top wall, and its height.
const DOOR_X: [f64; 2] = [8.4, 9.6];
const DOOR_HEIGHT_M: f64 = 2.0;

pub(super) fn build(seed: u64) -> Layout {
    let mut rng = StdRng::seed_from_u64(seed);
    let lane = 0.3;
    let trajectory = Route {
        path: Path::rounded_rect([-lane, -lane], [LOOP[0] + 2.0 * lane, LOOP[1] + 2.0 * lane], 0.6),
        speed_mps: 1.0,
        start_s: 9.4,
        height_m: 0.6,
        bob_m: 0.0,
        bob_cycles: 0.0,
        heading: Heading::AlongPath,
    };
    let mut statics = vec![Ground { height_m: 0.0 }.into()];
    statics.extend(walls());
    let lidar = SpinningLidar::uniform(
        16,
        -15f64.to_radians(),
        15f64.to_radians(),
        900,
        RangeLimits { min_m: 0.2, max_m: 20.0 },
    );
    Layout {
        statics,
        walkers: pedestrians(&mut rng),
        trajectory,
        sensor: Sensor::Lidar(lidar),
        frame_period_s: 0.1,
        default_frames: 150,
    }
}

fn walls() -> Vec<Primitive> {
    let (w, t, z) = (HALF_WIDTH_M, WALL_M, WALL_HEIGHT_M);
    let [lx, ly] = LOOP;
    let (o_lo, o_hi) = ([-w - t, -w - t], [lx + w + t, ly + w + t]);
    let (i_lo, i_hi) = ([w, w], [lx - w, ly - w]);
    vec![
        // Outer walls.
        block([o_lo[0], o_lo[1], 0.0], [o_hi[0], -w, z]),
        block([o_lo[0], ly + w, 0.0], [o_hi[0], o_hi[1], z]),
        block([o_lo[0], -w, 0.0], [-w, ly + w, z]),
        block([lx + w, -w, 0.0], [o_hi[0], ly + w, z]),
        // Inner room, its top wall split by the door.
        block([i_lo[0], i_lo[1], 0.0], [i_hi[0], i_lo[1] + t, z]),
        block([i_lo[0], i_lo[1] + t, 0.0], [i_lo[0] + t, i_hi[1], z]),
        block([i_hi[0] - t, i_lo[1] + t, 0.0], [i_hi[0], i_hi[1], z]),
        block([i_lo[0] + t, i_hi[1] - t, 0.0], [DOOR_X[0], i_hi[1], z]),
        block([DOOR_X[1], i_hi[1] - t, 0.0], [i_hi[0] - t, i_hi[1], z]),
        block([DOOR_X[0], i_hi[1] - t, DOOR_HEIGHT_M], [DOOR_X[1], i_hi[1], z]),
    ]
}

/// Pedestrians on the inner lanes (0.75 m from the centre line, 1.05 m
/// from the robot's lane), one walking out of the door.
fn pedestrians(rng: &mut StdRng) -> Vec<Pedestrian> {
    let [lx, ly] = LOOP;
    let inner = 0.75;
    let door = 0.5 * (DOOR_X[0] + DOOR_X[1]);
    let walks = [
        ([3.0, inner], [15.0, inner]),
        ([lx - inner, 2.5], [lx - inner, 8.0]),
        ([door, ly - 4.0], [door, ly - inner]),
        ([inner, 8.0], [inner, 2.5]),
    ];
    walks
        .into_iter()
        .map(|(from, to)| Pedestrian {
            from,
            to,
            mean_speed_mps: rng.random_range(1.1..1.3),
            phase_rad: rng.random_range(0.0..TAU),
            radius_m: 0.25,
            floor_m: 0.0,
            height_m: 1.7,
        })
        .collect()
}
