//! Per-frame observations of the local volume.

use edtmap_core::{LocalVolume, OBS_HIT, OBS_MISS, OBS_NONE};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU8, Ordering::Relaxed};

/// What one frame saw of each voxel of the local volume: a bit set of
/// [`OBS_MISS`] and [`OBS_HIT`]. Rays update it concurrently with `fetch_or`,
/// which commutes, so the result does not depend on thread scheduling; a
/// voxel with both bits set counts as a hit.
#[derive(Debug)]
pub struct Observations {
    volume: LocalVolume,
    cells: Vec<AtomicU8>,
}

impl Observations {
    /// Empty observations of `volume`.
    pub fn new(volume: LocalVolume) -> Self {
        let mut o = Observations { volume, cells: Vec::new() };
        o.reset(volume);
        o
    }

    /// Clears every cell and moves to `volume`, reusing the buffer.
    pub fn reset(&mut self, volume: LocalVolume) {
        self.volume = volume;
        let n = volume.len();
        if self.cells.len() != n {
            self.cells = (0..n).map(|_| AtomicU8::new(OBS_NONE)).collect();
        } else {
            self.cells.par_iter().with_min_len(1 << 14).for_each(|c| c.store(OBS_NONE, Relaxed));
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
        let bits = self.cells[i].load(Relaxed);
        if bits & OBS_HIT != 0 {
            OBS_HIT
        } else {
            bits & OBS_MISS
        }
    }

    /// Records a miss at linear index `i` (a no-op if already recorded).
    #[inline]
    pub(super) fn miss(&self, i: usize) {
        let c = &self.cells[i];
        if c.load(Relaxed) & OBS_MISS == 0 {
            c.fetch_or(OBS_MISS, Relaxed);
        }
    }

    /// Records a hit at linear index `i`.
    #[inline]
    pub(super) fn hit(&self, i: usize) {
        let c = &self.cells[i];
        if c.load(Relaxed) & OBS_HIT == 0 {
            c.fetch_or(OBS_HIT, Relaxed);
        }
    }

    /// The cells of z-plane `z`.
    pub(super) fn plane(&self, z: usize) -> &[AtomicU8] {
        let n = self.volume.dims[0] * self.volume.dims[1];
        &self.cells[z * n..(z + 1) * n]
    }

    /// Number of voxels observed (hit or miss).
    pub fn observed_count(&self) -> usize {
        self.cells.par_iter().filter(|c| c.load(Relaxed) != OBS_NONE).count()
    }
}
