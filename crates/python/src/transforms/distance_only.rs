//! The distance-only path of the transforms: distances written into the
//! output array itself, with no nearest-obstacle field.

use super::{Distances, Indices, Job, Output, CHUNK};
use crate::labelled::{squared_distances, Grid, Labels, Value};
use crate::memory::{check_memory, try_vec};
use edtmap_core::{EdtField, MemoryBudget, UNREACHABLE_DIST_SQ};
use pyo3::PyResult;
use rayon::prelude::*;

/// Squared distances below this are integers exact in f64 (2^53).
const F64_EXACT: f64 = 9_007_199_254_740_992.0;

impl Job<'_> {
    /// Whether the outputs need no nearest-obstacle field: no indices, and
    /// distances that do not depend on which of two equidistant obstacles
    /// is nearest (SciPy's do with non-integer sampling, whose rounding
    /// follows the obstacle's coordinates).
    pub(super) fn without_field(&self) -> bool {
        let g = self.geometry;
        self.indices == Indices::None
            && match self.output {
                Output::None => false,
                Output::Float32 | Output::Float32Sq => true,
                Output::Scipy => {
                    let diag: f64 = (0..g.shape.len()).map(|k| ((g.shape[k] - 1) as f64 * g.spacing[k]).powi(2)).sum();
                    g.spacing.iter().all(|w| w.fract() == 0.0) && diag < F64_EXACT
                }
            }
    }

    /// Whether the core's transform, which keeps each voxel's nearest
    /// obstacle, is the one to run for these outputs: it is about twice as
    /// fast on one label (its scans are vectorised across lines), and takes
    /// 8 bytes a voxel besides the input, so it runs only on an isotropic
    /// grid without `black_border`, and only where the system has room for
    /// it (80 % of the available memory, and the room under `RLIMIT_AS`);
    /// the distance-only transform needs only the output.
    pub(super) fn field_is_faster(&self) -> bool {
        let g = self.geometry;
        let n = g.shape.iter().product::<usize>() as u64;
        let out = match self.output {
            Output::None => return true,
            Output::Scipy => 8,
            // The float32 output takes the field's distances' place.
            Output::Float32 | Output::Float32Sq => 0,
        };
        let iso = g.spacing.iter().all(|&x| x == g.spacing[0]);
        iso && !self.black_border && MemoryBudget::from_system().check("", n.saturating_mul(8 + out), "").is_ok()
    }

    /// The float32 distances of an isotropic field, written over its squared
    /// distances once its nearest obstacles are dropped.
    pub(super) fn float32_in_place(&self, field: EdtField, w: f64) -> Distances {
        let (mut dist, near) = field.into_parts();
        drop(near);
        let squared = self.output == Output::Float32Sq;
        dist.par_iter_mut().for_each(|d| {
            let v = if *d == UNREACHABLE_DIST_SQ { f64::INFINITY } else { f64::from(*d) };
            *d = (if squared { (v * w * w) as f32 } else { (v.sqrt() * w) as f32 }).to_bits();
        });
        // Same size and alignment: the allocation is reused, not copied.
        Distances::F32(dist.into_iter().map(f32::from_bits).collect())
    }

    /// Refuses, before anything is allocated, a job whose outputs and
    /// working memory do not fit the room left to the process.
    pub(super) fn check_memory(&self) -> PyResult<()> {
        let g = self.geometry;
        let n = g.shape.iter().product::<usize>() as u64;
        let out = match self.output {
            Output::None => 0,
            Output::Scipy => 8,
            Output::Float32 | Output::Float32Sq => 4,
        };
        let indices = if self.indices == Indices::None { 0 } else { 4 * g.shape.len() as u64 };
        let iso = g.spacing.iter().all(|&x| x == g.spacing[0]);
        let field = if self.without_field() {
            0
        } else if iso {
            8
        } else {
            12
        };
        check_memory(&g.shape, n.saturating_mul(out + indices + field))
    }

    /// Squared distances by the distance-only transform, then the output's
    /// values in place. `background` voxels are at distance 0, `same` says
    /// whether two neighbours share a label (see `labelled.rs`).
    pub(super) fn distances_only<T: Copy + Sync>(
        &self,
        voxels: &[T],
        background: impl Fn(&T) -> bool + Sync,
        same: impl Fn(&T, &T) -> bool + Sync,
    ) -> PyResult<(Option<Distances>, Option<Vec<i32>>)> {
        let g = self.geometry;
        let n = voxels.len();
        let labels = Labels { voxels, background, same };
        // The core's axes are numpy's reversed.
        let w: Vec<f64> = g.spacing.iter().rev().copied().chain([1.0; 3]).take(3).collect();
        let mut grid =
            Grid { dims: g.dims(), axes: g.shape.len(), w: [w[0], w[1], w[2]], black_border: self.black_border };
        if self.output == Output::Scipy {
            if !voxels.par_iter().any(&labels.background) {
                return Ok((Some(Distances::F64(self.scipy_without_zeros()?)), None));
            }
            let mut out = try_vec(n, 0.0f64, &g.shape)?;
            squared_distances(&labels, grid, &mut out);
            out.par_iter_mut().for_each(|d| *d = d.sqrt());
            return Ok((Some(Distances::F64(out)), None));
        }
        // An isotropic grid is transformed in voxels, whose squared
        // distances are integers, and scaled once at the end.
        let scale = if grid.w.iter().all(|&x| x == grid.w[0]) {
            let s = grid.w[0];
            grid.w = [1.0; 3];
            s
        } else {
            1.0
        };
        let mut out = try_vec(n, 0.0f32, &g.shape)?;
        squared_distances(&labels, grid, &mut out);
        let squared = self.output == Output::Float32Sq;
        out.par_iter_mut().for_each(|o| {
            let d = o.get();
            *o = if squared { (d * scale * scale) as f32 } else { (d.sqrt() * scale) as f32 };
        });
        Ok((Some(Distances::F32(out)), None))
    }

    /// SciPy's answer for an input without any zero: distances to a virtual
    /// zero at index -1 of axis 0 (and 0 of the others).
    fn scipy_without_zeros(&self) -> PyResult<Vec<f64>> {
        let g = self.geometry;
        let mut out = try_vec(g.shape.iter().product(), 0.0f64, &g.shape)?;
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(t, chunk)| {
            let mut c = [0i64; 3];
            for (j, o) in chunk.iter_mut().enumerate() {
                g.coords(t * CHUNK + j, &mut c);
                c[0] += 1;
                let mut sum = 0.0;
                for (&c, &w) in c.iter().zip(&g.spacing) {
                    let d = if g.sampled { c as f64 * w } else { c as f64 };
                    sum += d * d;
                }
                *o = sum.sqrt();
            }
        });
        Ok(out)
    }
}
