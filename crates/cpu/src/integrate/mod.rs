//! Global EDT integration (paper §IV-C): each frame's batch EDT of the
//! local window is merged into the unbounded global EDT, so that obstacles
//! which appeared or vanished, inside or outside the window, are reflected
//! everywhere within the cutoff.
//!
//! Two modes ([`IntegrationMode`]): the paper's wavefronts
//! ([`wavefront`]) and an exact recomputation of the region the frame can
//! affect ([`exact`]). Both work on a dense copy of that region
//! ([`region`]) and write back only the voxels that changed, returning the
//! blocks they touched.

pub mod exact;
pub mod lazy;
pub mod region;
pub mod wavefront;

use crate::CpuError;
use edtmap_core::{EdtField, EdtMap, GlobalParams, IntegrationMode, LocalVolume, Obstacles};
use exact::{integrate_exact, ExactBuffers};
use region::{Packing, Region};
use wavefront::{integrate_wavefront, WaveBuffers};

pub use edtmap_core::backend::{IntegrateReport, WaveCounts};

/// The integration stage: parameters and buffers reused across frames.
#[derive(Debug)]
pub struct Integrator {
    params: GlobalParams,
    cutoff: edtmap_core::Cutoff,
    offsets: Vec<[i32; 3]>,
    waves: WaveBuffers,
    exact: ExactBuffers,
}

impl Integrator {
    /// An integrator for voxels of `voxel_size_m`; fails on a bad cutoff.
    pub fn new(params: &GlobalParams, voxel_size_m: f64) -> Result<Self, CpuError> {
        let cutoff = params.cutoff(voxel_size_m)?;
        Ok(Integrator {
            params: params.clone(),
            cutoff,
            offsets: params.connectivity.offsets(),
            waves: WaveBuffers::default(),
            exact: ExactBuffers::default(),
        })
    }

    /// The cutoff in voxels.
    pub fn cutoff(&self) -> edtmap_core::Cutoff {
        self.cutoff
    }

    /// The integration mode.
    pub fn mode(&self) -> IntegrationMode {
        self.params.mode
    }

    /// The neighbour offsets of the connectivity.
    pub fn offsets(&self) -> &[[i32; 3]] {
        &self.offsets
    }

    /// Drops what the integrator cached about `blocks`, which something
    /// else (another backend) changed.
    pub fn forget(&mut self, blocks: &[edtmap_core::BlockKey]) {
        self.waves.forget(blocks);
    }

    /// Recomputes exactly every voxel within the cutoff of the box `bounds`
    /// (forbidden zones, a prior map laid down), in tiles of at most
    /// `TILE`³ voxels so memory stays bounded.
    pub fn recompute(&mut self, map: &mut EdtMap, obstacles: &Obstacles<'_>, bounds: &Region) -> Result<IntegrateReport, CpuError> {
        const TILE: usize = 128;
        let mut total = IntegrateReport::default();
        for z in (0..bounds.dims[2]).step_by(TILE) {
            for y in (0..bounds.dims[1]).step_by(TILE) {
                for x in (0..bounds.dims[0]).step_by(TILE) {
                    let c = [x, y, z];
                    let tile = Region {
                        origin: [0, 1, 2].map(|a| bounds.origin[a] + c[a] as i32),
                        dims: [0, 1, 2].map(|a| TILE.min(bounds.dims[a] - c[a])),
                    };
                    let packing = Packing::new(tile.grown(self.cutoff.reach), self.cutoff)?;
                    let w = integrate_exact(map, obstacles, &packing, &mut self.exact)?;
                    self.waves.forget(&w.changed_blocks);
                    total.voxels_changed += w.voxels_changed;
                    total.change_sum_vox += w.change_sum_vox;
                    total.changed_blocks.extend(w.changed_blocks);
                    total.region_voxels += packing.region.len();
                }
            }
        }
        total.changed_blocks.sort_unstable();
        total.changed_blocks.dedup();
        Ok(total)
    }

    /// Merges the frame whose window is `window` into `map`. `batch` is the
    /// exact EDT of `window` with `obstacles` (unknown voxels free), used
    /// by the wavefront mode; the exact mode reads `obstacles` directly.
    ///
    /// The integrator caches, per block of `map`, the box its nearest
    /// obstacles lie in: give one integrator one map, and start a new one
    /// after changing the map's EDT by other means.
    pub fn integrate(
        &mut self,
        map: &mut EdtMap,
        obstacles: &Obstacles<'_>,
        window: &LocalVolume,
        batch: &EdtField,
    ) -> Result<IntegrateReport, CpuError> {
        if batch.dims() != window.dims {
            return Err(CpuError::Unsupported(format!("batch EDT of {:?} voxels for a window of {:?}", batch.dims(), window.dims)));
        }
        let reach = self.cutoff.reach;
        let (written, waves, region) = match self.params.mode {
            IntegrationMode::Wavefront => {
                let packing = Packing::new(Region::around(window, reach + 1), self.cutoff)?;
                let (w, c) = integrate_wavefront(map, window, batch, &packing, &self.offsets, &mut self.waves);
                (w, c, packing.region)
            }
            IntegrationMode::Exact => {
                let packing = Packing::new(Region::around(window, reach), self.cutoff)?;
                let written = integrate_exact(map, obstacles, &packing, &mut self.exact)?;
                self.waves.forget(&written.changed_blocks);
                (written, WaveCounts::default(), packing.region)
            }
        };
        Ok(IntegrateReport {
            voxels_changed: written.voxels_changed,
            change_sum_vox: written.change_sum_vox,
            changed_blocks: written.changed_blocks,
            region_voxels: region.len(),
            waves,
        })
    }
}
