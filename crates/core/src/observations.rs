//! Per-frame observations of the local volume.

use crate::{BlockKey, LocalVolume, OBS_HIT, OBS_MISS, OBS_NONE};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering::Relaxed};

/// Side of the cells that track which parts of the volume were touched.
const CELL: usize = 8;

/// What one frame saw of each voxel of the local volume: a bit set of
/// [`OBS_MISS`] and [`OBS_HIT`]. Rays update it concurrently with `fetch_or`,
/// which commutes, so the result does not depend on thread scheduling; a
/// voxel with both bits set counts as a hit.
///
/// Cells of 8³ voxels (aligned to the volume) remember whether they were
/// touched, so clearing and fusion visit only what a frame saw: a LiDAR
/// sweep touches a small part of a volume that spans its whole range.
#[derive(Debug)]
pub struct Observations {
    volume: LocalVolume,
    voxels: Vec<AtomicU8>,
    cell_dims: [usize; 3],
    touched: Vec<AtomicBool>,
}

impl Observations {
    /// Empty observations of `volume`.
    pub fn new(volume: LocalVolume) -> Self {
        let mut o = Observations { volume, voxels: Vec::new(), cell_dims: [0; 3], touched: Vec::new() };
        o.reset(volume);
        o
    }

    /// Clears every cell and moves to `volume`, reusing the buffers.
    pub fn reset(&mut self, volume: LocalVolume) {
        if self.voxels.len() != volume.len() || self.volume.dims != volume.dims {
            self.voxels = (0..volume.len()).map(|_| AtomicU8::new(OBS_NONE)).collect();
            self.cell_dims = volume.dims.map(|d| d.div_ceil(CELL));
            self.touched = (0..self.cell_dims.iter().product()).map(|_| AtomicBool::new(false)).collect();
        } else {
            let this = &*self;
            this.touched.par_iter().enumerate().filter(|(_, t)| t.load(Relaxed)).for_each(|(cell, t)| {
                this.for_each_in_cell(cell, |i| this.voxels[i].store(OBS_NONE, Relaxed));
                t.store(false, Relaxed);
            });
        }
        self.volume = volume;
    }

    fn for_each_in_cell(&self, cell: usize, mut f: impl FnMut(usize)) {
        let [cx, cy] = [self.cell_dims[0], self.cell_dims[1]];
        let c = [cell % cx, (cell / cx) % cy, cell / (cx * cy)];
        let [nx, ny, nz] = self.volume.dims;
        let range = |a: usize, n: usize| c[a] * CELL..((c[a] + 1) * CELL).min(n);
        for z in range(2, nz) {
            for y in range(1, ny) {
                let row = nx * (y + ny * z);
                range(0, nx).for_each(|x| f(row + x));
            }
        }
    }

    /// The volume observed.
    pub fn volume(&self) -> &LocalVolume {
        &self.volume
    }

    /// The observation of the voxel at linear index `i`: [`OBS_NONE`],
    /// [`OBS_MISS`] or [`OBS_HIT`].
    #[inline]
    pub fn get(&self, i: usize) -> u8 {
        let bits = self.voxels[i].load(Relaxed);
        if bits & OBS_HIT != 0 {
            OBS_HIT
        } else {
            bits & OBS_MISS
        }
    }

    /// Adds observation bit `obs` to the voxel at local coordinates `c`,
    /// linear index `i`.
    #[inline]
    pub fn mark(&self, c: [usize; 3], i: usize, obs: u8) {
        let v = &self.voxels[i];
        if v.load(Relaxed) & obs == 0 {
            v.fetch_or(obs, Relaxed);
            self.touch(c);
        }
    }

    /// [`Self::mark`] for a caller that alone marks voxel `i` while it
    /// runs (a tile of the projection, which no other thread touches): a
    /// plain load and store where [`Self::mark`] needs an atomic OR.
    #[inline]
    pub fn mark_alone(&self, c: [usize; 3], i: usize, obs: u8) {
        let v = &self.voxels[i];
        let bits = v.load(Relaxed);
        if bits & obs == 0 {
            v.store(bits | obs, Relaxed);
            self.touch(c);
        }
    }

    #[inline]
    fn touch(&self, c: [usize; 3]) {
        let [cx, cy, _] = self.cell_dims;
        let t = &self.touched[c[0] / CELL + cx * (c[1] / CELL + cy * (c[2] / CELL))];
        if !t.load(Relaxed) {
            t.store(true, Relaxed);
        }
    }

    /// Takes the observation bits of every voxel from `bits` (one byte per
    /// voxel, as a backend cast them), on a freshly reset volume: the same
    /// state as marking each bit in turn.
    pub fn load_bits(&self, bits: &[u8]) {
        let [nx, ny, _] = self.volume.dims;
        let [cx, cy, _] = self.cell_dims;
        let rows = self.voxels.par_chunks(nx).zip(bits.par_chunks(nx));
        rows.enumerate().for_each(|(row, (voxels, bits))| {
            let (y, z) = (row % ny, row / ny);
            let cell_row = cx * (y / CELL + cy * (z / CELL));
            for (x, (v, &b)) in voxels.iter().zip(bits).enumerate() {
                if b != OBS_NONE {
                    v.store(b, Relaxed);
                    let t = &self.touched[cell_row + x / CELL];
                    if !t.load(Relaxed) {
                        t.store(true, Relaxed);
                    }
                }
            }
        });
    }

    /// Whether any voxel of world block `key` may have been observed.
    pub fn block_touched(&self, key: BlockKey) -> bool {
        let span = self.volume.block_span(key);
        if span.iter().any(|r| r.is_empty()) {
            return false;
        }
        let [cx, cy, _] = self.cell_dims;
        let cells = span.map(|r| r.start / CELL..=(r.end - 1) / CELL);
        cells[2].clone().any(|z| {
            cells[1].clone().any(|y| cells[0].clone().any(|x| self.touched[x + cx * (y + cy * z)].load(Relaxed)))
        })
    }

    /// Every voxel observed, as (linear index, [`OBS_MISS`] or [`OBS_HIT`]),
    /// in no particular order; visits only the touched cells.
    pub fn observed(&self) -> Vec<(usize, u8)> {
        let cells: Vec<usize> =
            (0..self.touched.len()).into_par_iter().filter(|&c| self.touched[c].load(Relaxed)).collect();
        cells
            .into_par_iter()
            .flat_map_iter(|cell| {
                let mut found = Vec::new();
                self.for_each_in_cell(cell, |i| {
                    let code = self.get(i);
                    if code != OBS_NONE {
                        found.push((i, code));
                    }
                });
                found
            })
            .collect()
    }

    /// Number of voxels observed (hit or miss).
    pub fn observed_count(&self) -> usize {
        self.voxels.par_iter().filter(|c| c.load(Relaxed) != OBS_NONE).count()
    }
}
