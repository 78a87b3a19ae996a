//! Distance transforms of numpy arrays: the one Rust entry point behind
//! `edtmap.distance_transform_edt`, `edtmap.edt`/`edtsq` and
//! `edtmap.obstacle_distance` (python/edtmap/_transforms.py normalises the
//! arguments and the array layout, this does the work).
//!
//! Distances alone come from the distance-only transform (`labelled.rs`),
//! written into the output array itself; the nearest obstacles' indices,
//! and SciPy's distances with non-integer sampling (computed from those
//! indices to round as SciPy does), come from the core's transform, which
//! tracks every voxel's nearest obstacle.

use edtmap_core::{EdtField, NO_SITE, UNREACHABLE_DIST_SQ};
use edtmap_cpu::edt::{edt_slice_into, edt_weighted_int, edt_weighted_real, ScanLayout};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use rayon::prelude::*;
use std::sync::Mutex;

mod distance_only;

/// The distances and the nearest obstacles' coordinates, as asked.
type Outputs = (Option<Py<PyAny>>, Option<Py<PyAny>>);

/// Voxels per parallel task when the outputs are assembled.
const CHUNK: usize = 1 << 15;

/// Largest spacing taken by the exact integer path (larger integers use
/// f64, where they are exact as well up to 2^53).
const MAX_INT_WEIGHT: f64 = 65535.0;

/// What the distances output holds.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Output {
    /// No distances.
    None,
    /// float64 distances computed from the nearest obstacle's coordinates
    /// exactly as SciPy does (so that equal coordinates give equal bits).
    Scipy,
    /// float32 distances (the `edt` package).
    Float32,
    /// float32 squared distances (`edt.edtsq`).
    Float32Sq,
}

impl Output {
    fn parse(s: &str) -> PyResult<Self> {
        Ok(match s {
            "none" => Output::None,
            "scipy" => Output::Scipy,
            "float32" => Output::Float32,
            "float32sq" => Output::Float32Sq,
            other => return Err(PyValueError::new_err(format!("unknown output kind {other:?}"))),
        })
    }
}

/// What the nearest-obstacle output holds where the grid has no obstacle.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Missing {
    /// SciPy's convention: a virtual obstacle at index -1 of axis 0 and 0
    /// of the others, to which the distances are measured.
    Scipy,
    /// -1 on every axis and an infinite distance.
    Minus1,
}

/// The transform of one grid, in whichever arithmetic its spacing needs.
enum Field {
    /// Isotropic spacing `w`: squared distances in voxels.
    Iso(EdtField, f64),
    /// Integer spacings: exact weighted squared distances.
    Int(Vec<u64>, Vec<u32>),
    /// Real spacings: weighted squared distances in f64.
    Real(Vec<f64>, Vec<u32>),
}

impl Field {
    fn nearest(&self) -> &[u32] {
        match self {
            Field::Iso(f, _) => f.nearest(),
            Field::Int(_, n) | Field::Real(_, n) => n,
        }
    }

    /// Physical squared distance of voxel `i` (infinite without obstacle).
    #[inline]
    fn dist_sq(&self, i: usize) -> f64 {
        match self {
            Field::Iso(f, w) => match f.dist_sq_vox()[i] {
                UNREACHABLE_DIST_SQ => f64::INFINITY,
                d => f64::from(d) * w * w,
            },
            Field::Int(d, _) => match d[i] {
                u64::MAX => f64::INFINITY,
                d => d as f64,
            },
            Field::Real(d, _) => d[i],
        }
    }

    /// Physical distance of voxel `i`: for an isotropic grid
    /// `sqrt(d²) · w`, so unit spacing gives the correctly rounded root.
    #[inline]
    fn dist(&self, i: usize) -> f64 {
        match self {
            Field::Iso(f, w) => match f.dist_sq_vox()[i] {
                UNREACHABLE_DIST_SQ => f64::INFINITY,
                d => f64::from(d).sqrt() * w,
            },
            _ => self.dist_sq(i).sqrt(),
        }
    }
}

/// The grid's shape in numpy order and its per-axis spacing.
struct Geometry {
    shape: Vec<usize>,
    /// Spacing per numpy axis (all 1 when none was given).
    spacing: Vec<f64>,
    /// Whether a spacing was given (SciPy multiplies only then).
    sampled: bool,
}

impl Geometry {
    /// `[nx, ny, nz]` of the core transform: numpy's last axis is the
    /// contiguous one, the core's `x`.
    fn dims(&self) -> [usize; 3] {
        let mut dims = [1; 3];
        for (k, &n) in self.shape.iter().rev().enumerate() {
            dims[k] = n;
        }
        dims
    }

    /// Numpy coordinates of C-order linear index `linear`.
    #[inline]
    fn coords(&self, mut linear: usize, out: &mut [i64; 3]) {
        for k in (0..self.shape.len()).rev() {
            out[k] = (linear % self.shape[k]) as i64;
            linear /= self.shape[k];
        }
    }

    /// Squared distance from voxel `c` to the nearest voxel outside the
    /// grid (the `edt` package's `black_border`).
    #[inline]
    fn border_sq(&self, c: &[i64; 3]) -> f64 {
        (0..self.shape.len())
            .map(|k| {
                let steps = (c[k] + 1).min(self.shape[k] as i64 - c[k]) as f64 * self.spacing[k];
                steps * steps
            })
            .fold(f64::INFINITY, f64::min)
    }
}

/// Runs the transform on a C-contiguous array of unsigned integers or
/// floats (python/edtmap/_transforms.py views bool and signed data as
/// unsigned integers).
///
/// With `labels` (`edt` semantics), zero elements are background and every
/// other value is a label: each voxel's distance is to the nearest voxel
/// not of its label. Otherwise obstacles are the zero elements when
/// `zero_is_obstacle` (SciPy semantics), the nonzero ones if not. Returns
/// the distances (as `output` says) and, if `indices`, the nearest
/// obstacle's coordinates as an int32 array of shape `(ndim,) + shape`
/// (`indices = "first"`) or `shape + (ndim,)` (`"last"`).
#[pyfunction]
#[pyo3(signature = (input, spacing, labels, zero_is_obstacle, output, indices, black_border, missing, threads))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn transform<'py>(
    py: Python<'py>,
    input: &Bound<'py, PyAny>,
    spacing: Option<Vec<f64>>,
    labels: bool,
    zero_is_obstacle: bool,
    output: &str,
    indices: &str,
    black_border: bool,
    missing: &str,
    threads: usize,
) -> PyResult<Outputs> {
    let output = Output::parse(output)?;
    let indices = match indices {
        "none" => Indices::None,
        "first" => Indices::First,
        "last" => Indices::Last,
        other => return Err(PyValueError::new_err(format!("unknown indices kind {other:?}"))),
    };
    let missing = match missing {
        "scipy" => Missing::Scipy,
        "minus1" => Missing::Minus1,
        other => return Err(PyValueError::new_err(format!("unknown missing kind {other:?}"))),
    };
    macro_rules! by_type {
        ($($t:ty),*) => {
            $(if let Ok(array) = input.extract::<PyReadonlyArrayDyn<'py, $t>>() {
                let shape = array.shape().to_vec();
                if !array.is_c_contiguous() {
                    return Err(PyValueError::new_err("internal: the array must be C-contiguous"));
                }
                let voxels = array.as_slice().map_err(|e| PyValueError::new_err(e.to_string()))?;
                let geometry = geometry(shape, spacing)?;
                let job = Job { geometry: &geometry, output, indices, black_border, missing };
                job.check_memory()?;
                let zero = <$t>::default();
                let (dist, near) = py.detach(|| {
                    with_threads(threads, || {
                        if labels {
                            let one_label = || !several_labels(voxels, zero);
                            if job.field_is_faster() && one_label() {
                                job.run(voxels, |v: &$t| *v == zero)
                            } else {
                                // Float labels compare as numbers: -0.0 is
                                // background, NaN no other voxel's label.
                                job.distances_only(voxels, |v: &$t| *v == zero, |a: &$t, b: &$t| a == b)
                            }
                        } else {
                            let is_obstacle = |v: &$t| (*v == zero) == zero_is_obstacle;
                            if job.without_field() && !job.field_is_faster() {
                                job.distances_only(voxels, is_obstacle, |_: &$t, _: &$t| true)
                            } else {
                                job.run(voxels, is_obstacle)
                            }
                        }
                    })
                })?;
                return job.to_arrays(py, dist, near);
            })*
        };
    }
    by_type!(u8, u16, u32, u64, f32, f64);
    Err(PyTypeError::new_err("internal: the array must hold unsigned integers or floats"))
}

/// Whether `values` holds two different nonzero values (labels; a NaN
/// differs from every value), decided without sorting.
fn several_labels<T: Copy + PartialEq + Sync>(values: &[T], zero: T) -> bool {
    let first = values.par_iter().find_first(|&&v| v != zero).copied();
    first.is_some_and(|first| values.par_iter().any(|&v| v != zero && v != first))
}

/// The isotropic transform's working field, kept between calls: a grid
/// transformed again (as a planner does every cycle) then reuses memory
/// that is already mapped, rather than faulting in 8 bytes per voxel anew.
/// A second concurrent call makes its own.
static FIELD: Mutex<Option<EdtField>> = Mutex::new(None);

/// Largest field kept between calls, voxels (512 MiB of field).
const KEEP_MAX_VOXELS: usize = 1 << 26;

fn take_field() -> EdtField {
    FIELD.lock().ok().and_then(|mut f| f.take()).unwrap_or_else(EdtField::empty)
}

fn keep_field(field: EdtField) {
    if field.dist_sq_vox().len() <= KEEP_MAX_VOXELS {
        if let Ok(mut slot) = FIELD.lock() {
            *slot = Some(field);
        }
    }
}

/// Checks the shape and the spacing.
fn geometry(shape: Vec<usize>, spacing: Option<Vec<f64>>) -> PyResult<Geometry> {
    if shape.is_empty() || shape.len() > 3 {
        return Err(PyValueError::new_err(format!(
            "the array must have 1, 2 or 3 dimensions, not {} (shape {shape:?})",
            shape.len()
        )));
    }
    if shape.contains(&0) {
        return Err(PyValueError::new_err(format!("the array is empty (shape {shape:?})")));
    }
    let sampled = spacing.is_some();
    let spacing = spacing.unwrap_or_else(|| vec![1.0; shape.len()]);
    if spacing.len() != shape.len() {
        return Err(PyValueError::new_err(format!(
            "the spacing has {} values for an array of {} dimensions",
            spacing.len(),
            shape.len()
        )));
    }
    if let Some(bad) = spacing.iter().find(|w| !(w.is_finite() && **w > 0.0)) {
        return Err(PyValueError::new_err(format!("spacing values must be finite and positive, got {bad}")));
    }
    Ok(Geometry { shape, spacing, sampled })
}

/// Runs `f` on a pool of `threads` threads (0: all cores), at most as many
/// as the cores this process may use: more would only contend for them.
fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> PyResult<T> + Send) -> PyResult<T> {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let threads = threads.min(cores);
    if threads == 0 || threads == rayon::current_num_threads() {
        return f();
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| PyValueError::new_err(format!("cannot start {threads} threads: {e}")))?;
    pool.install(f)
}

/// Whether and where the nearest obstacle's coordinates go.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Indices {
    None,
    /// `(ndim,) + shape` (SciPy).
    First,
    /// `shape + (ndim,)` (the command line's `--nearest`).
    Last,
}

/// One request: the geometry and which outputs to build.
struct Job<'a> {
    geometry: &'a Geometry,
    output: Output,
    indices: Indices,
    black_border: bool,
    missing: Missing,
}

/// Distances as f64 or f32 values.
enum Distances {
    F64(Vec<f64>),
    F32(Vec<f32>),
}

impl Job<'_> {
    /// The transform and the outputs, without the GIL.
    fn run<T: Copy + Sync>(
        &self,
        voxels: &[T],
        is_obstacle: impl Fn(&T) -> bool + Sync,
    ) -> PyResult<(Option<Distances>, Option<Vec<i32>>)> {
        let g = self.geometry;
        let dims = g.dims();
        // The core's axes are numpy's reversed.
        let w: Vec<f64> = g.spacing.iter().rev().copied().chain([1.0; 3]).take(3).collect();
        let w = [w[0], w[1], w[2]];
        let err = |e: edtmap_cpu::CpuError| match e {
            edtmap_cpu::CpuError::Core(edtmap_core::CoreError::OutOfMemory { .. }) => {
                pyo3::exceptions::PyMemoryError::new_err(e.to_string())
            }
            _ => PyValueError::new_err(e.to_string()),
        };
        let field = if w.iter().all(|&x| x == w[0]) {
            let mut field = take_field();
            edt_slice_into(voxels, dims, is_obstacle, ScanLayout::default(), &mut field).map_err(err)?;
            let float32 = matches!(self.output, Output::Float32 | Output::Float32Sq);
            if float32 && self.indices == Indices::None && !self.black_border {
                return Ok((Some(self.float32_in_place(field, w[0])), None));
            }
            Field::Iso(field, w[0])
        } else if w.iter().all(|&x| x.fract() == 0.0 && x <= MAX_INT_WEIGHT) {
            let (d, n) = edt_weighted_int(voxels, dims, is_obstacle, w.map(|x| x as u32)).map_err(err)?;
            Field::Int(d, n)
        } else {
            let (d, n) = edt_weighted_real(voxels, dims, is_obstacle, w).map_err(err)?;
            Field::Real(d, n)
        };
        let any_site = field.nearest().first().is_some_and(|&s| s != NO_SITE);
        let dist = self.distances(&field, any_site);
        let near = (self.indices != Indices::None).then(|| self.coordinates(&field, any_site));
        if let Field::Iso(field, _) = field {
            keep_field(field);
        }
        Ok((dist, near))
    }

    /// The distances output.
    fn distances(&self, field: &Field, any_site: bool) -> Option<Distances> {
        let plain = (field, self.output, self.black_border);
        if let (Field::Iso(f, w), Output::Float32 | Output::Float32Sq, false) = plain {
            // The common case, one vectorisable pass: `edt.edt` of a mask.
            let (w, squared) = (*w, self.output == Output::Float32Sq);
            let mut out = vec![0.0f32; f.dist_sq_vox().len()];
            out.par_chunks_mut(CHUNK).zip(f.dist_sq_vox().par_chunks(CHUNK)).for_each(|(out, d2)| {
                for (o, &d) in out.iter_mut().zip(d2) {
                    let d = if d == UNREACHABLE_DIST_SQ { f64::INFINITY } else { f64::from(d) };
                    *o = if squared { (d * w * w) as f32 } else { (d.sqrt() * w) as f32 };
                }
            });
            return Some(Distances::F32(out));
        }
        let g = self.geometry;
        let n: usize = g.shape.iter().product();
        let border = self.black_border;
        let value = |i: usize| -> f64 {
            let mut c = [0i64; 3];
            match self.output {
                Output::Scipy => {
                    g.coords(i, &mut c);
                    let mut s = [0i64; 3];
                    if any_site {
                        g.coords(field.nearest()[i] as usize, &mut s);
                    } else {
                        s[0] = -1;
                    }
                    let mut sum = 0.0;
                    for k in 0..g.shape.len() {
                        let mut d = (c[k] - s[k]) as f64;
                        if g.sampled {
                            d *= g.spacing[k];
                        }
                        sum += d * d;
                    }
                    sum.sqrt()
                }
                Output::Float32Sq | Output::Float32 => {
                    let squared = self.output == Output::Float32Sq;
                    if border {
                        g.coords(i, &mut c);
                        let b = g.border_sq(&c);
                        let d = field.dist_sq(i);
                        if b < d {
                            return if squared { b } else { b.sqrt() };
                        }
                    }
                    if squared {
                        field.dist_sq(i)
                    } else {
                        field.dist(i)
                    }
                }
                Output::None => 0.0,
            }
        };
        match self.output {
            Output::None => None,
            Output::Scipy => {
                let mut out = vec![0.0f64; n];
                out.par_chunks_mut(CHUNK).enumerate().for_each(|(t, chunk)| {
                    for (j, o) in chunk.iter_mut().enumerate() {
                        *o = value(t * CHUNK + j);
                    }
                });
                Some(Distances::F64(out))
            }
            Output::Float32 | Output::Float32Sq => {
                let mut out = vec![0.0f32; n];
                out.par_chunks_mut(CHUNK).enumerate().for_each(|(t, chunk)| {
                    for (j, o) in chunk.iter_mut().enumerate() {
                        *o = value(t * CHUNK + j) as f32;
                    }
                });
                Some(Distances::F32(out))
            }
        }
    }

    /// Nearest obstacle coordinates, `(ndim,) + shape` or `shape + (ndim,)`.
    fn coordinates(&self, field: &Field, any_site: bool) -> Vec<i32> {
        let g = self.geometry;
        let n: usize = g.shape.iter().product();
        let ndim = g.shape.len();
        let near = field.nearest();
        // Without any obstacle every voxel has none.
        let fill = match (self.missing, any_site) {
            (Missing::Scipy, false) => [-1, 0, 0],
            _ => [-1, -1, -1],
        };
        let site_coords = |i: usize, s: &mut [i64; 3]| match near[i] {
            NO_SITE => *s = fill,
            site => g.coords(site as usize, s),
        };
        let mut out = vec![0i32; n * ndim];
        if self.indices == Indices::Last {
            out.par_chunks_mut(CHUNK * ndim).enumerate().for_each(|(t, chunk)| {
                let mut s = [0i64; 3];
                for (j, voxel) in chunk.chunks_mut(ndim).enumerate() {
                    site_coords(t * CHUNK + j, &mut s);
                    for (o, &c) in voxel.iter_mut().zip(&s) {
                        *o = c as i32;
                    }
                }
            });
            return out;
        }
        // One task per chunk of voxels, writing that chunk of every axis.
        let mut axes: Vec<&mut [i32]> = out.chunks_mut(n).collect();
        let mut per_task: Vec<Vec<&mut [i32]>> = Vec::new();
        while !axes[0].is_empty() {
            let take = CHUNK.min(axes[0].len());
            let mut parts = Vec::with_capacity(ndim);
            for axis in axes.iter_mut() {
                let (head, tail) = std::mem::take(axis).split_at_mut(take);
                parts.push(head);
                *axis = tail;
            }
            per_task.push(parts);
        }
        per_task.into_par_iter().enumerate().for_each(|(t, mut parts)| {
            let mut s = [0i64; 3];
            for j in 0..parts[0].len() {
                site_coords(t * CHUNK + j, &mut s);
                for (k, part) in parts.iter_mut().enumerate() {
                    part[j] = s[k] as i32;
                }
            }
        });
        out
    }

    /// Wraps the outputs as numpy arrays of the grid's shape.
    fn to_arrays(&self, py: Python<'_>, dist: Option<Distances>, near: Option<Vec<i32>>) -> PyResult<Outputs> {
        let shape = self.geometry.shape.clone();
        let dist = match dist {
            None => None,
            Some(Distances::F64(v)) => Some(PyArray1::from_vec(py, v).reshape(shape.clone())?.into_any()),
            Some(Distances::F32(v)) => Some(PyArray1::from_vec(py, v).reshape(shape.clone())?.into_any()),
        };
        let near = match near {
            None => None,
            Some(v) => {
                let full = match self.indices {
                    Indices::Last => shape.iter().copied().chain([shape.len()]).collect(),
                    _ => [shape.len()].into_iter().chain(shape.iter().copied()).collect::<Vec<_>>(),
                };
                Some(PyArray1::from_vec(py, v).reshape(full)?.into_any().unbind())
            }
        };
        Ok((dist.map(Bound::unbind), near))
    }
}
