//! A spinning LiDAR's [`ProjectJob::is_miss_at`], its necessary conditions
//! tested cheapest first, and its angles decided without trigonometry.
//!
//! The definition projects every voxel (two `atan2`), then asks whether a
//! ring passes near it (a square root and an `asin`). Most voxels of a
//! window fail on range (behind the wall a beam hit) or fall between
//! rings, so [`LidarMiss`] tests the range first, against the farthest free
//! range of the whole scan, then the ring, then the azimuth bin, then the
//! beam's range.
//!
//! Every angle the definition compares is a threshold on an angle of `p`:
//! the elevation against the bounds between rings and the fan's edges, its
//! distance to the nearest ring against `asin(r_half / |p|)`, the azimuth
//! against the bins' edges. Each comparison is a sign in the plane that
//! holds the angle: `el > θ` exactly when `z cos θ − h sin θ > 0`
//! (`h` the horizontal distance), `az > β` when `y cos β − x sin β > 0`
//! within a half turn, and `|el − ring| ≤ asin(r / |p|)` when the
//! distance of `p` to the ring's cone, `|z cos ring − h sin ring|`, is at
//! most `r` (for angles below a right angle, which [`Angles::new`]
//! checks). [`Angles`] evaluates these products in `f64` and accepts
//! their sign only beyond a margin of 1e-9 of the point's scale, some
//! million times what the definition's `atan2`/`asin` and these products
//! err by; a voxel that lands within the margin of a threshold goes to
//! the definition's own functions ([`LidarMiss::is_miss_exact`]). So the
//! answer is the definition's bit for bit, and a typical voxel costs a few
//! multiplications instead of three inverse trigonometric functions.

use super::ProjectJob;
use crate::sensor::{norm, LidarScan, SpinningLidar, View};
use std::f64::consts::{FRAC_PI_2, PI};

/// Relative margin on the sign tests: a sign is trusted when the product
/// exceeds this times the point's scale (the rounding of the definition's
/// angles, and of these products, is below 1e-15 of it).
const SIGN_MARGIN: f64 = 1e-9;
/// Largest angle between a point in a ring's band and the ring for which
/// the cone-distance test is used, radians: `sin` is monotonic well below
/// a right angle, so the test is the definition's `asin` comparison.
const MAX_BAND_RAD: f64 = 1.2;

/// [`ProjectJob::is_miss_at`] of a LiDAR job, with its bounds.
#[derive(Debug, Clone)]
pub(super) struct LidarMiss<'a> {
    job: ProjectJob<'a>,
    lidar: &'a SpinningLidar,
    scan: &'a LidarScan,
    /// Per azimuth bin, the largest [`ProjectJob::free_below_m`] of its
    /// beams: a voxel behind the walls that bin saw costs one `atan2`.
    bin_free_below_m: Vec<f32>,
    /// The largest of `bin_free_below_m`.
    free_below_m: f32,
    /// The radius `is_miss_at` gives the ring test, metres.
    half_voxel_m: f32,
    /// The sign tables, when the sensor's geometry allows them.
    angles: Option<Angles>,
}

impl<'a> LidarMiss<'a> {
    /// The decision for `job`, when it projects a LiDAR range image.
    pub(super) fn new(job: &ProjectJob<'a>) -> Option<Self> {
        let View::Rings { lidar, scan } = job.view else {
            return None;
        };
        let mut bin_free_below_m = vec![f32::MIN; lidar.azimuth_bins];
        for ring in scan.ranges.chunks(lidar.azimuth_bins) {
            for (sup, &d) in bin_free_below_m.iter_mut().zip(ring) {
                *sup = sup.max(job.free_below_m(d, &lidar.range));
            }
        }
        let free_below_m = bin_free_below_m.iter().copied().fold(f32::MIN, f32::max);
        let half_voxel_m = (job.volume.voxel_size_m / 2.0) as f32;
        let angles = Angles::new(lidar);
        Some(LidarMiss { job: *job, lidar, scan, bin_free_below_m, free_below_m, half_voxel_m, angles })
    }

    /// Per azimuth bin, the largest [`ProjectJob::free_below_m`] of its
    /// beams, metres.
    pub(super) fn bin_free_below_m(&self) -> &[f32] {
        &self.bin_free_below_m
    }

    /// The largest [`ProjectJob::free_below_m`] of the scan, metres.
    pub(super) fn free_below_sup(&self) -> f32 {
        self.free_below_m
    }

    /// [`ProjectJob::is_miss_at`]`(p)`, by sign tests where they are
    /// certain and by [`Self::is_miss_exact`] where they are not. `hint`
    /// is where the search for `p`'s ring starts, and is left at its end:
    /// neighbouring voxels have neighbouring rings (any start gives the
    /// same answer).
    #[inline]
    pub(super) fn is_miss_at(&self, p: [f32; 3], hint: &mut usize) -> bool {
        // A NaN range passes this bound and goes to the exact test.
        let point_m = norm(p);
        if point_m >= self.free_below_m {
            return false;
        }
        let Some(angles) = &self.angles else {
            return self.is_miss_exact(p, point_m);
        };
        let horiz = (p[0] * p[0] + p[1] * p[1]).sqrt() as f64;
        let (ring, bin) = match angles.ring(p[2] as f64, horiz, self.half_voxel_m as f64, hint) {
            Decided::No => return false,
            Decided::Unsure => return self.is_miss_exact(p, point_m),
            Decided::Yes(ring) => match angles.bin(p[0] as f64, p[1] as f64) {
                Some(bin) => (ring, bin),
                None => return self.is_miss_exact(p, point_m),
            },
        };
        let measured_m = self.scan.ranges[ring * self.lidar.azimuth_bins + bin];
        point_m < self.job.free_below_m(measured_m, &self.lidar.range)
    }

    /// [`ProjectJob::is_miss_at`]`(p)` with the definition's own functions,
    /// `point_m` being `p`'s range: free in its beam (range below the
    /// beam's [`ProjectJob::free_below_m`], which is what
    /// `ProjectJob::is_free` compares for a return and for no return), in
    /// the fan, near a ring.
    fn is_miss_exact(&self, p: [f32; 3], point_m: f32) -> bool {
        let bin = self.lidar.azimuth_bin(p);
        if point_m >= self.bin_free_below_m[bin] {
            return false;
        }
        let (horiz, el) = SpinningLidar::elevation(p);
        let Some(ring) = self.lidar.nearest_ring(el) else {
            return false;
        };
        let measured_m = self.scan.ranges[ring * self.lidar.azimuth_bins + bin];
        point_m < self.job.free_below_m(measured_m, &self.lidar.range)
            && self.lidar.ring_passes_at(p, horiz, el, self.half_voxel_m)
    }
}

/// A decision of [`Angles::ring`].
enum Decided {
    /// The point is not near its nearest ring (or outside the fan).
    No,
    /// Its nearest ring, which passes within the radius.
    Yes(usize),
    /// Too close to a threshold for the sign tests.
    Unsure,
}

/// A direction `(cos θ, sin θ)` of a threshold angle `θ`.
type Dir = (f64, f64);

/// The thresholds of a LiDAR's angles as directions.
#[derive(Debug, Clone)]
struct Angles {
    /// Ring `k` is the nearest for elevations in `(bounds[k], bounds[k+1])`:
    /// the fan's lower edge, the midpoints between rings, the upper edge
    /// (an edge beyond the vertical taken at the vertical, where the sign
    /// tests are never sure, so the definition decides).
    bounds: Vec<Dir>,
    /// Each ring's elevation.
    rings: Vec<Dir>,
    /// Bin `b` covers azimuths in `(edges[b], edges[b+1])`.
    edges: Vec<Dir>,
    /// Bins per radian, for the first guess of a bin.
    bins_per_rad: f64,
    /// [`ATAN`], for the first guess of a bin.
    atan: &'static [f64],
}

impl Angles {
    /// The tables for `lidar`, or `None` for geometries the sign tests do
    /// not cover (bins of a half turn or more, a ring band wider than
    /// [`MAX_BAND_RAD`]).
    fn new(lidar: &SpinningLidar) -> Option<Self> {
        let rings = &lidar.ring_elevations_rad;
        let n = rings.len();
        if lidar.azimuth_bins < 3 {
            return None;
        }
        let (lo, hi) = lidar.fan_rad();
        let mut angles = vec![lo];
        angles.extend(rings.windows(2).map(|w| (w[0] + w[1]) / 2.0));
        angles.push(hi);
        let wide = (0..n).any(|k| {
            let band = (angles[k].max(-FRAC_PI_2), angles[k + 1].min(FRAC_PI_2));
            rings[k] - band.0 > MAX_BAND_RAD || band.1 - rings[k] > MAX_BAND_RAD
        });
        // Inner bounds lie between rings, strictly within ±90°.
        if wide || angles[1..n].iter().any(|a| a.abs() >= FRAC_PI_2) {
            return None;
        }
        let dir = |a: f64| (a.cos(), a.sin());
        let bounds = angles.iter().map(|&a| dir(a.clamp(-FRAC_PI_2, FRAC_PI_2))).collect();
        let bins = lidar.azimuth_bins;
        let edges = (0..=bins).map(|b| dir(-PI + 2.0 * PI * b as f64 / bins as f64)).collect();
        Some(Angles {
            bounds,
            rings: rings.iter().map(|&e| dir(e)).collect(),
            edges,
            bins_per_rad: bins as f64 / (2.0 * PI),
            atan: ATAN.as_slice(),
        })
    }

    /// The ring nearest to the elevation of `(h, z)` (`h` the horizontal
    /// distance, as [`SpinningLidar::elevation`] rounds it) and whether it
    /// passes within `radius_m`, as [`SpinningLidar::nearest_ring`] and
    /// [`SpinningLidar::ring_passes_at`] decide; the search for the
    /// bounds around the elevation walks from `hint` and leaves it there.
    #[inline]
    fn ring(&self, z: f64, h: f64, radius_m: f64, hint: &mut usize) -> Decided {
        let scale = z.abs() + h;
        let margin = SIGN_MARGIN * scale;
        // `z cos θ − h sin θ = |p| sin(el − θ)`: its sign is that of el − θ.
        let side = |&(c, s): &Dir| z * c - h * s;
        // The number of bounds below el: ring `k` when it is k + 1. Each
        // answer below rests on sure signs alone, whatever this count says.
        let mut k = (*hint).min(self.bounds.len());
        while k < self.bounds.len() && side(&self.bounds[k]) > 0.0 {
            k += 1;
        }
        while k > 0 && side(&self.bounds[k - 1]) <= 0.0 {
            k -= 1;
        }
        *hint = k;
        if k == 0 {
            return if side(&self.bounds[0]) < -margin { Decided::No } else { Decided::Unsure };
        }
        if k == self.bounds.len() {
            return if side(&self.bounds[k - 1]) > margin { Decided::No } else { Decided::Unsure };
        }
        if !(side(&self.bounds[k - 1]) > margin && side(&self.bounds[k]) < -margin) {
            return Decided::Unsure;
        }
        let ring = k - 1;
        let cone_m = side(&self.rings[ring]).abs();
        if cone_m < radius_m - margin {
            Decided::Yes(ring)
        } else if cone_m > radius_m + margin {
            Decided::No
        } else {
            Decided::Unsure
        }
    }

    /// The azimuth bin of `(x, y)`, as [`SpinningLidar::azimuth_bin`]
    /// gives it, or `None` within the margin of a bin's edge.
    #[inline]
    fn bin(&self, x: f64, y: f64) -> Option<usize> {
        let bins = self.edges.len() - 1;
        let guess = ((fast_atan2(y, x, self.atan) + PI) * self.bins_per_rad) as usize;
        let b = guess.min(bins - 1);
        let margin = SIGN_MARGIN * (x.abs() + y.abs());
        // `y cos β − x sin β = |p| sin(az − β)`, within a bin's width < π.
        let side = |(c, s): Dir| y * c - x * s;
        (side(self.edges[b]) > margin && side(self.edges[b + 1]) < -margin).then_some(b)
    }
}

/// Steps of [`ATAN`] over `[0, 1]`.
const ATAN_STEPS: usize = 1024;

/// `atan(i / ATAN_STEPS)` for `i` in `0..=ATAN_STEPS + 1` (one past the
/// end, so that `t = 1` interpolates without a test).
pub(super) static ATAN: std::sync::LazyLock<Vec<f64>> =
    std::sync::LazyLock::new(|| (0..=ATAN_STEPS + 1).map(|i| (i as f64 / ATAN_STEPS as f64).atan()).collect());

/// `atan2(y, x)` to some 1e-7 rad, for a first guess only: every answer
/// built on it is checked by sign tests. The arctangent of the ratio
/// (in `[0, 1]`) is interpolated linearly in [`ATAN`]: the error is at
/// most `h² max|atan''| / 8 ≈ 0.65 / (8 · 1024²) < 1e-7`, from one
/// division and a table that fits the L1 cache, where a polynomial costs
/// a chain of eight multiply-adds.
#[inline]
pub(super) fn fast_atan2(y: f64, x: f64, atan: &[f64]) -> f64 {
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = if ay > ax { (ax, ay) } else { (ay, ax) };
    let t = if den > 0.0 { num / den } else { 0.0 };
    let f = t * ATAN_STEPS as f64;
    // `t` is in [0, 1] (NaN only for NaN input, which casts to 0); through
    // `u32`, the casts are one instruction each.
    let i = (f as u32).min(ATAN_STEPS as u32);
    let a = atan[i as usize] + (f - f64::from(i)) * (atan[i as usize + 1] - atan[i as usize]);
    let a = if ay > ax { FRAC_PI_2 - a } else { a };
    let a = if x < 0.0 { PI - a } else { a };
    if y < 0.0 {
        -a
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::RangeLimits;
    use crate::{LocalVolume, VoxelIndex};
    use nalgebra::Isometry3;

    #[test]
    fn fast_atan2_guesses_within_1e_7() {
        let mut worst: f64 = 0.0;
        for i in 0..20_000 {
            let a = -PI + 2.0 * PI * (i as f64 + 0.37) / 20_000.0;
            let (x, y) = (3.0 * a.cos(), 3.0 * a.sin());
            worst = worst.max((fast_atan2(y, x, &ATAN) - y.atan2(x)).abs());
        }
        // The octants' edges: t = 0 and t = 1 exactly.
        for (x, y) in [
            (1.0, 0.0),
            (2.0, 2.0),
            (0.0, 1.5),
            (-1.0, 1.0),
            (-3.0, 0.0),
            (-0.5, -0.5),
            (0.0, -2.0),
            (4.0, -4.0),
            (1e-300, 1.0),
        ] {
            worst = worst.max((fast_atan2(y, x, &ATAN) - f64::atan2(y, x)).abs());
        }
        assert!(worst < 1e-7, "{worst}");
    }

    /// xorshift64*, seeded: uniform draws in `[lo, hi)`.
    struct Rng(u64);

    impl Rng {
        fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let u = (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64;
            lo + (hi - lo) * u
        }
    }

    /// Points placed on the thresholds the sign tests decide (bin edges,
    /// bounds between rings, the fan's edges, a half voxel from a ring's
    /// cone) and a hair either side of them: the fast decision must be the
    /// definition's on every one.
    #[test]
    fn points_on_every_threshold_get_the_definitions_answer() {
        let mut rng = Rng(0x5eed_11da);
        let (mut checked, mut misses) = (0, 0);
        for case in 0..40 {
            let rings = [1, 2, 5, 32][case % 4];
            let bins = [3, 90, 900, 1024][(case / 4) % 4];
            let range = RangeLimits { min_m: 0.1, max_m: 30.0 };
            let (lo, hi) = (rng.uniform(-0.6, -0.01), rng.uniform(0.01, 0.6));
            let mut lidar = SpinningLidar::uniform(rings, lo, hi, bins, range);
            if rings > 2 && case % 3 == 0 {
                lidar.ring_elevations_rad.iter_mut().skip(1).for_each(|e| *e += rng.uniform(0.0, 0.004));
            }
            lidar.validate().expect("valid LiDAR");
            let ranges = (0..rings * bins).map(|_| rng.uniform(0.0, 40.0) as f32).collect();
            let scan = LidarScan { ranges };
            let voxel_size_m = [0.05, 0.2][case % 2];
            let pose = Isometry3::identity();
            let volume = LocalVolume { origin: VoxelIndex([0, 0, 0]), dims: [8, 8, 8], voxel_size_m };
            let job = ProjectJob {
                view: View::Rings { lidar: &lidar, scan: &scan },
                t_world_sensor: &pose,
                volume,
                free_margin_m: 0.0,
                clear_no_return: false,
                planar_half_thickness_m: 0.0,
            };
            let fast = LidarMiss::new(&job).expect("a LiDAR job");
            assert!(fast.angles.is_some(), "case {case}: sign tables");
            let (fan_lo, fan_hi) = lidar.fan_rad();
            let mut elevations: Vec<f64> = vec![fan_lo, fan_hi];
            elevations.extend(lidar.ring_elevations_rad.windows(2).map(|w| (w[0] + w[1]) / 2.0));
            let radius_m = voxel_size_m / 2.0;
            for _ in 0..400 {
                let dist_m = rng.uniform(0.2, 20.0);
                let ring = lidar.ring_elevations_rad[(rng.uniform(0.0, rings as f64) as usize).min(rings - 1)];
                let cone = ring + [1.0, -1.0][rng.uniform(0.0, 2.0) as usize] * (radius_m / dist_m).asin();
                let el = [elevations[rng.uniform(0.0, elevations.len() as f64) as usize], cone, rng.uniform(lo, hi)]
                    [rng.uniform(0.0, 3.0) as usize];
                let edge = (rng.uniform(0.0, bins as f64 + 1.0) as usize).min(bins);
                let az =
                    [-PI + 2.0 * PI * edge as f64 / bins as f64, rng.uniform(-PI, PI)][rng.uniform(0.0, 2.0) as usize];
                for nudge in [0.0, 1e-15, -1e-15, 1e-12, -1e-12, 1e-9, -1e-9, 1e-6, -1e-6] {
                    let (el, az) = (el + nudge, az + nudge * rng.uniform(-1.0, 1.0));
                    let p = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()].map(|c| (c * dist_m) as f32);
                    let want = job.is_miss_at(p);
                    let mut hint = rng.uniform(0.0, rings as f64 + 2.0) as usize;
                    assert_eq!(fast.is_miss_at(p, &mut hint), want, "case {case}: point {p:?}");
                    (checked, misses) = (checked + 1, misses + usize::from(want));
                }
            }
        }
        assert_eq!(checked, 40 * 400 * 9);
        assert!(misses * 10 > checked, "{misses} misses of {checked}: the cases must exercise the misses");
    }
}
