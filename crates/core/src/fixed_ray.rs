//! Exact ray walks in fixed point, shared by every backend.
//!
//! Ray casting must give the same observations on the CPU and on a GPU, and
//! floating-point DDAs do not: at a near-tie between two axes the order of
//! two face crossings, and so the voxels visited, depends on rounding. The
//! walk is therefore split in two:
//!
//! * [`setup_ray`], on the host in `f64`: clip the segment to the volume
//!   (slab method), quantize its ends to `1/q` voxel ([`fixed_scale`]) and
//!   find the return's voxel. Its output, a [`FixedRay`], is plain data that
//!   any backend receives unchanged.
//! * [`walk`]: an Amanatides–Woo traversal of the quantized segment in
//!   exact `u32` arithmetic (no floats, no 64-bit integers, no wrapping), so
//!   that a WGSL shader can copy it line by line and visit the same voxels in
//!   the same order.
//!
//! [`prepare_rays`] runs [`setup_ray`] for a whole frame, from the sensor's
//! rays and pose; every backend's [`crate::Backend::cast_rays`] then walks
//! its output.

use crate::sensor::SensorRay;
use crate::{CoreError, LocalVolume, Observations, OBS_HIT, OBS_MISS};
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;

/// [`FixedRay::flags`] bit: the segment meets the volume and is walked.
pub const RAY_WALK: u32 = 1;
/// [`FixedRay::flags`] bit: the walk leaves out its last voxel (a return
/// whose free segment ends inside the volume).
pub const RAY_SKIP_LAST: u32 = 2;
/// [`FixedRay::hit`] when the ray marks no hit.
pub const NO_HIT: u32 = u32::MAX;

/// Largest fixed-point coordinate: every product of the walk fits in `u32`.
const MAX_FIXED: u64 = 65535;
/// Largest scale [`fixed_scale`] returns.
const MAX_SCALE: u32 = 1 << 16;

/// One ray of a frame, ready to walk: eight `u32`s (start x y z, end x y z,
/// flags, hit), to match a WGSL struct of eight `u32` scalars (a
/// `vec3<u32>` member would be padded to 16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FixedRay {
    /// Start of the segment clipped to the volume, in `1/q` voxel from the
    /// volume's lowest corner (`0 ..= dims[k] * q`).
    pub start: [u32; 3],
    /// End of the clipped segment, same units.
    pub end: [u32; 3],
    /// [`RAY_WALK`] and [`RAY_SKIP_LAST`].
    pub flags: u32,
    /// Linear index `x + nx (y + ny z)` of the voxel to mark as a hit, or
    /// [`NO_HIT`].
    pub hit: u32,
}

impl FixedRay {
    /// A ray that visits nothing and marks no hit.
    pub const EMPTY: FixedRay = FixedRay { start: [0; 3], end: [0; 3], flags: 0, hit: NO_HIT };
}

impl Default for FixedRay {
    /// [`FixedRay::EMPTY`]: all zeros but the hit, which must be [`NO_HIT`]
    /// (a zero would mark voxel 0).
    fn default() -> Self {
        FixedRay::EMPTY
    }
}

/// The fixed-point scale `q` (units per voxel) of a volume of `dims`: the
/// largest power of two, at most 2¹⁶, with `(max(dims) + 1) q <= 65535`.
/// Fails on an empty axis, an axis of more than 65534 voxels, or more than
/// `u32::MAX` voxels (linear indices are `u32`, and `u32::MAX` is
/// [`NO_HIT`]).
pub fn fixed_scale(dims: [usize; 3]) -> Result<u32, CoreError> {
    let count = crate::Grid3::<()>::voxel_count(dims)?;
    if count > u32::MAX as usize {
        return Err(CoreError::TooLarge { dims, reason: "more than 2^32 - 1 voxels for a ray walk" });
    }
    let cells = dims.iter().max().map_or(0, |&n| n as u64) + 1;
    if cells > MAX_FIXED {
        return Err(CoreError::TooLarge { dims, reason: "more than 65534 voxels along an axis for a ray walk" });
    }
    let mut q = MAX_SCALE;
    while cells * u64::from(q) > MAX_FIXED {
        q /= 2;
    }
    Ok(q)
}

/// Prepares the walk of a ray: `origin → free_end` is the segment to walk
/// (misses), `end` the return (a hit when `is_return`), all in voxel units
/// from the volume's lowest corner; `q` comes from [`fixed_scale`]`(dims)`.
///
/// The segment is clipped to the box `[0, dims]` (slab method) and its ends
/// quantized as `round(p q)`, clamped to `0 ..= dims[k] q`. [`RAY_WALK`] is
/// set when the segment meets the box, [`RAY_SKIP_LAST`] when `is_return` and
/// the segment's end was not clipped (the ray leaves that voxel beyond
/// `free_end`). The hit is `floor(end)`'s voxel when `is_return` and it lies
/// inside. Any non-finite input gives [`FixedRay::EMPTY`].
pub fn setup_ray(
    origin: [f64; 3],
    free_end: [f64; 3],
    end: [f64; 3],
    is_return: bool,
    dims: [usize; 3],
    q: u32,
) -> FixedRay {
    if !origin.iter().chain(&free_end).chain(&end).all(|v| v.is_finite()) {
        return FixedRay::EMPTY;
    }
    let hit = if is_return { cell_of(end, dims).unwrap_or(NO_HIT) } else { NO_HIT };
    let Some((t0, t1)) = clip_segment(origin, free_end, dims) else { return FixedRay { hit, ..FixedRay::EMPTY } };
    let quantize = |t: f64| {
        [0, 1, 2].map(|k| {
            let p = origin[k] + t * (free_end[k] - origin[k]);
            round_clamped(p * f64::from(q), dims[k] as u64 * u64::from(q)) as u32
        })
    };
    let skip = if is_return && t1 >= 1.0 { RAY_SKIP_LAST } else { 0 };
    FixedRay { start: quantize(t0), end: quantize(t1), flags: RAY_WALK | skip, hit }
}

/// The parameter interval `[t0, t1] ⊆ [0, 1]` of the segment `a → b`
/// inside the closed box `[0, dims]`, if they meet (slab method); `None` for
/// non-finite input.
pub fn clip_segment(a: [f64; 3], b: [f64; 3], dims: [usize; 3]) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        let d = b[k] - a[k];
        let hi = dims[k] as f64;
        if !(a[k].is_finite() && d.is_finite()) {
            return None;
        }
        if d == 0.0 {
            if a[k] < 0.0 || a[k] > hi {
                return None;
            }
            continue;
        }
        let (lo_t, hi_t) = ((0.0 - a[k]) / d, (hi - a[k]) / d);
        t0 = t0.max(lo_t.min(hi_t));
        t1 = t1.min(lo_t.max(hi_t));
    }
    (t0 <= t1).then_some((t0, t1))
}

/// `round(x)` (halves away from zero) clamped to `0..=max`, for `x` not
/// NaN, without libm's `round` (a call per coordinate, six per ray, a
/// fifth of the preparation in a profile of velodyne-pair): below `max`
/// the truncation of a positive `x` is its floor, and `x` less its floor
/// is exact.
fn round_clamped(x: f64, max: u64) -> u64 {
    if x <= 0.0 {
        return 0;
    }
    if x >= max as f64 {
        return max;
    }
    let t = x as u64;
    (t + u64::from(x - t as f64 >= 0.5)).min(max)
}

/// Linear index of the voxel holding `p` (voxel units), if inside.
fn cell_of(p: [f64; 3], dims: [usize; 3]) -> Option<u32> {
    let mut linear = 0u64;
    for k in (0..3).rev() {
        // `floor(p)` is in `0..n` exactly when `p` is in `[0, n)` (false for
        // NaN), and there it is the truncation: no call to libm's `floor`.
        if !(p[k] >= 0.0 && p[k] < dims[k] as f64) {
            return None;
        }
        linear = linear * dims[k] as u64 + p[k] as u64;
    }
    u32::try_from(linear).ok().filter(|&i| i != NO_HIT)
}

/// Calls `visit(linear)` for the voxels of the volume `dims` that the
/// prepared segment of `ray` passes through, in order from its start; `q`
/// must be [`fixed_scale`]`(dims)` (or a smaller scale the ray was set up
/// with). Nothing is visited unless [`RAY_WALK`] is set, or when `q` does
/// not fit `dims`. The hit is not visited: it is the caller's.
///
/// The rules, in `u32` arithmetic only (every value stays in `0 ..= 65535`
/// and every product below `2³²`), per axis `k` with `n = dims[k]`:
///
/// 1. `s = min(start[k], n q)`, `e = min(end[k], n q)`; the first cell is
///    `min(s / q, n - 1)`, the last `min(e / q, n - 1)`; the axis makes
///    `left = |last - first|` steps.
/// 2. Direction: up if `e > s`, down if `e < s`. `len = |e - s|` and `num`,
///    the distance to the next cell face: up `(first + 1) q - s`, down
///    `s - first q`. An axis with `left = 0` gets `len = 0`, `num = q`.
///    (`num / len` is the segment parameter of the next face crossing;
///    `len = 0` means never, as `num > 0`.)
/// 3. The walk makes `left_x + left_y + left_z` steps. Before each it visits
///    the current cell, then picks the axis of the next crossing by exact
///    cross-multiplication, `a` before `b` when `num_a len_b <= num_b len_a`:
///    x if `x <= y` and `x <= z`, else y if `y <= z`, else z (ties go to x,
///    then y). It steps that axis's cell by one in its direction, adds `q`
///    to its `num`, decrements its `left`, and sets its `len` to 0 once
///    `left` reaches 0.
/// 4. After the steps, the walk is in the last cell; it is visited unless
///    [`RAY_SKIP_LAST`] is set.
///
/// Rule 3's last clause retires an axis once it has reached its last cell.
/// Its only other crossings lie at or beyond the end (segment parameter
/// `>= 1`), so this changes nothing but ties at the very end, where a face
/// crossed exactly at the end must not be stepped through: the walk always
/// ends in the last cell and never leaves the volume.
///
/// Every visited voxel meets the closed segment, every voxel whose interior
/// the segment crosses is visited, each once, and consecutive voxels share a
/// face.
pub fn walk(ray: &FixedRay, dims: [usize; 3], q: u32, mut visit: impl FnMut(u32)) {
    walk_cells(ray, dims, q, |_, linear| visit(linear));
}

/// [`walk`], also passing each voxel's coordinates: `visit(cell, linear)`.
pub fn walk_cells(ray: &FixedRay, dims: [usize; 3], q: u32, mut visit: impl FnMut([u32; 3], u32)) {
    if ray.flags & RAY_WALK == 0 || !scale_fits(dims, q) {
        return;
    }
    let n = dims.map(|d| d as u32);
    let axis = |k: usize| Axis::new(ray.start[k], ray.end[k], n[k], q);
    let (mut x, mut y, mut z) = (axis(0), axis(1), axis(2));
    let (stride_y, stride_z) = (n[0], n[0] * n[1]);
    let mut linear = x.cell + stride_y * y.cell + stride_z * z.cell;
    for _ in 0..x.left + y.left + z.left {
        visit([x.cell, y.cell, z.cell], linear);
        if x.num * y.len <= y.num * x.len && x.num * z.len <= z.num * x.len {
            linear = x.step(linear, 1, q);
        } else if y.num * z.len <= z.num * y.len {
            linear = y.step(linear, stride_y, q);
        } else {
            linear = z.step(linear, stride_z, q);
        }
    }
    if ray.flags & RAY_SKIP_LAST == 0 {
        visit([x.cell, y.cell, z.cell], linear);
    }
}

/// Whether `q` keeps every value of a walk in `dims` within `0 ..= 65535`,
/// and linear indices in `u32`.
fn scale_fits(dims: [usize; 3], q: u32) -> bool {
    let max = dims.iter().max().map_or(0, |&n| n as u64);
    let count = dims.iter().try_fold(1u64, |acc, &n| acc.checked_mul(n as u64));
    q >= 1
        && dims.iter().all(|&n| n >= 1)
        && (max + 1) * u64::from(q) <= MAX_FIXED
        && count.is_some_and(|c| c <= u64::from(u32::MAX))
}

/// One axis of a walk (rules 1–2 of [`walk`]).
#[derive(Debug, Clone, Copy)]
struct Axis {
    cell: u32,
    left: u32,
    up: bool,
    num: u32,
    len: u32,
}

impl Axis {
    #[inline(always)]
    fn new(start: u32, end: u32, n: u32, q: u32) -> Axis {
        let (s, e) = (start.min(n * q), end.min(n * q));
        let (first, last) = ((s / q).min(n - 1), (e / q).min(n - 1));
        let left = first.abs_diff(last);
        let up = e > s;
        if left == 0 {
            return Axis { cell: first, left, up, num: q, len: 0 };
        }
        let (num, len) = if up { ((first + 1) * q - s, e - s) } else { (s - first * q, s - e) };
        Axis { cell: first, left, up, num, len }
    }

    /// Steps to the next cell (rule 3); returns the new linear index.
    #[inline(always)]
    fn step(&mut self, linear: u32, stride: u32, q: u32) -> u32 {
        self.num += q;
        self.left -= 1;
        if self.left == 0 {
            self.len = 0;
        }
        if self.up {
            self.cell += 1;
            linear + stride
        } else {
            self.cell -= 1;
            linear - stride
        }
    }
}

/// Rays per rayon task: enough to amortise scheduling, small enough to
/// balance rays of very different lengths.
pub const RAYS_PER_TASK: usize = 256;

/// Sets up every ray (sensor frame) from the pose for a walk through
/// `obs_volume`, into `out` (one per ray, in order), and returns the
/// fixed-point scale `q` they use.
///
/// A voxel is a miss only if the ray leaves it more than `free_margin_m`
/// (metres) before the return: the surface is located to a voxel, so a
/// voxel the ray crosses just before it may hold part of the surface. The
/// return's own voxel is the hit.
pub fn prepare_rays(
    obs_volume: &LocalVolume,
    t_world_sensor: &Isometry3<f64>,
    rays: &[SensorRay],
    free_margin_m: f32,
    out: &mut Vec<FixedRay>,
) -> Result<u32, CoreError> {
    let (dims, inv) = (obs_volume.dims, 1.0 / obs_volume.voxel_size_m);
    let q = fixed_scale(dims)?;
    let corner = Vector3::from(obs_volume.min_corner_m());
    let origin = (t_world_sensor.translation.vector - corner) * inv;
    let rot = t_world_sensor.rotation.to_rotation_matrix();
    rays.par_iter()
        .with_min_len(RAYS_PER_TASK)
        .map(|ray| {
            let dir = rot * Vector3::new(ray.dir[0] as f64, ray.dir[1] as f64, ray.dir[2] as f64) * inv;
            let end = origin + dir * ray.range_m as f64;
            // Voxels the ray leaves before `free_end` are misses: walk to it
            // and, for a return, leave out its own voxel, which the ray
            // leaves beyond it.
            let margin = if ray.hit { free_margin_m.min(ray.range_m) as f64 } else { 0.0 };
            let free_end = origin + dir * (ray.range_m as f64 - margin);
            setup_ray(origin.into(), free_end.into(), end.into(), ray.hit, dims, q)
        })
        .collect_into_vec(out);
    Ok(q)
}

/// Walks rays prepared for `obs`'s volume at scale `q` ([`prepare_rays`])
/// on the host's cores: the voxels they pass through become misses, their
/// hits hits. The CPU backend's ray casting, and the reference a device
/// falls back on where its kernel does not apply.
pub fn cast_fixed(obs: &Observations, rays: &[FixedRay], q: u32) {
    let dims = obs.volume().dims;
    rays.par_chunks(RAYS_PER_TASK).for_each(|chunk| {
        for ray in chunk {
            walk_cells(ray, dims, q, |c, i| obs.mark(c.map(|v| v as usize), i as usize, OBS_MISS));
            if ray.hit != NO_HIT && (ray.hit as usize) < obs.volume().len() {
                let i = ray.hit as usize;
                let c = [i % dims[0], (i / dims[0]) % dims[1], i / (dims[0] * dims[1])];
                obs.mark(c, i, OBS_HIT);
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::RngSeed;
    use std::cmp::Ordering;

    /// A rational `num / den` with `den > 0`.
    #[derive(Debug, Clone, Copy)]
    struct Frac(i128, i128);

    impl Frac {
        fn new(num: i128, den: i128) -> Frac {
            if den < 0 {
                Frac(-num, -den)
            } else {
                Frac(num, den)
            }
        }
        fn cmp(self, o: Frac) -> Ordering {
            (self.0 * o.1).cmp(&(o.0 * self.1))
        }
    }

    /// Whether the closed segment `s → e` (fixed point) meets cell `c`:
    /// the closed cell, or when `open` its interior.
    fn meets(s: [u32; 3], e: [u32; 3], c: [u32; 3], q: u32, open: bool) -> bool {
        let (q, inf) = (i128::from(q), Frac(1, 0));
        let (mut lo, mut hi) = (Frac(-1, 0), inf);
        for k in 0..3 {
            let (s, d) = (i128::from(s[k]), i128::from(e[k]) - i128::from(s[k]));
            let (min, max) = (i128::from(c[k]) * q, i128::from(c[k] + 1) * q);
            if d == 0 {
                let inside = if open { min < s && s < max } else { min <= s && s <= max };
                if !inside {
                    return false;
                }
                continue;
            }
            let (a, b) = (Frac::new(min - s, d), Frac::new(max - s, d));
            let (a, b) = if a.cmp(b) == Ordering::Greater { (b, a) } else { (a, b) };
            if a.cmp(lo) == Ordering::Greater {
                lo = a
            }
            if b.cmp(hi) == Ordering::Less {
                hi = b
            }
        }
        let (zero, one) = (Frac(0, 1), Frac(1, 1));
        if open {
            // t in (lo, hi) ∩ [0, 1]. Infinite bounds compare correctly
            // with finite ones (den 0, numerator ±1), but not with each other.
            let finite = lo.1 != 0 && hi.1 != 0;
            (!finite || lo.cmp(hi) == Ordering::Less)
                && lo.cmp(one) == Ordering::Less
                && hi.cmp(zero) == Ordering::Greater
        } else {
            let lo = if lo.cmp(zero) == Ordering::Less { zero } else { lo };
            let hi = if hi.cmp(one) == Ordering::Greater { one } else { hi };
            lo.cmp(hi) != Ordering::Greater
        }
    }

    fn walked(ray: &FixedRay, dims: [usize; 3], q: u32) -> Vec<[u32; 3]> {
        let mut seen = Vec::new();
        walk_cells(ray, dims, q, |c, i| {
            assert_eq!(i as usize, c[0] as usize + dims[0] * (c[1] as usize + dims[1] * c[2] as usize));
            seen.push(c);
        });
        let mut linear = Vec::new();
        walk(ray, dims, q, |i| linear.push(i));
        assert_eq!(linear.len(), seen.len());
        seen
    }

    /// The walk against the brute-force oracle.
    fn check(s: [u32; 3], e: [u32; 3], dims: [usize; 3], q: u32) -> Result<(), TestCaseError> {
        let ray = FixedRay { start: s, end: e, flags: RAY_WALK, hit: NO_HIT };
        let seen = walked(&ray, dims, q);
        let n = dims.map(|d| d as u32);
        let last = [0, 1, 2].map(|k| (e[k] / q).min(n[k] - 1));
        let steps: u32 = (0..3).map(|k| (s[k] / q).min(n[k] - 1).abs_diff(last[k])).sum();
        prop_assert_eq!(seen.len() as u32, steps + 1);
        prop_assert_eq!(seen.last(), Some(&last));
        for w in seen.windows(2) {
            let d: u32 = (0..3).map(|k| w[0][k].abs_diff(w[1][k])).sum();
            prop_assert_eq!(d, 1, "{:?} are not face neighbours", w);
        }
        let mut sorted = seen.clone();
        sorted.sort_unstable();
        sorted.dedup();
        prop_assert_eq!(sorted.len(), seen.len(), "a cell was visited twice");
        for z in 0..n[2] {
            for y in 0..n[1] {
                for x in 0..n[0] {
                    let c = [x, y, z];
                    let visited = sorted.binary_search(&c).is_ok();
                    prop_assert!(!visited || meets(s, e, c, q, false), "{:?} off the segment was visited", c);
                    prop_assert!(visited || !meets(s, e, c, q, true), "{:?} crossed by the segment was missed", c);
                }
            }
        }
        let skipped = walked(&FixedRay { flags: RAY_WALK | RAY_SKIP_LAST, ..ray }, dims, q);
        prop_assert_eq!(&skipped[..], &seen[..seen.len() - 1]);
        Ok(())
    }

    /// A coordinate on axis `n` at scale `q`: on a cell face when `snap`
    /// (the degenerate cases), anywhere otherwise.
    fn coord(raw: u32, snap: bool, n: usize, q: u32) -> u32 {
        if snap {
            raw % (n as u32 + 1) * q
        } else {
            raw % (n as u32 * q + 1)
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 3000, rng_seed: RngSeed::Fixed(0xED7_3A9), ..ProptestConfig::default() })]

        #[test]
        fn walk_visits_exactly_the_crossed_cells(
            dims in [1usize..9, 1usize..9, 1usize..7],
            q_log in 0u32..15,
            raw in prop::array::uniform6(any::<u32>()),
            snap in prop::array::uniform6(any::<bool>()),
        ) {
            let q = (1u32 << q_log).min(fixed_scale(dims).expect("small dims"));
            let p = |i: usize| [0, 1, 2].map(|k| coord(raw[3 * i + k], snap[3 * i + k], dims[k], q));
            check(p(0), p(1), dims, q)?;
        }

        #[test]
        fn walk_along_an_axis(dims in [1usize..9, 1usize..9, 1usize..7], raw in prop::array::uniform4(any::<u32>()), snap in any::<bool>(), axis in 0usize..3) {
            let q = fixed_scale(dims).expect("small dims");
            let s = [0, 1, 2].map(|k| coord(raw[k], snap, dims[k], q));
            let mut e = s;
            e[axis] = coord(raw[3], false, dims[axis], q);
            check(s, e, dims, q)?;
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 5000, rng_seed: RngSeed::Fixed(0x20D_C1A), ..ProptestConfig::default() })]

        /// The quantization and the hit's cell are libm's `round` and
        /// `floor` definitions: near halves and integers, at the box's faces
        /// and far outside it.
        #[test]
        fn rounding_and_cells_are_libms(
            whole in -70i64..70,
            frac in prop_oneof![Just(0.0), Just(0.5), Just(0.49999999999999994), Just(-0.5), Just(1e-12), Just(-1e-12), -1.0f64..1.0],
            scale in prop_oneof![Just(1.0), Just(1e-9), Just(1e9), Just(1e300)],
            dims in [1usize..9, 1usize..9, 1usize..70],
        ) {
            let x = (whole as f64 + frac) * scale;
            for max in [0u64, 1, 8, 64, 1 << 40] {
                let want = (x.round().max(0.0) as u64).min(max);
                prop_assert_eq!(round_clamped(x, max), want, "round {} max {}", x, max);
            }
            let p = [x, x * 0.125 + 3.0, -x + 60.0];
            let floors = p.map(f64::floor);
            let want = (0..3).all(|k| floors[k] >= 0.0 && floors[k] < dims[k] as f64).then(|| {
                floors[0] as u64 + dims[0] as u64 * (floors[1] as u64 + dims[1] as u64 * floors[2] as u64)
            });
            prop_assert_eq!(cell_of(p, dims).map(u64::from), want, "cell of {:?} in {:?}", p, dims);
        }
    }

    #[test]
    fn rounding_edges() {
        for x in [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            -f64::MAX,
            0.0,
            -0.0,
            4503599627370495.5,
            9007199254740993.0,
            18446744073709551615.0,
            1e-320,
        ] {
            for max in [0u64, 1, 1 << 40, u64::MAX >> 12] {
                assert_eq!(round_clamped(x, max), (x.round().max(0.0) as u64).min(max), "{x} {max}");
            }
        }
        assert_eq!(round_clamped(f64::NAN, 5), 0);
        // The hit's cell at the box's faces.
        let dims = [4, 5, 6];
        for (p, want) in [
            ([0.0, 0.0, 0.0], Some(0)),
            ([-0.0, 0.0, 0.0], Some(0)),
            ([3.999, 4.999, 5.999], Some(119)),
            ([4.0, 0.0, 0.0], None),
            ([-1e-300, 0.0, 0.0], None),
            ([0.0, 5.0, 0.0], None),
            ([0.0, 0.0, f64::NAN], None),
            ([1.0, 1.0, 1.0], Some(25)),
        ] {
            assert_eq!(cell_of(p, dims), want, "{p:?}");
        }
    }

    #[test]
    fn ray_is_eight_packed_u32s() {
        assert_eq!((std::mem::size_of::<FixedRay>(), std::mem::align_of::<FixedRay>()), (32, 4));
        assert_eq!(FixedRay::default(), FixedRay::EMPTY);
    }

    #[test]
    fn scale_for_typical_and_extreme_volumes() {
        assert_eq!(fixed_scale([200, 200, 60]), Ok(256));
        assert_eq!(fixed_scale([1, 1, 1]), Ok(1 << 14));
        assert_eq!(fixed_scale([65534, 65534, 1]), Ok(1));
        assert!(matches!(fixed_scale([65535, 1, 1]), Err(CoreError::TooLarge { .. })));
        assert!(matches!(fixed_scale([65534, 65534, 2]), Err(CoreError::TooLarge { .. })));
        assert!(matches!(fixed_scale([4, 0, 4]), Err(CoreError::EmptyAxis { axis: 1, .. })));
    }

    #[test]
    fn largest_volume_walks_without_overflow() {
        // Debug builds check every operation for overflow. The diagonal
        // passes through every cell corner: ties go to x, then y.
        let dims = [65534, 65534, 1];
        let q = fixed_scale(dims).expect("allowed");
        let ray = setup_ray([-1.0, -1.0, 0.5], [70000.0, 70000.0, 0.5], [0.0; 3], false, dims, q);
        let (mut count, mut prev) = (0u32, None);
        walk(&ray, dims, q, |i| {
            assert!(prev.is_none_or(|p| p < i));
            prev = Some(i);
            count += 1;
        });
        assert_eq!(count, 2 * 65533 + 1);
        assert_eq!(prev, Some(u32::try_from(65534u64 * 65534 - 1).expect("fits")));
        let row = FixedRay { start: [65534, 1, 1], end: [0, 0, 0], flags: RAY_WALK, hit: NO_HIT };
        assert_eq!(visits(&row, [65534, 1, 1], 1), (0..65534).rev().collect::<Vec<_>>());
        let small = [3, 4, 5];
        let q = fixed_scale(small).expect("allowed");
        check([3 * q, 4 * q, 5 * q], [0, 0, 0], small, q).expect("diagonal");
        check([3 * q, 0, 5 * q], [0, 4 * q, 0], small, q).expect("diagonal");
    }

    fn visits(ray: &FixedRay, dims: [usize; 3], q: u32) -> Vec<u32> {
        let mut seen = Vec::new();
        walk(ray, dims, q, |i| seen.push(i));
        seen
    }

    /// The oracle accepts either order at a tie; backends must agree on one.
    #[test]
    fn ties_go_to_x_then_y_then_z() {
        let (dims, q) = ([3, 3, 3], 4);
        let ray = |start: [u32; 3], end: [u32; 3]| FixedRay { start, end, flags: RAY_WALK, hit: NO_HIT };
        assert_eq!(visits(&ray([0; 3], [8; 3]), dims, q), vec![0, 1, 4, 13, 14, 17, 26]);
        assert_eq!(visits(&ray([0, 0, 0], [0, 8, 8]), dims, q), vec![0, 3, 12, 15, 24]);
        assert_eq!(visits(&ray([12, 12, 0], [4, 4, 0]), dims, q), vec![8, 7, 4]);
        // Crossing the corner x = y = 4 mid-walk, after one z face.
        assert_eq!(visits(&ray([2, 2, 2], [6, 6, 10]), dims, q), vec![0, 9, 10, 13, 22]);
    }

    #[test]
    fn setup_clips_quantizes_and_flags() {
        let (dims, q) = ([8, 2, 2], 4);
        // Axis aligned, inside: the return's voxel is the hit, and the free
        // segment's own last voxel is left out.
        let ray = setup_ray([0.5, 0.5, 0.5], [3.6, 0.5, 0.5], [4.5, 0.5, 0.5], true, dims, q);
        assert_eq!(ray, FixedRay { start: [2, 2, 2], end: [14, 2, 2], flags: RAY_WALK | RAY_SKIP_LAST, hit: 4 });
        assert_eq!(visits(&ray, dims, q), vec![0, 1, 2]);
        // Clipped at both ends: the whole row, last voxel included.
        let ray = setup_ray([-5.0, 1.5, 1.5], [20.0, 1.5, 1.5], [21.0, 1.5, 1.5], true, dims, q);
        assert_eq!(ray, FixedRay { start: [0, 6, 6], end: [32, 6, 6], flags: RAY_WALK, hit: NO_HIT });
        assert_eq!(visits(&ray, dims, q), (0..8).map(|x| x + 8 * (1 + 2)).collect::<Vec<_>>());
        // No return: nothing left out.
        let ray = setup_ray([0.5, 0.5, 0.5], [2.5, 0.5, 0.5], [2.5, 0.5, 0.5], false, dims, q);
        assert_eq!(visits(&ray, dims, q), vec![0, 1, 2]);
    }

    #[test]
    fn outside_empty_and_non_finite_rays_visit_nothing() {
        let (dims, q) = ([4, 4, 4], 8);
        let outside = setup_ray([-3.0, 0.5, 0.5], [-1.0, 0.5, 0.5], [-0.5, 0.5, 0.5], true, dims, q);
        assert_eq!(outside, FixedRay::EMPTY);
        // The segment misses, the return is inside.
        let hit_only = setup_ray([5.0, 5.0, 5.0], [5.0, 5.0, 4.5], [3.5, 0.5, 0.5], true, dims, q);
        assert_eq!(hit_only, FixedRay { hit: 3, ..FixedRay::EMPTY });
        assert!(visits(&hit_only, dims, q).is_empty());
        for bad in [f64::NAN, f64::INFINITY] {
            assert_eq!(setup_ray([bad, 0.5, 0.5], [1.0, 0.5, 0.5], [1.0; 3], true, dims, q), FixedRay::EMPTY);
            assert_eq!(setup_ray([0.5; 3], [1.0; 3], [1.0, bad, 1.0], true, dims, q), FixedRay::EMPTY);
        }
        // Zero length: its one voxel, or nothing when left out.
        let point = setup_ray([1.5; 3], [1.5; 3], [1.5; 3], false, dims, q);
        assert_eq!(visits(&point, dims, q), vec![1 + 4 * (1 + 4)]);
        let point = setup_ray([1.5; 3], [1.5; 3], [1.5; 3], true, dims, q);
        assert!(visits(&point, dims, q).is_empty());
        assert_eq!(point.hit, 1 + 4 * (1 + 4));
        // A scale that does not fit the volume walks nothing.
        let ray = FixedRay { start: [0; 3], end: [32; 3], flags: RAY_WALK, hit: NO_HIT };
        assert!(visits(&ray, dims, 1 << 14).is_empty());
        assert!(visits(&ray, [4, 0, 4], q).is_empty());
    }
}
