//! Exact EDT with a different spacing along each axis (anisotropic voxels).
//!
//! The squared distance between voxels `a` and `b` is
//! `Σ_k w_k² (a_k - b_k)²` for per-axis spacings `w`. The separable scans
//! are those of the isotropic transform with every parabola scaled by the
//! axis's `w²`: the first scan finds each voxel's nearest obstacle in its
//! row, the lower envelope of `w² (x - i)² + f[i]` does the other axes.
//!
//! Integer spacings give exact integer results (`u64`); any other spacing
//! is computed in `f64`, where a near tie between two obstacles may resolve
//! either way within rounding. The isotropic transform ([`super::edt_with`])
//! is a separate code path, so this one costs it nothing.

use edtmap_core::{CoreError, Grid3, NO_SITE};
use rayon::prelude::*;

use super::shared::SharedBuf;
use crate::CpuError;

/// Lines gathered into one tile by the strided scans.
const LANES: usize = 16;

/// Rows of the first scan handed to one task, in voxels at least.
const MIN_VOXELS_PER_TASK: usize = 1 << 14;

/// Largest weighted squared diagonal of an integer transform: every sum the
/// envelope forms stays below `2^63`.
const MAX_INT_DIAG_SQ: u128 = 1 << 61;

/// Squared distances in one of the two arithmetics.
pub(crate) trait Cost: Copy + PartialOrd + Send + Sync {
    /// The value of a voxel with no obstacle in reach.
    const INF: Self;
    /// `w2 · d²`.
    fn scaled_sq(w2: Self, d: i64) -> Self;
    /// `self + other`.
    fn plus(self, other: Self) -> Self;
    /// First integer `x` from which the parabola `w2 (x - q)² + fq` is
    /// strictly below `w2 (x - p)² + fp`, for `p < q`.
    fn first_lower(w2: Self, p: i64, fp: Self, q: i64, fq: Self) -> i64;
}

impl Cost for u64 {
    const INF: Self = u64::MAX;
    #[inline]
    fn scaled_sq(w2: Self, d: i64) -> Self {
        w2 * (d * d) as u64
    }
    #[inline]
    fn plus(self, other: Self) -> Self {
        self + other
    }
    #[inline]
    fn first_lower(w2: Self, p: i64, fp: Self, q: i64, fq: Self) -> i64 {
        let (w2, p, q) = (i128::from(w2), i128::from(p), i128::from(q));
        let num = (i128::from(fq) + w2 * q * q) - (i128::from(fp) + w2 * p * p);
        let start = 1 + num.div_euclid(2 * w2 * (q - p));
        start.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64
    }
}

impl Cost for f64 {
    const INF: Self = f64::INFINITY;
    #[inline]
    fn scaled_sq(w2: Self, d: i64) -> Self {
        w2 * (d * d) as f64
    }
    #[inline]
    fn plus(self, other: Self) -> Self {
        self + other
    }
    #[inline]
    fn first_lower(w2: Self, p: i64, fp: Self, q: i64, fq: Self) -> i64 {
        let (pf, qf) = (p as f64, q as f64);
        let s = ((fq + w2 * qf * qf) - (fp + w2 * pf * pf)) / (2.0 * w2 * (qf - pf));
        // `as` saturates, and a NaN (never produced by finite inputs) maps
        // to 0, which the caller's monotonic guard corrects.
        s.floor() as i64 + 1
    }
}

/// Exact weighted EDT with integer spacings `weights` (`[wx, wy, wz]`, each
/// at least 1) of `voxels` (one per voxel, `x` fastest, `dims = [nx, ny,
/// nz]`): per voxel the squared distance `Σ w_k² d_k²` to the nearest
/// obstacle (`u64::MAX` with no obstacle) and that obstacle's linear index
/// ([`NO_SITE`] with none).
///
/// Fails if `dims` is empty or too large for 32-bit indices, if a weight is
/// 0, or if the weighted squared diagonal exceeds `2^61`.
///
/// ```
/// use edtmap_cpu::edt::edt_weighted_int;
///
/// // One obstacle at x = 0 of a 3 x 2 image whose voxels are 2 wide, 1 tall.
/// let grid = [true, false, false, false, false, false];
/// let (dist_sq, nearest) = edt_weighted_int(&grid, [3, 2, 1], |&o| o, [2, 1, 1]).unwrap();
/// assert_eq!(dist_sq, [0, 4, 16, 1, 5, 17]);
/// assert!(nearest.iter().all(|&n| n == 0));
/// ```
pub fn edt_weighted_int<T: Sync>(
    voxels: &[T],
    dims: [usize; 3],
    is_obstacle: impl Fn(&T) -> bool + Sync,
    weights: [u32; 3],
) -> Result<(Vec<u64>, Vec<u32>), CpuError> {
    check(voxels, dims)?;
    if let Some(axis) = weights.iter().position(|&w| w == 0) {
        return Err(CpuError::Unsupported(format!("weight of axis {axis} is 0")));
    }
    let diag: u128 = (0..3).map(|k| u128::from(weights[k]).pow(2) * (dims[k] as u128 - 1).pow(2)).sum();
    if diag >= MAX_INT_DIAG_SQ {
        return Err(CoreError::TooLarge { dims, reason: "weighted squared diagonal over 2^61" }.into());
    }
    let w2 = weights.map(|w| u64::from(w) * u64::from(w));
    Ok(run(voxels, dims, &is_obstacle, w2))
}

/// Weighted EDT with real spacings `weights` (each finite and positive),
/// computed in `f64`: as [`edt_weighted_int`], with `f64::INFINITY` for
/// voxels without an obstacle. Distances are exact up to `f64` rounding; of
/// two obstacles whose distances differ by rounding only, either may be
/// reported.
pub fn edt_weighted_real<T: Sync>(
    voxels: &[T],
    dims: [usize; 3],
    is_obstacle: impl Fn(&T) -> bool + Sync,
    weights: [f64; 3],
) -> Result<(Vec<f64>, Vec<u32>), CpuError> {
    check(voxels, dims)?;
    if let Some(axis) = weights.iter().position(|&w| !(w.is_finite() && w > 0.0)) {
        return Err(CpuError::Unsupported(format!(
            "weight of axis {axis} is {}: spacings must be finite and positive",
            weights[axis]
        )));
    }
    let w2 = weights.map(|w| w * w);
    if w2.iter().any(|&w| !w.is_normal()) {
        return Err(CpuError::Unsupported(format!("spacings {weights:?} overflow when squared")));
    }
    Ok(run(voxels, dims, &is_obstacle, w2))
}

/// Checks the grid's size against the input and the 32-bit indices.
fn check<T>(voxels: &[T], dims: [usize; 3]) -> Result<(), CpuError> {
    let expected = Grid3::<()>::voxel_count(dims)?;
    if expected >= NO_SITE as usize {
        return Err(CoreError::TooLarge { dims, reason: "more than 2^32 - 2 voxels" }.into());
    }
    if voxels.len() != expected {
        return Err(CoreError::LengthMismatch { dims, expected, actual: voxels.len() }.into());
    }
    Ok(())
}

/// The three scans; axes of length 1 are skipped.
fn run<T: Sync, D: Cost>(
    voxels: &[T],
    dims: [usize; 3],
    is_obstacle: &(impl Fn(&T) -> bool + Sync),
    w2: [D; 3],
) -> (Vec<D>, Vec<u32>) {
    let [nx, ny, nz] = dims;
    let count = nx * ny * nz;
    let mut dist = vec![D::INF; count];
    let mut near = vec![NO_SITE; count];
    let rows = (MIN_VOXELS_PER_TASK / nx).max(1) * nx;
    dist.par_chunks_mut(rows).zip(near.par_chunks_mut(rows)).zip(voxels.par_chunks(rows)).enumerate().for_each(
        |(task, ((dist, near), voxels))| {
            let base = task * rows;
            let rows = dist.chunks_mut(nx).zip(near.chunks_mut(nx)).zip(voxels.chunks(nx));
            for (r, ((dist, near), row)) in rows.enumerate() {
                sweep_row(row, is_obstacle, base + r * nx, w2[0], dist, near);
            }
        },
    );
    if ny > 1 {
        let lines = Lines { outer: nz, outer_stride: nx * ny, len: ny, stride: nx, nx };
        scan_axis(&lines, w2[1], &mut dist, &mut near);
    }
    if nz > 1 {
        let lines = Lines { outer: ny, outer_stride: nx, len: nz, stride: nx * ny, nx };
        scan_axis(&lines, w2[2], &mut dist, &mut near);
    }
    (dist, near)
}

/// First scan of one row whose first voxel has linear index `base`.
fn sweep_row<T, D: Cost>(
    row: &[T],
    is_obstacle: &impl Fn(&T) -> bool,
    base: usize,
    w2: D,
    dist: &mut [D],
    near: &mut [u32],
) {
    let mut last = None;
    for (x, slot) in near.iter_mut().enumerate() {
        if is_obstacle(&row[x]) {
            last = Some(x);
        }
        *slot = last.map_or(NO_SITE, |x| x as u32);
    }
    let mut next = None;
    for x in (0..row.len()).rev() {
        let before = (near[x] != NO_SITE).then_some(near[x] as usize);
        if before == Some(x) {
            next = Some(x);
        }
        let site = match (before, next) {
            (Some(b), Some(n)) => Some(if x - b <= n - x { b } else { n }),
            (b, n) => b.or(n),
        };
        match site {
            Some(s) => {
                dist[x] = D::scaled_sq(w2, x as i64 - s as i64);
                near[x] = (base + s) as u32;
            }
            None => {
                dist[x] = D::INF;
                near[x] = NO_SITE;
            }
        }
    }
}

/// Parallel lines along one strided axis: line `(o, x)` starts at
/// `o * outer_stride + x` (`o < outer`, `x < nx`), its `len` elements
/// `stride` apart.
struct Lines {
    outer: usize,
    outer_stride: usize,
    len: usize,
    stride: usize,
    nx: usize,
}

/// One tile's buffers, element-major (element `i` of lane `w` at
/// `i * LANES + w`), and the envelope's stack.
struct Scratch<D> {
    f: Vec<D>,
    site: Vec<u32>,
    out_f: Vec<D>,
    out_site: Vec<u32>,
    stack: Vec<Parabola<D>>,
}

impl<D> Default for Scratch<D> {
    fn default() -> Self {
        Scratch { f: Vec::new(), site: Vec::new(), out_f: Vec::new(), out_site: Vec::new(), stack: Vec::new() }
    }
}

/// The envelope scan of every line of `lines`, `LANES` neighbouring lines
/// per task gathered into a contiguous tile.
fn scan_axis<D: Cost>(lines: &Lines, w2: D, dist: &mut [D], near: &mut [u32]) {
    let tiles_per_outer = lines.nx.div_ceil(LANES);
    let (dist, near) = (SharedBuf::new(dist), SharedBuf::new(near));
    (0..lines.outer * tiles_per_outer).into_par_iter().for_each_init(Scratch::default, |s, tile| {
        let (outer, x0) = (tile / tiles_per_outer, (tile % tiles_per_outer) * LANES);
        let start = outer * lines.outer_stride + x0;
        let width = LANES.min(lines.nx - x0);
        // SAFETY: tiles differ in their plane or row (`outer`) or in their
        // x range, so no two tasks touch the same voxel; every index is
        // inside the grid.
        unsafe { scan_tile(lines, start, width, w2, dist, near, s) }
    });
}

/// Gathers a tile of `width` lines starting at voxel `start`, runs the
/// envelope on each, scatters the results back.
///
/// # Safety
/// The tile's voxels are in bounds and accessed by no other task.
unsafe fn scan_tile<D: Cost>(
    lines: &Lines,
    start: usize,
    width: usize,
    w2: D,
    dist: SharedBuf<D>,
    near: SharedBuf<u32>,
    s: &mut Scratch<D>,
) {
    let len = lines.len;
    s.f.resize(LANES * len, D::INF);
    s.out_f.resize(LANES * len, D::INF);
    s.site.resize(LANES * len, NO_SITE);
    s.out_site.resize(LANES * len, NO_SITE);
    for i in 0..len {
        let row = start + i * lines.stride;
        for w in 0..width {
            // SAFETY: the caller owns the tile.
            unsafe {
                s.f[i * LANES + w] = dist.read(row + w);
                s.site[i * LANES + w] = near.read(row + w);
            }
        }
    }
    for w in 0..width {
        envelope(&s.f[w..], &s.site[w..], len, w2, &mut s.out_f[w..], &mut s.out_site[w..], &mut s.stack);
    }
    for i in 0..len {
        let row = start + i * lines.stride;
        for w in 0..width {
            // SAFETY: the caller owns the tile.
            unsafe {
                dist.write(row + w, s.out_f[i * LANES + w]);
                near.write(row + w, s.out_site[i * LANES + w]);
            }
        }
    }
}

/// A parabola `w2 (x - pos)² + f` of the lower envelope, lowest from the
/// integer `start` on, with its value there.
#[derive(Clone, Copy)]
struct Parabola<D> {
    pos: i64,
    f: D,
    start: i64,
    at_start: D,
}

/// `min_i w2 (x - i)² + f[i]` and the minimiser's site for every `x < n`
/// of one lane (element `i` at `i * LANES`); ties keep the leftmost.
fn envelope<D: Cost>(
    f: &[D],
    site: &[u32],
    n: usize,
    w2: D,
    out_f: &mut [D],
    out_site: &mut [u32],
    stack: &mut Vec<Parabola<D>>,
) {
    stack.clear();
    let end = n as i64;
    for q in 0..n {
        let fq = f[q * LANES];
        if fq == D::INF {
            continue;
        }
        let q = q as i64;
        while let Some(top) = stack.last() {
            if top.at_start > D::scaled_sq(w2, top.start - q).plus(fq) {
                stack.pop();
            } else {
                break;
            }
        }
        let start = match stack.last() {
            None => 0,
            // The guard keeps the starts increasing where f64 rounding
            // would place an intersection before the top's start.
            Some(top) => D::first_lower(w2, top.pos, top.f, q, fq).max(top.start + 1),
        };
        if start < end {
            stack.push(Parabola { pos: q, f: fq, start, at_start: D::scaled_sq(w2, start - q).plus(fq) });
        }
    }
    if stack.is_empty() {
        for x in 0..n {
            out_f[x * LANES] = D::INF;
            out_site[x * LANES] = NO_SITE;
        }
        return;
    }
    let mut j = 0;
    for x in 0..n {
        let x = x as i64;
        while j + 1 < stack.len() && stack[j + 1].start <= x {
            j += 1;
        }
        let p = stack[j];
        out_f[x as usize * LANES] = D::scaled_sq(w2, x - p.pos).plus(p.f);
        out_site[x as usize * LANES] = site[p.pos as usize * LANES];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_lower_matches_definition() {
        for w2 in [1u64, 4, 9] {
            for (p, fp, q, fq) in [(0i64, 0u64, 3i64, 0u64), (1, 5, 2, 0), (0, 0, 1, 40), (2, 7, 5, 1)] {
                let start = u64::first_lower(w2, p, fp, q, fq);
                let below = |x: i64| u64::scaled_sq(w2, x - q) + fq < u64::scaled_sq(w2, x - p) + fp;
                assert!(below(start), "{w2} {p} {q}");
                assert!(!below(start - 1), "{w2} {p} {q}");
            }
        }
    }
}
