//! How a frame's occupancy is built (paper §IV-A), as every backend and
//! the mapper's occupancy stage share it: the construction and its
//! options, the projection job a backend receives, and the returns' hits,
//! marked on the host.
//!
//! Both constructions write one observation per voxel per frame (a hit wins
//! over a miss), so the fused map does not depend on thread scheduling.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};

use crate::sensor::{Frame, ReturnBatch, Sensor, SensorRay, RETURN_BATCH};
use crate::{LocalVolume, Observations, ProjectJob, OBS_HIT};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// How a frame's occupancy is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Construction {
    /// Projection where the sensor model allows it, else ray casting.
    #[default]
    Auto,
    /// Ray casting (an exact fixed-point 3D DDA) from the sensor to each
    /// return.
    RayCasting,
    /// Volumetric projection of every voxel into the measurement.
    Projection,
}

/// Options of the occupancy stage. The lengths left `None` follow the
/// voxel size of the map in use (a loaded map's, whatever a configuration
/// said).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OgmOptions {
    /// Which construction runs.
    pub construction: Construction,
    /// Whether a ray with no return clears space up to the maximum range.
    pub clear_no_return: bool,
    /// Both constructions: a voxel is free only if it lies more than this
    /// in front of the return (ray casting: the ray leaves it that far
    /// before the return), metres. Voxels between are left unobserved, as
    /// the surface is only located to a voxel. `None`: half a voxel
    /// diagonal.
    pub free_margin_m: Option<f32>,
    /// Projection of planar scans: voxels within this height of the scan
    /// plane are observed, metres. `None`: half a voxel.
    pub planar_half_thickness_m: Option<f32>,
}

impl OgmOptions {
    /// The free margin at `voxel_size_m`: the one set, or half a voxel
    /// diagonal.
    pub fn free_margin_at(&self, voxel_size_m: f64) -> f32 {
        self.free_margin_m.unwrap_or((voxel_size_m * 3f64.sqrt() / 2.0) as f32)
    }

    /// The planar scans' half thickness at `voxel_size_m`: the one set, or
    /// half a voxel.
    pub fn planar_half_thickness_at(&self, voxel_size_m: f64) -> f32 {
        self.planar_half_thickness_m.unwrap_or((voxel_size_m / 2.0) as f32)
    }
}

/// The projection of `frame` over `volume` as a backend receives it;
/// `None` when projection cannot interpret the measurement (a point
/// cloud, or a measurement of another sensor).
pub fn project_job<'a>(
    sensor: &'a Sensor,
    frame: &'a Frame,
    volume: LocalVolume,
    opts: &OgmOptions,
) -> Option<ProjectJob<'a>> {
    Some(ProjectJob {
        view: sensor.view(&frame.measurement)?,
        t_world_sensor: &frame.t_world_sensor,
        volume,
        free_margin_m: opts.free_margin_at(volume.voxel_size_m),
        clear_no_return: opts.clear_no_return,
        planar_half_thickness_m: opts.planar_half_thickness_at(volume.voxel_size_m),
    })
}

/// Marks the voxel of every return as a hit: volumetric projection's hits
/// (voxels are usually larger than a beam's spacing, so testing only the
/// beam nearest a voxel's centre would miss a surface crossing it
/// off-centre; one pass over the returns finds them all).
///
/// A return `p` (sensor frame) lies at `(R p + t − corner) / s` in voxels
/// of the volume; its voxel is that point rounded down.
pub fn scatter_returns(obs: &Observations, sensor: &Sensor, frame: &Frame, rays: &mut Vec<SensorRay>) {
    let vol = *obs.volume();
    for_each_return_voxel(&vol, sensor, frame, rays, |voxel, mut starts| {
        while starts != 0 {
            let i = starts.trailing_zeros() as usize;
            starts &= starts - 1;
            let c = [0, 1, 2].map(|k| voxel[k][i] as usize);
            obs.mark(c, vol.linear(c), OBS_HIT);
        }
    });
}

/// `f(voxel, starts)` for each batch of `frame`'s returns in `vol`, in
/// parallel: the batch's voxels by axis ([`Voxels`]) and the bits of the
/// points that start a run of one voxel, each voxel marked once per run.
fn for_each_return_voxel(
    vol: &LocalVolume,
    sensor: &Sensor,
    frame: &Frame,
    rays: &mut Vec<SensorRay>,
    f: impl Fn(&[[i32; RETURN_BATCH]; 3], u64) + Sync,
) {
    let pose = &frame.t_world_sensor;
    let inv = 1.0 / vol.voxel_size_m;
    let to_volume = ToVolume {
        rot: pose.rotation.to_rotation_matrix().into_inner() * inv,
        origin: (pose.translation.vector - Vector3::from(vol.min_corner_m())) * inv,
        // No voxel index exceeds an i32; no volume is that wide.
        dims: vol.dims.map(|n| n.min(i32::MAX as usize) as f64),
    };
    sensor.par_returns(&frame.measurement, rays, |batch| {
        let Voxels { voxel, mut starts } = to_volume.voxels(batch);
        // Neighbouring pixels mostly share a voxel: it is marked once,
        // at the first point of each run.
        if batch.len < RETURN_BATCH {
            starts &= (1 << batch.len) - 1;
        }
        f(&voxel, starts);
    });
}

/// The voxels of a frame's returns, found apart from the observations so
/// that the search runs beside the projection (which marks its tiles with
/// plain stores) and the hits are marked after it: [`scatter_returns`] in
/// two steps, [`Self::find`] and [`Self::mark`]. Its buffer is kept from
/// frame to frame.
#[derive(Debug, Default)]
pub struct Returns {
    /// Each found voxel's coordinates, 21 bits per axis: `len` of them.
    voxels: Vec<AtomicU64>,
    len: AtomicUsize,
    volume: Option<LocalVolume>,
}

/// Bits per axis of a voxel's coordinates packed in [`Returns`].
const AXIS_BITS: u32 = 21;

impl Returns {
    /// Finds the voxels of `frame`'s returns in `vol`, for [`Self::mark`].
    /// `false` where they cannot be kept (a volume wider than 2²¹ voxels,
    /// or a buffer that cannot be allocated): nothing is kept then, and
    /// [`scatter_returns`] marks them.
    pub fn find(&mut self, vol: &LocalVolume, sensor: &Sensor, frame: &Frame, rays: &mut Vec<SensorRay>) -> bool {
        self.volume = None;
        *self.len.get_mut() = 0;
        let n = frame.measurement.values();
        if vol.dims.iter().any(|&d| d >= 1 << AXIS_BITS) || !self.room_for(n) {
            return false;
        }
        let (voxels, len) = (&self.voxels[..n], &self.len);
        let overflow = AtomicBool::new(false);
        for_each_return_voxel(vol, sensor, frame, rays, |voxel, mut starts| {
            let k = starts.count_ones() as usize;
            if k == 0 {
                return;
            }
            let first = len.fetch_add(k, Ordering::Relaxed);
            let Some(slots) = voxels.get(first..first + k) else {
                overflow.store(true, Ordering::Relaxed);
                return;
            };
            for slot in slots {
                let i = starts.trailing_zeros() as usize;
                starts &= starts - 1;
                let c = [0, 1, 2].map(|a| voxel[a][i] as u64);
                slot.store(c[0] | c[1] << AXIS_BITS | c[2] << (2 * AXIS_BITS), Ordering::Relaxed);
            }
        });
        // A measurement gives a return per value at most; more would be a
        // model's mistake, and the marks fall back to the direct way.
        if overflow.into_inner() {
            return false;
        }
        self.volume = Some(*vol);
        true
    }

    /// Room for `n` voxels, kept from frame to frame; `false` where the
    /// allocation cannot be made.
    fn room_for(&mut self, n: usize) -> bool {
        if self.voxels.len() >= n {
            return true;
        }
        if self.voxels.try_reserve_exact(n - self.voxels.len()).is_err() {
            return false;
        }
        self.voxels.resize_with(n, || AtomicU64::new(0));
        true
    }

    /// Marks the voxels [`Self::find`] found as hits of `obs`, whose volume
    /// they were found in; `false` (nothing marked) where the last `find`
    /// kept nothing or ran over another volume.
    pub fn mark(&self, obs: &Observations) -> bool {
        let Some(vol) = self.volume.filter(|v| v == obs.volume()) else {
            return false;
        };
        let len = self.len.load(Ordering::Relaxed).min(self.voxels.len());
        let mask = (1u64 << AXIS_BITS) - 1;
        self.voxels[..len].par_chunks(4096).for_each(|chunk| {
            for v in chunk {
                let v = v.load(Ordering::Relaxed);
                let c = [v & mask, v >> AXIS_BITS & mask, v >> (2 * AXIS_BITS)].map(|x| x as usize);
                obs.mark(c, vol.linear(c), OBS_HIT);
            }
        });
        true
    }
}

/// A batch's voxels ([`ToVolume::voxels`]).
struct Voxels {
    /// The voxel of each point, by axis; `-1` on every axis for a point
    /// outside the volume or NaN.
    voxel: [[i32; RETURN_BATCH]; 3],
    /// Bit `i` set where point `i` lies in the volume and in another voxel
    /// than point `i − 1` (or is the first): the runs' first points.
    starts: u64,
}

/// A point's voxel in a local volume: `rot · p + origin`, rounded down.
struct ToVolume {
    /// The sensor's rotation into the volume, in voxels.
    rot: Matrix3<f64>,
    /// The sensor's position in the volume, in voxels.
    origin: Vector3<f64>,
    /// The volume's voxels along each axis.
    dims: [f64; 3],
}

impl ToVolume {
    /// The voxel of each point of `batch`, by axis, `-1` on every axis for
    /// a point outside the volume or NaN. The coordinates take nalgebra's
    /// operations for `Matrix3 * Vector3 + Vector3` in its order (a row's
    /// first two products summed, then the third, then the offset), so
    /// each is the same to the bit; written out without branches so that
    /// a batch is computed in vector registers.
    fn voxels(&self, batch: &ReturnBatch) -> Voxels {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { self.voxels_avx2(batch) };
        }
        self.voxels_of(batch)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn voxels_avx2(&self, batch: &ReturnBatch) -> Voxels {
        self.voxels_of(batch)
    }

    #[inline(always)]
    fn voxels_of(&self, batch: &ReturnBatch) -> Voxels {
        let [x, y, z] = &batch.xyz;
        let (m, o, n) = (self.rot, self.origin, self.dims);
        let mut q = [[0f64; RETURN_BATCH]; 3];
        for (k, q) in q.iter_mut().enumerate() {
            let (a, b, c, o) = (m[(k, 0)], m[(k, 1)], m[(k, 2)], o[k]);
            for i in 0..RETURN_BATCH {
                q[i] = (a * x[i] + b * y[i]) + c * z[i] + o;
            }
        }
        let mut voxel = [[-1; RETURN_BATCH]; 3];
        for i in 0..RETURN_BATCH {
            // Truncation is the floor on [0, n); NaN fails the test.
            let inside = (q[0][i] >= 0.0 && q[0][i] < n[0])
                & (q[1][i] >= 0.0 && q[1][i] < n[1])
                & (q[2][i] >= 0.0 && q[2][i] < n[2]);
            for k in 0..3 {
                let v = if inside { q[k][i] } else { -1.0 };
                // SAFETY: `v` is -1 or in [0, n) with n at most i32::MAX
                // (see `dims`), so it truncates to an i32.
                voxel[k][i] = unsafe { v.to_int_unchecked::<i32>() };
            }
        }
        let mut starts = u64::from(voxel[0][0] >= 0);
        for i in 1..RETURN_BATCH {
            let moved = (0..3).fold(false, |m, k| m | (voxel[k][i] != voxel[k][i - 1]));
            starts |= u64::from(moved & (voxel[0][i] >= 0)) << i;
        }
        Voxels { voxel, starts }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::{DepthData, DepthImage, Measurement, PinholeCamera, RangeLimits};
    use crate::VoxelIndex;
    use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
    use proptest::prelude::*;
    use proptest::test_runner::RngSeed;
    use std::collections::HashSet;

    /// A volume too wide for the packed coordinates keeps nothing: the
    /// caller marks the returns directly.
    #[test]
    fn returns_in_a_volume_too_wide_are_left_to_the_direct_way() {
        let cam = PinholeCamera {
            fx: 4.0,
            fy: 4.0,
            cx: 2.0,
            cy: 2.0,
            width: 4,
            height: 4,
            range: RangeLimits { min_m: 0.1, max_m: 5.0 },
        };
        let image = DepthImage { width: 4, height: 4, data: DepthData::Metres(vec![0.5; 16]) };
        let frame =
            Frame { stamp_s: 0.0, t_world_sensor: Isometry3::identity(), measurement: Measurement::Depth(image) };
        let wide = LocalVolume { origin: VoxelIndex([-8, -8, -8]), dims: [1 << AXIS_BITS, 16, 16], voxel_size_m: 0.1 };
        let mut returns = Returns::default();
        assert!(!returns.find(&wide, &Sensor::Depth(cam.clone()), &frame, &mut Vec::new()));
        let vol = LocalVolume { dims: [16, 16, 16], ..wide };
        assert!(returns.find(&vol, &Sensor::Depth(cam), &frame, &mut Vec::new()));
        let obs = Observations::new(vol);
        assert!(returns.mark(&obs));
        assert!((0..vol.len()).any(|i| obs.get(i) == OBS_HIT), "the wall at 0.5 m is hit");
    }

    /// Voxels (local linear indices) of the returns, by the world point
    /// `T (ray(u, v) · d)` through nalgebra's isometry and
    /// [`VoxelIndex::containing`]: `sure` those of points at least 1e-6
    /// voxel from every face, `maybe` every voxel a point within that of a
    /// face may round to.
    fn oracle(
        vol: &LocalVolume,
        cam: &PinholeCamera,
        depths: &[f32],
        pose: &Isometry3<f64>,
    ) -> (HashSet<usize>, HashSet<usize>) {
        let (mut sure, mut maybe) = (HashSet::new(), HashSet::new());
        for (i, &d) in depths.iter().enumerate() {
            if !cam.range.accepts(d) {
                continue;
            }
            let (u, v) = ((i % cam.width as usize) as u32, (i / cam.width as usize) as u32);
            let ray = cam.pixel_ray(u, v).map(|c| c * d as f64);
            let p = pose.transform_point(&Point3::from(ray)).coords / vol.voxel_size_m;
            let near_face = (0..3).any(|k| (p[k] - p[k].round()).abs() < 1e-6);
            for dx in [-1e-6, 1e-6] {
                for dy in [-1e-6, 1e-6] {
                    for dz in [-1e-6, 1e-6] {
                        let w = VoxelIndex::containing([p[0] + dx, p[1] + dy, p[2] + dz], 1.0).expect("finite");
                        if let Some(c) = vol.local(w) {
                            maybe.insert(vol.linear(c));
                        }
                    }
                }
            }
            if !near_face {
                let w = VoxelIndex::containing(p.into(), 1.0).expect("finite");
                if let Some(c) = vol.local(w) {
                    sure.insert(vol.linear(c));
                }
            }
        }
        (sure, maybe)
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 200, rng_seed: RngSeed::Fixed(0x5CA7), ..ProptestConfig::default() })]
        /// Every return's voxel is a hit and every hit is a return's voxel,
        /// against an independent transform of each pixel's point; depths
        /// land on voxel faces (multiples of the voxel size) as often as not.
        #[test]
        fn depth_returns_hit_their_voxels(
            axis in proptest::array::uniform3(-1.0f64..1.0),
            angle in -3.2f64..3.2,
            t in proptest::array::uniform3(-2.0f64..2.0),
            origin in proptest::array::uniform3(-40i32..0),
            voxel_size_m in prop_oneof![Just(0.05), Just(0.1), 0.02f64..0.3],
            depths in proptest::collection::vec(prop_oneof![0.0f32..6.0, (1u32..60).prop_map(|k| k as f32 * 0.1), Just(f32::NAN)], 70 * 6),
        ) {
            // Rows of 70 pixels: a whole batch and part of another.
            let cam = PinholeCamera { fx: 40.0, fy: 21.0, cx: 34.5, cy: 2.5, width: 70, height: 6, range: RangeLimits { min_m: 0.2, max_m: 5.0 } };
            let axis = nalgebra::Vector3::from(axis);
            let rot = match nalgebra::Unit::try_new(axis, 1e-3) { Some(a) => UnitQuaternion::from_axis_angle(&a, angle), None => UnitQuaternion::identity() };
            let pose = Isometry3::from_parts(Translation3::from(nalgebra::Vector3::from(t)), rot);
            let vol = LocalVolume { origin: VoxelIndex([origin[0], origin[1], origin[2] / 2]), dims: [60, 50, 40], voxel_size_m };
            let frame = Frame { stamp_s: 0.0, t_world_sensor: pose, measurement: Measurement::Depth(DepthImage { width: 70, height: 6, data: DepthData::Metres(depths.clone()) }) };
            let obs = Observations::new(vol);
            let sensor = Sensor::Depth(cam.clone());
            scatter_returns(&obs, &sensor, &frame, &mut Vec::new());
            let hits_of = |obs: &Observations| (0..vol.len()).filter(|&i| obs.get(i) & OBS_HIT != 0).collect::<HashSet<usize>>();
            let hits = hits_of(&obs);
            let (sure, maybe) = oracle(&vol, &cam, &depths, &pose);
            prop_assert!(!maybe.is_empty() || hits.is_empty());
            prop_assert!(sure.is_subset(&hits), "returns not hit: {:?}", sure.difference(&hits).collect::<Vec<_>>());
            prop_assert!(hits.is_subset(&maybe), "hits of no return: {:?}", hits.difference(&maybe).collect::<Vec<_>>());
            // Found first and marked after: the same hits, in the cells
            // the observations list.
            let (two_steps, mut returns) = (Observations::new(vol), Returns::default());
            prop_assert!(returns.find(&vol, &sensor, &frame, &mut Vec::new()));
            prop_assert!(returns.mark(&two_steps));
            prop_assert_eq!(hits_of(&two_steps), hits);
            let listed = |obs: &Observations| { let mut v = obs.observed(); v.sort_unstable(); v };
            prop_assert_eq!(listed(&two_steps), listed(&obs));
            // Not into another volume.
            let other = LocalVolume { dims: [60, 50, 41], ..vol };
            prop_assert!(!returns.mark(&Observations::new(other)));
        }

        /// A batch's voxels are those of nalgebra's `rot * p + origin`,
        /// rounded down, to the bit: points near voxel faces, on them, and
        /// outside the volume or NaN (no voxel).
        #[test]
        fn batch_voxels_are_nalgebras(
            axis in proptest::array::uniform3(-1.0f64..1.0),
            angle in -3.2f64..3.2,
            origin in proptest::array::uniform3(-30.0f64..30.0),
            points in proptest::collection::vec(proptest::array::uniform3(prop_oneof![-40.0f64..40.0, (-400i32..400).prop_map(|k| f64::from(k) * 0.1), Just(f64::NAN)]), 1..=RETURN_BATCH),
        ) {
            let axis = nalgebra::Vector3::from(axis);
            let rot = match nalgebra::Unit::try_new(axis, 1e-3) { Some(a) => UnitQuaternion::from_axis_angle(&a, angle), None => UnitQuaternion::identity() };
            let to = ToVolume { rot: rot.to_rotation_matrix().into_inner() * 20.0, origin: Vector3::from(origin), dims: [60.0, 50.0, 40.0] };
            let mut batch = ReturnBatch::new();
            points.iter().for_each(|&p| batch.push(p));
            let Voxels { voxel, starts } = to.voxels(&batch);
            let mut last = [-1; 3];
            for (i, p) in batch.points().enumerate() {
                let q = to.rot * Vector3::from(p) + to.origin;
                let inside = (0..3).all(|k| q[k] >= 0.0 && q[k] < to.dims[k]);
                let want = if inside { [0, 1, 2].map(|k| q[k].floor() as i32) } else { [-1; 3] };
                prop_assert_eq!([voxel[0][i], voxel[1][i], voxel[2][i]], want, "point {:?} at {:?}", p, q);
                prop_assert_eq!(starts >> i & 1 == 1, inside && want != last, "point {}", i);
                last = want;
            }
        }
    }
}
