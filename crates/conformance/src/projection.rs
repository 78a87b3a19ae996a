//! The volumetric projection suite: a depth camera (metric and 16-bit
//! images), planar scanners and spinning LiDARs at random poses over
//! synthetic measurements; a backend's bytes must match `ProjectJob::is_miss` on
//! every voxel it decides, and it may leave only a few undecided.

use super::SplitMix;
use edtmap_core::sensor::{
    DepthData, DepthImage, Frame, LaserScan, LidarScan, Measurement, PinholeCamera, RangeLimits, Sensor, SpinningLidar,
};
use edtmap_core::{
    Backend, LocalVolume, Observations, ProjectJob, VoxelIndex, OBS_MISS, OBS_NONE, PROJ_MISS, PROJ_NOT_MISS,
    PROJ_UNCERTAIN,
};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::{PI, TAU};

/// One frame of the projection suite, with the options it is projected
/// with.
#[derive(Debug, Clone)]
pub struct ProjectionCase {
    /// The sensor.
    pub sensor: Sensor,
    /// Its measurement and pose.
    pub frame: Frame,
    /// The volume projected.
    pub volume: LocalVolume,
    /// `ProjectJob::free_margin_m`.
    pub free_margin_m: f32,
    /// `ProjectJob::clear_no_return`.
    pub clear_no_return: bool,
    /// `ProjectJob::planar_half_thickness_m`.
    pub planar_half_thickness_m: f32,
    /// Whether the sensor is aligned with the voxel grid, its thresholds
    /// falling on voxel centres.
    pub aligned: bool,
}

impl ProjectionCase {
    /// The case as a backend receives it.
    pub fn job(&self) -> ProjectJob<'_> {
        ProjectJob {
            view: self.sensor.view(&self.frame.measurement).expect("a case's measurement is its sensor's own"),
            t_world_sensor: &self.frame.t_world_sensor,
            volume: self.volume,
            free_margin_m: self.free_margin_m,
            clear_no_return: self.clear_no_return,
            planar_half_thickness_m: self.planar_half_thickness_m,
        }
    }
}

/// What a backend left undecided: (voxels, uncertain voxels) per kind of
/// case.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ProjectionTally {
    /// Depth-camera cases in general position.
    pub depth: (usize, usize),
    /// Planar-scan cases in general position.
    pub planar: (usize, usize),
    /// Spinning-LiDAR cases in general position.
    pub lidar: (usize, usize),
    /// Aligned cases of both sensors, where many voxels sit on thresholds.
    pub aligned: (usize, usize),
}

fn uniform(rng: &mut SplitMix, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64
}

/// A volume of `dims` voxels of `voxel_size_m` somewhere near the world's
/// origin and a sensor position inside it (or, one time in four, outside),
/// on a voxel face or centre along each axis when `snap`.
fn volume_and_position(rng: &mut SplitMix, dims: [usize; 3], voxel_size_m: f64, snap: bool) -> (LocalVolume, [f64; 3]) {
    let origin = VoxelIndex([0, 1, 2].map(|_| rng.below(2000) - 1000));
    let volume = LocalVolume { origin, dims, voxel_size_m };
    let corner = volume.min_corner_m();
    let outside = rng.below(4) == 0;
    let t = [0, 1, 2].map(|k| {
        let extent = dims[k] as f64 * voxel_size_m;
        let f = if outside { uniform(rng, -0.3, 1.3) } else { uniform(rng, 0.2, 0.8) };
        // Half of the positions on voxel faces or centres, where ties live.
        let f = if snap || rng.below(2) == 0 { (f * dims[k] as f64 * 2.0).round() / (dims[k] as f64 * 2.0) } else { f };
        corner[k] + f * extent
    });
    (volume, t)
}

/// A depth image of a tilted plane with boxes in front, holes (NaN or 0)
/// and returns beyond the range.
fn depth_image(rng: &mut SplitMix, cam: &PinholeCamera, u16_data: bool) -> DepthImage {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let base = uniform(rng, 1.0, 4.0);
    let (gu, gv) = (uniform(rng, -0.01, 0.01), uniform(rng, -0.01, 0.01));
    let boxes: Vec<[f64; 5]> = (0..4)
        .map(|_| {
            [
                uniform(rng, 0.0, w as f64),
                uniform(rng, 0.0, h as f64),
                uniform(rng, 5.0, 40.0),
                uniform(rng, 5.0, 40.0),
                uniform(rng, 0.3, 2.0),
            ]
        })
        .collect();
    let mut metres = Vec::with_capacity(w * h);
    for v in 0..h {
        for u in 0..w {
            let mut d = base + gu * u as f64 + gv * v as f64;
            for b in &boxes {
                if (u as f64 - b[0]).abs() < b[2] && (v as f64 - b[1]).abs() < b[3] {
                    d = d.min(b[4]);
                }
            }
            let d = match rng.below(50) {
                0 => f64::NAN,
                1 => 0.0,
                2 => cam.range.max_m as f64 + 1.0,
                _ => d,
            };
            metres.push(d as f32);
        }
    }
    let data = if u16_data {
        let values =
            metres.iter().map(|&d| if d.is_finite() { (d * 1000.0).round().min(65535.0) as u16 } else { 0 }).collect();
        DepthData::U16 { values, metres_per_unit: 0.001 }
    } else {
        DepthData::Metres(metres)
    };
    DepthImage { width: cam.width, height: cam.height, data }
}

/// A planar scan of a room-like outline with gaps; a full or partial turn,
/// either direction, `angle_min` anywhere (also beyond ±π).
fn laser_scan(rng: &mut SplitMix) -> LaserScan {
    let beams = [360usize, 720, 1081, 1440][rng.below(4) as usize];
    let full = rng.below(2) == 0;
    let span = if full { TAU } else { 1.5 * PI };
    let inc = if rng.below(2) == 0 { span / beams as f64 } else { -span / beams as f64 };
    let angle_min_rad = uniform(rng, -PI, PI) + [0.0, TAU, -2.0 * TAU][rng.below(3) as usize];
    let centre = [uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0)];
    let half = [uniform(rng, 2.0, 4.0), uniform(rng, 2.0, 4.0)];
    let ranges = (0..beams)
        .map(|i| {
            let a = angle_min_rad + i as f64 * inc;
            let (c, s) = (a.cos(), a.sin());
            // Distance to the box's walls along the beam (the sensor is inside).
            let tx = if c > 0.0 { (centre[0] + half[0]) / c } else { (centre[0] - half[0]) / c };
            let ty = if s > 0.0 { (centre[1] + half[1]) / s } else { (centre[1] - half[1]) / s };
            match rng.below(40) {
                0 => f32::INFINITY,
                1 => f32::NAN,
                _ => tx.min(ty) as f32,
            }
        })
        .collect();
    LaserScan { angle_min_rad, angle_increment_rad: inc, ranges, range: RangeLimits { min_m: 0.1, max_m: 4.5 } }
}

/// A random rotation (roll and pitch within `tilt`), or when `aligned` one
/// whose axes are the world's, so that voxel centres line up with pixel
/// and beam boundaries.
fn random_rotation(rng: &mut SplitMix, tilt: f64, aligned: bool) -> UnitQuaternion<f64> {
    if aligned {
        let quarter = |rng: &mut SplitMix| f64::from(rng.below(4)) * PI / 2.0;
        let (roll, pitch) = if tilt > 1.0 { (quarter(rng), quarter(rng)) } else { (0.0, 0.0) };
        return UnitQuaternion::from_euler_angles(roll, pitch, quarter(rng));
    }
    let yaw = uniform(rng, -PI, PI);
    UnitQuaternion::from_euler_angles(uniform(rng, -tilt, tilt), uniform(rng, -tilt, tilt), yaw)
}

/// The cases of the projection suite (seeded): `depth` depth-camera frames
/// (alternating metric and 16-bit images), `planar` planar scans and
/// `lidar` spinning-LiDAR scans. One case in three (one in four for the
/// LiDAR) is aligned: the sensor's axes are the world's and it sits on
/// voxel faces or centres, the camera's pixel edges and depths (less the
/// free margin), the scan's beam edges and plane thickness, the LiDAR's
/// bin edges, a ring and its ranges fall on voxel centres, so the
/// backend's margins are exercised, not just its arithmetic.
pub fn projection_cases(depth: usize, planar: usize, lidar: usize) -> Vec<ProjectionCase> {
    let mut rng = SplitMix(0x5eed_0f9a_07ec_7000);
    let mut cases = Vec::new();
    for k in 0..depth {
        let voxel_size_m = [0.05, 0.1, 0.04][k % 3];
        let aligned = k % 3 == 2;
        let (volume, t) = volume_and_position(&mut rng, [72, 64, 40], voxel_size_m, aligned);
        let half_diagonal = (voxel_size_m * 3f64.sqrt() / 2.0) as f32;
        let (fx, fy, cx, cy) = if aligned { (100.0, 100.0, 79.5, 59.5) } else { (150.0, 149.0, 79.5, 60.25) };
        let cam =
            PinholeCamera { fx, fy, cx, cy, width: 160, height: 120, range: RangeLimits { min_m: 0.2, max_m: 5.0 } };
        let mut image = depth_image(&mut rng, &cam, k % 2 == 1 && !aligned);
        if let (true, DepthData::Metres(d)) = (aligned, &mut image.data) {
            // Every free range a multiple of half a voxel.
            let half = voxel_size_m / 2.0;
            d.iter_mut().for_each(|d| *d = ((f64::from(*d) / half).round() * half) as f32 + half_diagonal);
        }
        // Optical frame: z forward; any orientation.
        let rot = random_rotation(&mut rng, PI, aligned);
        let frame = Frame {
            stamp_s: k as f64,
            t_world_sensor: Isometry3::from_parts(Translation3::from(Vector3::from(t)), rot),
            measurement: Measurement::Depth(image),
        };
        cases.push(ProjectionCase {
            sensor: Sensor::Depth(cam),
            frame,
            volume,
            free_margin_m: half_diagonal,
            clear_no_return: k % 4 >= 2,
            planar_half_thickness_m: 0.0,
            aligned,
        });
    }
    for k in 0..planar {
        let voxel_size_m = [0.05, 0.1][k % 2];
        let aligned = k % 3 == 2;
        let (volume, t) = volume_and_position(&mut rng, [100, 90, 12], voxel_size_m, aligned);
        let mut scan = laser_scan(&mut rng);
        if aligned {
            // Whole degrees, the beam edges on the axes and diagonals.
            scan.angle_increment_rad = scan.angle_increment_rad.signum() * TAU / 360.0;
            scan.angle_min_rad = -PI + scan.angle_increment_rad / 2.0;
            scan.ranges.truncate(360);
        }
        let rot = random_rotation(&mut rng, 0.05, aligned);
        let frame = Frame {
            stamp_s: k as f64,
            t_world_sensor: Isometry3::from_parts(Translation3::from(Vector3::from(t)), rot),
            measurement: Measurement::Scan(scan),
        };
        let half = (voxel_size_m / 2.0) as f32;
        let margin = (voxel_size_m * 3f64.sqrt() / 2.0) as f32;
        cases.push(ProjectionCase {
            sensor: Sensor::Planar,
            frame,
            volume,
            free_margin_m: margin,
            clear_no_return: k % 3 == 0,
            planar_half_thickness_m: half,
            aligned,
        });
    }
    for k in 0..lidar {
        let voxel_size_m = [0.1, 0.2, 0.05][k % 3];
        let aligned = k % 4 == 3;
        let (volume, t) = volume_and_position(&mut rng, [64, 64, 24], voxel_size_m, aligned);
        let range = RangeLimits { min_m: 0.3, max_m: 6.0 };
        let sensor = if aligned {
            // Rings every 2° through 0°, bins of 1°: edges on the axes and
            // the diagonals.
            SpinningLidar::uniform(17, (-16f64).to_radians(), 16f64.to_radians(), 360, range)
        } else {
            let rings = [16usize, 32, 64][k % 3];
            let mut elevations: Vec<f64> = (0..rings).map(|_| uniform(&mut rng, -0.45, 0.3)).collect();
            elevations.sort_by(f64::total_cmp);
            elevations.dedup();
            SpinningLidar { ring_elevations_rad: elevations, azimuth_bins: [512, 1024, 1800, 2048][k % 4], range }
        };
        let mut scan = lidar_scan(&mut rng, &sensor);
        if aligned {
            let half = voxel_size_m / 2.0;
            let half_diagonal = voxel_size_m * 3f64.sqrt() / 2.0;
            scan.ranges
                .iter_mut()
                .filter(|d| d.is_finite())
                .for_each(|d| *d = ((f64::from(*d) / half).round() * half + half_diagonal) as f32);
        }
        let rot = random_rotation(&mut rng, 0.1, aligned);
        let frame = Frame {
            stamp_s: k as f64,
            t_world_sensor: Isometry3::from_parts(Translation3::from(Vector3::from(t)), rot),
            measurement: Measurement::Lidar(scan),
        };
        let margin = (voxel_size_m * 3f64.sqrt() / 2.0) as f32;
        cases.push(ProjectionCase {
            sensor: Sensor::Lidar(sensor),
            frame,
            volume,
            free_margin_m: margin,
            clear_no_return: k % 2 == 0,
            planar_half_thickness_m: 0.0,
            aligned,
        });
    }
    cases
}

/// A spinning LiDAR's scan from inside a box room (walls, floor and
/// ceiling), with dropouts (NaN, infinity, zero) and returns beyond the
/// range.
fn lidar_scan(rng: &mut SplitMix, lidar: &SpinningLidar) -> LidarScan {
    let centre = [uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0), uniform(rng, 0.0, 0.5)];
    let half = [uniform(rng, 2.0, 7.0), uniform(rng, 2.0, 7.0), uniform(rng, 1.0, 2.0)];
    let mut ranges = Vec::with_capacity(lidar.ring_elevations_rad.len() * lidar.azimuth_bins);
    for r in 0..lidar.ring_elevations_rad.len() {
        for b in 0..lidar.azimuth_bins {
            let d = lidar.direction(r, b);
            // Distance to the box's faces along the beam (the sensor is inside).
            let t = (0..3)
                .filter(|&a| d[a].abs() > 1e-12)
                .map(|a| (centre[a] + half[a].copysign(d[a])) / d[a])
                .fold(f64::INFINITY, f64::min);
            ranges.push(match rng.below(40) {
                0 => f32::INFINITY,
                1 => f32::NAN,
                2 => 0.0,
                _ => t as f32,
            });
        }
    }
    LidarScan { ranges }
}

/// Runs the projection suite on `backend` through
/// [`Backend::project_volume`]: every voxel must be a miss exactly where
/// `ProjectJob::is_miss` says so. Returns the voxels checked.
pub fn check_projection(backend: &mut dyn Backend) -> Result<usize, String> {
    let mut checked = 0;
    for (n, case) in projection_cases(12, 12, 8).iter().enumerate() {
        let job = case.job();
        let obs = Observations::new(case.volume);
        backend.project_volume(&job, &obs).map_err(|e| format!("case {n}: {e}"))?;
        let geom = job.voxel_to_sensor();
        let [nx, ny, _] = case.volume.dims;
        for i in 0..case.volume.len() {
            let c = [i % nx, (i / nx) % ny, i / (nx * ny)];
            let want = if job.is_miss(&geom, c) { OBS_MISS } else { OBS_NONE };
            if obs.get(i) != want {
                return Err(format!(
                    "case {n} ({}): voxel {c:?} is {}, the definition says {want}; point {:?}",
                    case.sensor.kind(),
                    obs.get(i),
                    geom.point(c)
                ));
            }
        }
        checked += case.volume.len();
    }
    Ok(checked)
}

/// The projection suite on a device's own bytes, before the host decides
/// the voxels it left uncertain: `project(job, bits)` fills one byte per
/// voxel ([`PROJ_MISS`], [`PROJ_NOT_MISS`], [`PROJ_UNCERTAIN`]) or returns
/// `false` where the device does not project. `Ok(None)` when it never
/// does, else the tally of uncertain voxels, or the first voxel it decided
/// differently from `ProjectJob::is_miss`.
pub fn check_projection_bits(
    mut project: impl FnMut(&ProjectJob<'_>, &mut Vec<u8>) -> Result<bool, String>,
) -> Result<Option<ProjectionTally>, String> {
    let mut tally = ProjectionTally::default();
    let mut bits = Vec::new();
    for (n, case) in projection_cases(12, 12, 8).iter().enumerate() {
        let job = case.job();
        if !project(&job, &mut bits)? {
            return Ok(None);
        }
        if bits.len() != case.volume.len() {
            return Err(format!("case {n}: {} bytes for {} voxels", bits.len(), case.volume.len()));
        }
        let geom = job.voxel_to_sensor();
        let [nx, ny, _] = case.volume.dims;
        let mut uncertain = 0;
        for (i, &b) in bits.iter().enumerate() {
            let c = [i % nx, (i / nx) % ny, i / (nx * ny)];
            let want = if job.is_miss(&geom, c) { PROJ_MISS } else { PROJ_NOT_MISS };
            match b {
                PROJ_UNCERTAIN => uncertain += 1,
                b if b == want => {}
                b => {
                    return Err(format!(
                        "case {n} ({}): voxel {c:?} is {b}, the definition says {want}; point {:?}",
                        case.sensor.kind(),
                        geom.point(c)
                    ))
                }
            }
        }
        let slot = match (case.aligned, &case.sensor) {
            (true, _) => &mut tally.aligned,
            (false, Sensor::Planar) => &mut tally.planar,
            (false, Sensor::Lidar(_)) => &mut tally.lidar,
            (false, _) => &mut tally.depth,
        };
        slot.0 += bits.len();
        slot.1 += uncertain;
    }
    Ok(Some(tally))
}
