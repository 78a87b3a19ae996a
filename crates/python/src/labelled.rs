//! The distance-only transform: squared distances written straight into the
//! output array, with no nearest-obstacle field beside it, and any number of
//! labels handled in the same three passes.
//!
//! Every voxel that is not background gets its squared distance to the
//! nearest voxel that is not of its label: background, another label, or
//! (with `black_border`) the outside of the grid. That is the exact EDT of
//! each label's mask at once. The first pass measures, along each row, the
//! gap to the nearest voxel of another label. The later passes split each
//! line into runs of one label: the voxels just outside a run are of
//! another label, so they bound its voxels' distances and shadow everything
//! beyond them, and inside the run the lower envelope of the parabolas of
//! the previous pass (Felzenszwalb and Huttenlocher, "Distance Transforms
//! of Sampled Functions", 2012) gives the rest. Runs of one label never
//! need another label's values, so one set of passes serves every label.
//!
//! Arithmetic is in `f64` within a pass; the values stored between passes
//! are of the output's type. With unit or integer weights the squared
//! distances are integers, exact in `f32` below 2^24 and in `f64` below
//! 2^53.

use edtmap_cpu::edt::SharedBuf;
use rayon::prelude::*;

/// Rows of the first pass handed to one task, voxels.
const MIN_VOXELS_PER_TASK: usize = 1 << 14;

/// Neighbouring lines gathered together by the later passes, so that each
/// cache line read from the volume feeds several lines.
const LANES: usize = 32;

/// A stored squared distance: `f32` or `f64`.
pub(crate) trait Value: Copy + Send + Sync {
    fn get(self) -> f64;
    fn put(v: f64) -> Self;
}

impl Value for f32 {
    #[inline]
    fn get(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn put(v: f64) -> Self {
        v as f32
    }
}

impl Value for f64 {
    #[inline]
    fn get(self) -> f64 {
        self
    }
    #[inline]
    fn put(v: f64) -> Self {
        v
    }
}

/// The voxels and how to read them as labels.
pub(crate) struct Labels<'a, T, B, S> {
    /// One per voxel, `x` fastest.
    pub(crate) voxels: &'a [T],
    /// Whether a voxel is background (distance 0).
    pub(crate) background: B,
    /// Whether two neighbouring voxels, neither background, share a label.
    pub(crate) same: S,
}

impl<T, B: Fn(&T) -> bool, S: Fn(&T, &T) -> bool> Labels<'_, T, B, S> {
    /// Whether `b`, next to `a` (not background), ends `a`'s run.
    #[inline]
    fn ends(&self, a: &T, b: &T) -> bool {
        (self.background)(b) || !(self.same)(a, b)
    }
}

/// The grid: `dims = [nx, ny, nz]`, `axes` of them real (a 2D array has no
/// z axis whose outside could count as background), `w` the spacing per
/// axis, `black_border` whether the outside of the grid is background.
#[derive(Clone, Copy)]
pub(crate) struct Grid {
    pub(crate) dims: [usize; 3],
    pub(crate) axes: usize,
    pub(crate) w: [f64; 3],
    pub(crate) black_border: bool,
}

/// Writes every voxel's squared distance into `out` (one per voxel),
/// `f64::INFINITY` where nothing bounds it.
pub(crate) fn squared_distances<T, B, S, V>(labels: &Labels<'_, T, B, S>, grid: Grid, out: &mut [V])
where
    T: Copy + Sync,
    B: Fn(&T) -> bool + Sync,
    S: Fn(&T, &T) -> bool + Sync,
    V: Value,
{
    let [nx, ny, nz] = grid.dims;
    debug_assert_eq!(out.len(), nx * ny * nz);
    debug_assert_eq!(labels.voxels.len(), out.len());
    let chunk = (MIN_VOXELS_PER_TASK / nx).max(1) * nx;
    out.par_chunks_mut(chunk).zip(labels.voxels.par_chunks(chunk)).for_each(|(out, voxels)| {
        for (out, row) in out.chunks_mut(nx).zip(voxels.chunks(nx)) {
            first_pass(labels, row, grid.w[0], grid.black_border, out);
        }
    });
    // A line of one voxel only meets the outside, which counts only with
    // `black_border`.
    if grid.axes >= 2 && (ny > 1 || grid.black_border) {
        let lines = Lines { outer: nz, outer_stride: nx * ny, len: ny, stride: nx, nx };
        later_pass(labels, &lines, grid.w[1] * grid.w[1], grid.black_border, out);
    }
    if grid.axes >= 3 && (nz > 1 || grid.black_border) {
        let lines = Lines { outer: ny, outer_stride: nx, len: nz, stride: nx * ny, nx };
        later_pass(labels, &lines, grid.w[2] * grid.w[2], grid.black_border, out);
    }
}

/// One row: each voxel's squared gap (`w` apart) to the nearest voxel of
/// another label along the row.
fn first_pass<T, B, S, V>(labels: &Labels<'_, T, B, S>, row: &[T], w: f64, border: bool, out: &mut [V])
where
    B: Fn(&T) -> bool,
    S: Fn(&T, &T) -> bool,
    V: Value,
{
    let n = row.len();
    // Position of the last run end seen, as a signed voxel index.
    let mut end: Option<isize> = border.then_some(-1);
    for i in 0..n {
        if (labels.background)(&row[i]) {
            end = Some(i as isize);
            out[i] = V::put(0.0);
            continue;
        }
        if i > 0 && labels.ends(&row[i], &row[i - 1]) {
            end = Some(i as isize - 1);
        }
        // The gap to the left, in voxels, held until the right is known.
        out[i] = V::put(end.map_or(f64::INFINITY, |e| (i as isize - e) as f64));
    }
    let mut end: Option<usize> = border.then_some(n);
    for i in (0..n).rev() {
        if (labels.background)(&row[i]) {
            end = Some(i);
            continue;
        }
        if i + 1 < n && labels.ends(&row[i], &row[i + 1]) {
            end = Some(i + 1);
        }
        let gap = end.map_or(f64::INFINITY, |e| (e - i) as f64).min(out[i].get());
        out[i] = V::put(if gap.is_finite() { (gap * w) * (gap * w) } else { f64::INFINITY });
    }
}

/// A family of parallel lines along one strided axis: line `(o, x)` starts
/// at voxel `o * outer_stride + x` (`o < outer`, `x < nx`), its `len`
/// elements `stride` apart.
struct Lines {
    outer: usize,
    outer_stride: usize,
    len: usize,
    stride: usize,
    nx: usize,
}

/// Per-task buffers: a tile of up to [`LANES`] lines, each contiguous.
struct Scratch<T> {
    f: Vec<f64>,
    labels: Vec<T>,
    out: Vec<f64>,
    envelope: Envelope,
}

/// The lower envelope of one run: the parabolas' sites and where each
/// starts to be the lowest, as the fraction `num / den` (`den > 0`), so
/// that building and reading the envelope compare products instead of
/// dividing.
#[derive(Default)]
struct Envelope {
    sites: Vec<usize>,
    num: Vec<f64>,
    den: Vec<f64>,
}

/// A later pass over every line of `lines`, tiles of neighbouring lines in
/// parallel.
fn later_pass<T, B, S, V>(labels: &Labels<'_, T, B, S>, lines: &Lines, w2: f64, border: bool, out: &mut [V])
where
    T: Copy + Sync,
    B: Fn(&T) -> bool + Sync,
    S: Fn(&T, &T) -> bool + Sync,
    V: Value,
{
    let tiles_per_outer = lines.nx.div_ceil(LANES);
    // The later passes' tiles interleave in memory: each task writes only
    // its own tile's voxels (every index below is in bounds by the tiling).
    let shared = SharedBuf::new(out);
    let scratch = || Scratch { f: Vec::new(), labels: Vec::new(), out: Vec::new(), envelope: Envelope::default() };
    (0..lines.outer * tiles_per_outer).into_par_iter().for_each_init(scratch, |s, tile| {
        let (outer, x0) = (tile / tiles_per_outer, (tile % tiles_per_outer) * LANES);
        let start = outer * lines.outer_stride + x0;
        let width = LANES.min(lines.nx - x0);
        let len = lines.len;
        s.f.resize(width * len, 0.0);
        s.out.resize(width * len, 0.0);
        s.labels.clear();
        s.labels.resize(width * len, labels.voxels[start]);
        for i in 0..len {
            let row = start + i * lines.stride;
            for w in 0..width {
                // SAFETY: tiles differ in `outer` (disjoint planes or rows)
                // or in `x0` (disjoint x ranges), so no other task touches
                // this tile's voxels, which lie inside the grid.
                s.f[w * len + i] = unsafe { shared.read(row + w) }.get();
                s.labels[w * len + i] = labels.voxels[row + w];
            }
        }
        for w in 0..width {
            let line = w * len..(w + 1) * len;
            line_pass(
                labels,
                &s.f[line.clone()],
                &s.labels[line.clone()],
                w2,
                border,
                &mut s.out[line],
                &mut s.envelope,
            );
        }
        for i in 0..len {
            let row = start + i * lines.stride;
            for w in 0..width {
                // SAFETY: as above.
                unsafe { shared.write(row + w, V::put(s.out[w * len + i])) };
            }
        }
    });
}

/// One contiguous line: run by run, the envelope of the run's parabolas
/// bounded by the voxels just outside it.
fn line_pass<T, B, S>(
    labels: &Labels<'_, T, B, S>,
    f: &[f64],
    lab: &[T],
    w2: f64,
    border: bool,
    out: &mut [f64],
    env: &mut Envelope,
) where
    B: Fn(&T) -> bool,
    S: Fn(&T, &T) -> bool,
{
    let n = f.len();
    let mut a = 0;
    while a < n {
        if (labels.background)(&lab[a]) {
            out[a] = 0.0;
            a += 1;
            continue;
        }
        let mut b = a + 1;
        while b < n && !labels.ends(&lab[b - 1], &lab[b]) {
            b += 1;
        }
        let before = (a > 0 || border).then_some(a as f64 - 1.0);
        let after = (b < n || border).then_some(b as f64);
        run(&f[a..b], a, w2, before, after, &mut out[a..b], env);
        a = b;
    }
}

/// The run `f` starting at position `a` of its line, bounded by voxels of
/// another label at positions `before` and `after` where there are any.
fn run(f: &[f64], a: usize, w2: f64, before: Option<f64>, after: Option<f64>, out: &mut [f64], env: &mut Envelope) {
    let n = f.len();
    for buf in [&mut env.num, &mut env.den] {
        buf.resize(n.max(buf.len()), 0.0);
    }
    env.sites.resize(n.max(env.sites.len()), 0);
    let (sites, num, den) = (&mut env.sites[..n], &mut env.num[..n], &mut env.den[..n]);
    // The envelope is sites[..=k] (none while k is None); the first one is
    // lowest towards -infinity and always stays.
    let mut top: Option<usize> = None;
    for (q, &fq) in f.iter().enumerate() {
        if !fq.is_finite() {
            continue;
        }
        let Some(mut k) = top else {
            sites[0] = q;
            top = Some(0);
            continue;
        };
        // Pop the parabolas that q lies below from where they start on.
        let (mut sn, mut sd) = start(f, w2, sites[k], q, fq);
        while k > 0 && sn * den[k] <= num[k] * sd {
            k -= 1;
            (sn, sd) = start(f, w2, sites[k], q, fq);
        }
        k += 1;
        sites[k] = q;
        num[k] = sn;
        den[k] = sd;
        top = Some(k);
    }
    let mut k = 0;
    for (i, o) in out.iter_mut().enumerate() {
        let mut d = f64::INFINITY;
        if let Some(last) = top {
            let x = i as f64;
            while k < last && num[k + 1] < x * den[k + 1] {
                k += 1;
            }
            let p = sites[k];
            let gap = i.abs_diff(p) as f64;
            d = w2 * gap * gap + f[p];
        }
        let x = (a + i) as f64;
        if let Some(e) = before {
            d = d.min(w2 * (x - e) * (x - e));
        }
        if let Some(e) = after {
            d = d.min(w2 * (e - x) * (e - x));
        }
        *o = d;
    }
}

/// Where parabola `q` (value `fq`) starts to lie below parabola `p < q`, as
/// a fraction with a positive denominator.
#[inline]
fn start(f: &[f64], w2: f64, p: usize, q: usize, fq: f64) -> (f64, f64) {
    let d = (q - p) as f64;
    ((fq - f[p]) + w2 * d * (q + p) as f64, 2.0 * w2 * d)
}
