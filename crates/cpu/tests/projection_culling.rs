//! `mark_misses` skips tiles and reorders a LiDAR's tests; its misses
//! must still be exactly `ProjectJob::is_miss` on every voxel. Random
//! (seeded) depth cameras, spinning LiDARs and planar scanners, in general
//! and grid-aligned poses, inside and outside the volume, with maximum
//! ranges that end inside it, cameras facing surfaces, LiDARs among walls
//! (whole tiles behind them skipped by azimuth bin), against the
//! definition voxel by voxel.

use edtmap_conformance::SplitMix;
use edtmap_core::sensor::{
    DepthData, DepthImage, LaserScan, LidarScan, Measurement, PinholeCamera, RangeLimits, Sensor, SpinningLidar,
};
use edtmap_core::{mark_misses, LocalVolume, Observations, ProjectJob, VoxelIndex, OBS_MISS, OBS_NONE};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::{PI, TAU};

/// The suite's SplitMix64, with the draws these cases need.
struct Rng(SplitMix);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0.next_u64()
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// One projection to check, owning what the job borrows.
struct Case {
    sensor: Sensor,
    measurement: Measurement,
    pose: Isometry3<f64>,
    volume: LocalVolume,
    free_margin_m: f32,
    clear_no_return: bool,
    planar_half_thickness_m: f32,
}

impl Case {
    fn job(&self) -> ProjectJob<'_> {
        ProjectJob {
            view: self.sensor.view(&self.measurement).expect("a case's measurement is its sensor's own"),
            t_world_sensor: &self.pose,
            volume: self.volume,
            free_margin_m: self.free_margin_m,
            clear_no_return: self.clear_no_return,
            planar_half_thickness_m: self.planar_half_thickness_m,
        }
    }
}

/// A volume whose dimensions are not all multiples of a tile, and a pose:
/// one time in three grid-aligned (quarter turns, on voxel centres or
/// faces), one position in four outside the volume.
fn volume_and_pose(rng: &mut Rng, voxel_size_m: f64, dims: [usize; 3], tilt: f64) -> (LocalVolume, Isometry3<f64>) {
    let origin = VoxelIndex([0, 1, 2].map(|_| rng.below(400) as i32 - 200));
    let volume = LocalVolume { origin, dims, voxel_size_m };
    let corner = volume.min_corner_m();
    let aligned = rng.below(3) == 0;
    let outside = rng.below(4) == 0;
    let t = [0, 1, 2].map(|k| {
        let f = if outside { rng.uniform(-0.4, 1.4) } else { rng.uniform(0.1, 0.9) };
        let steps = dims[k] as f64 * 2.0;
        let f = if aligned { (f * steps).round() / steps } else { f };
        corner[k] + f * dims[k] as f64 * voxel_size_m
    });
    let rot = if aligned {
        let quarter = |rng: &mut Rng| rng.below(4) as f64 * PI / 2.0;
        let (roll, pitch) = if tilt > 1.0 { (quarter(rng), quarter(rng)) } else { (0.0, 0.0) };
        UnitQuaternion::from_euler_angles(roll, pitch, quarter(rng))
    } else {
        UnitQuaternion::from_euler_angles(rng.uniform(-tilt, tilt), rng.uniform(-tilt, tilt), rng.uniform(-PI, PI))
    };
    (volume, Isometry3::from_parts(Translation3::from(Vector3::from(t)), rot))
}

/// A range: one in eight no return (NaN, 0, inf or beyond the maximum),
/// else anywhere up to a little beyond the maximum range.
fn range(rng: &mut Rng, limits: &RangeLimits) -> f32 {
    match rng.below(32) {
        0 => f32::NAN,
        1 => 0.0,
        2 => f32::INFINITY,
        3 => limits.max_m * 1.5,
        _ => rng.uniform(0.0, limits.max_m as f64 * 1.1) as f32,
    }
}

/// Maximum ranges that end inside a small volume half the time.
fn limits(rng: &mut Rng) -> RangeLimits {
    let max_m = if rng.below(2) == 0 { rng.uniform(0.5, 2.0) } else { rng.uniform(2.0, 12.0) };
    RangeLimits { min_m: rng.uniform(0.0, 0.3) as f32, max_m: max_m as f32 }
}

fn depth_case(rng: &mut Rng) -> Case {
    let range = limits(rng);
    let (width, height) = (rng.below(120) as u32 + 8, rng.below(90) as u32 + 6);
    let f = rng.uniform(0.4, 2.0) * width as f64;
    let cx = width as f64 / 2.0 - 0.5 + rng.uniform(-0.3, 0.3) * width as f64;
    let cy = height as f64 / 2.0 - 0.5 + rng.uniform(-0.3, 0.3) * height as f64;
    let camera = PinholeCamera { fx: f, fy: f * rng.uniform(0.9, 1.1), cx, cy, width, height, range };
    let metres: Vec<f32> = (0..width * height).map(|_| self::range(rng, &range)).collect();
    let data = if rng.below(2) == 0 {
        DepthData::Metres(metres)
    } else {
        let values =
            metres.iter().map(|&d| if d.is_finite() { (d * 1000.0).round().min(65535.0) as u16 } else { 0 }).collect();
        DepthData::U16 { values, metres_per_unit: 0.001 }
    };
    let voxel_size_m = [0.05, 0.1, 0.04][rng.below(3) as usize];
    let (volume, pose) = volume_and_pose(rng, voxel_size_m, [45, 38, 27], PI);
    let measurement = Measurement::Depth(DepthImage { width, height, data });
    finish(rng, Sensor::Depth(camera), measurement, volume, pose)
}

fn lidar_case(rng: &mut Rng) -> Case {
    let range = limits(rng);
    let rings = [1, 2, 16, 32][rng.below(4) as usize];
    let (lo, hi) = (rng.uniform(-0.5, 0.0), rng.uniform(0.05, 0.5));
    let azimuth_bins = [90, 360, 901][rng.below(3) as usize];
    let mut lidar = SpinningLidar::uniform(rings, lo, hi, azimuth_bins, range);
    if rings > 2 && rng.below(2) == 0 {
        // Uneven spacing, as real sensors have.
        let mut e: Vec<f64> = (0..rings).map(|_| rng.uniform(lo, hi)).collect();
        e.sort_by(f64::total_cmp);
        e.dedup();
        lidar.ring_elevations_rad = e;
    }
    let ranges = (0..lidar.ring_elevations_rad.len() * azimuth_bins).map(|_| self::range(rng, &range)).collect();
    let voxel_size_m = [0.1, 0.2, 0.05][rng.below(3) as usize];
    let (volume, pose) = volume_and_pose(rng, voxel_size_m, [50, 44, 19], 0.3);
    finish(rng, Sensor::Lidar(lidar), Measurement::Lidar(LidarScan { ranges }), volume, pose)
}

/// A camera facing surfaces: the image in rectangles, each at one depth
/// (some no return), from a pixel to the whole image, so whole tiles lie
/// behind the surfaces their pixels saw.
fn depth_surfaces_case(rng: &mut Rng) -> Case {
    let case = depth_case(rng);
    surfaces(rng, case, 0.05, 1.2)
}

/// A camera in a room: fine voxels, a larger volume, surfaces from 0.3 to
/// 4 m, so that whole tiles lie in front of the surfaces (all misses) as
/// well as behind them.
fn depth_room_case(rng: &mut Rng) -> Case {
    let mut case = depth_case(rng);
    let voxel_size_m = [0.05, 0.04, 0.03][rng.below(3) as usize];
    (case.volume, case.pose) = volume_and_pose(rng, voxel_size_m, [70, 61, 44], PI);
    if let Sensor::Depth(camera) = &mut case.sensor {
        camera.range = RangeLimits { min_m: 0.1, max_m: 6.0 };
    }
    let (near, far) = (0.3, 4.0);
    let mut case = surfaces(rng, case, near, far);
    // Surfaces on voxel faces half the time: tiles of an aligned pose end
    // where they begin.
    if rng.below(2) == 0 {
        if let Measurement::Depth(DepthImage { data: DepthData::Metres(m), .. }) = &mut case.measurement {
            m.iter_mut().for_each(|d| *d = ((*d as f64 / voxel_size_m).round() * voxel_size_m) as f32);
        }
    }
    case
}

/// `case` with its image in rectangles, each at one depth in `near..far`
/// (one in four any range, no return included).
fn surfaces(rng: &mut Rng, mut case: Case, near: f64, far: f64) -> Case {
    let (Sensor::Depth(camera), Measurement::Depth(image)) = (&case.sensor, &mut case.measurement) else {
        unreachable!()
    };
    let (w, h) = (camera.width as usize, camera.height as usize);
    let limits = camera.range;
    let (cols, rows) = [(1, 1), (3, 2), (7, 5), (w, h)][rng.below(4) as usize];
    let depths: Vec<f32> = (0..cols * rows)
        .map(|_| if rng.below(4) == 0 { self::range(rng, &limits) } else { rng.uniform(near, far) as f32 })
        .collect();
    let metres: Vec<f32> = (0..w * h).map(|i| depths[(i % w) * cols / w + cols * ((i / w) * rows / h)]).collect();
    image.data = match image.data {
        DepthData::Metres(_) => DepthData::Metres(metres),
        DepthData::U16 { metres_per_unit, .. } => {
            let values = metres
                .iter()
                .map(|&d| if d.is_finite() { (d / metres_per_unit).round().min(65535.0) as u16 } else { 0 })
                .collect();
            DepthData::U16 { values, metres_per_unit }
        }
    };
    case
}

/// A LiDAR among walls: the bins fall in sectors, each a wall at one
/// range for all its rings (some sectors open, some no return), so whole
/// tiles lie behind the walls their bins saw and the azimuth cull skips
/// them; sectors as narrow as a bin, and poses putting the ±π cut inside
/// the volume, test its edges.
fn lidar_walls_case(rng: &mut Rng) -> Case {
    let mut case = lidar_case(rng);
    let (Sensor::Lidar(lidar), Measurement::Lidar(scan)) = (&case.sensor, &mut case.measurement) else {
        unreachable!()
    };
    let bins = lidar.azimuth_bins;
    let limits = lidar.range;
    let sectors = [1, 2, 7, bins][rng.below(4) as usize];
    let walls: Vec<f32> = (0..sectors)
        .map(|_| if rng.below(4) == 0 { self::range(rng, &limits) } else { rng.uniform(0.1, 1.5) as f32 })
        .collect();
    let rotate = rng.below(bins as u64) as usize;
    for (i, d) in scan.ranges.iter_mut().enumerate() {
        let bin = (i % bins + rotate) % bins;
        *d = walls[bin * sectors / bins];
    }
    case
}

fn planar_case(rng: &mut Rng) -> Case {
    let range = limits(rng);
    let beams = [90usize, 360, 1081][rng.below(3) as usize];
    let span = if rng.below(2) == 0 { TAU } else { 1.5 * PI };
    let inc = span / beams as f64 * if rng.below(2) == 0 { 1.0 } else { -1.0 };
    let ranges = (0..beams).map(|_| self::range(rng, &range)).collect();
    let scan = LaserScan { angle_min_rad: rng.uniform(-PI, PI), angle_increment_rad: inc, ranges, range };
    let voxel_size_m = [0.05, 0.1][rng.below(2) as usize];
    let (volume, pose) = volume_and_pose(rng, voxel_size_m, [60, 52, 17], 0.1);
    finish(rng, Sensor::Planar, Measurement::Scan(scan), volume, pose)
}

/// The options: free margins from none to two voxels, planar slabs from
/// none to three voxels.
fn finish(rng: &mut Rng, sensor: Sensor, measurement: Measurement, volume: LocalVolume, pose: Isometry3<f64>) -> Case {
    let s = volume.voxel_size_m;
    let free_margin_m = [0.0, s * 3f64.sqrt() / 2.0, rng.uniform(0.0, 2.0 * s)][rng.below(3) as usize] as f32;
    let planar_half_thickness_m = [0.0, s / 2.0, rng.uniform(0.0, 3.0 * s)][rng.below(3) as usize] as f32;
    let clear_no_return = rng.below(2) == 0;
    Case { sensor, measurement, pose, volume, free_margin_m, clear_no_return, planar_half_thickness_m }
}

/// Checks `mark_misses` against `is_miss` on every voxel; returns the
/// number of misses.
fn check(n: usize, case: &Case) -> usize {
    let job = case.job();
    case.sensor.validate().expect("valid sensor");
    let obs = Observations::new(case.volume);
    mark_misses(&obs, &job);
    let geom = job.voxel_to_sensor();
    let [nx, ny, _] = case.volume.dims;
    let mut misses = 0;
    for i in 0..case.volume.len() {
        let c = [i % nx, (i / nx) % ny, i / (nx * ny)];
        let want = if job.is_miss(&geom, c) { OBS_MISS } else { OBS_NONE };
        assert_eq!(obs.get(i), want, "case {n} ({}): voxel {c:?}, point {:?}", case.sensor.kind(), geom.point(c));
        misses += usize::from(want == OBS_MISS);
    }
    misses
}

fn check_cases(seed: u64, count: usize, make: fn(&mut Rng) -> Case) {
    let mut rng = Rng(SplitMix(seed));
    let with_misses = (0..count).filter(|&n| check(n, &make(&mut rng)) > 0).count();
    // The cases must exercise the misses, not only empty volumes.
    assert!(with_misses * 3 > count, "{with_misses} of {count} cases had misses");
}

#[test]
fn culled_depth_projection_is_the_definition() {
    check_cases(0xdeb7, 150, depth_case);
}

#[test]
fn culled_depth_projection_facing_surfaces_is_the_definition() {
    check_cases(0x5fac, 150, depth_surfaces_case);
}

#[test]
fn culled_depth_projection_in_a_room_is_the_definition() {
    check_cases(0x400f, 120, depth_room_case);
}

#[test]
fn culled_lidar_projection_is_the_definition() {
    check_cases(0x11da, 150, lidar_case);
}

#[test]
fn culled_lidar_projection_among_walls_is_the_definition() {
    check_cases(0x3a11, 150, lidar_walls_case);
}

#[test]
fn culled_planar_projection_is_the_definition() {
    check_cases(0x91a4, 150, planar_case);
}
