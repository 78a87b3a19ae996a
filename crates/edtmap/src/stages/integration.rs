//! The integration stage (paper §IV-C): each frame's batch EDT of the local
//! window merged into the unbounded global EDT on the backend, so that
//! obstacles which appeared or vanished, inside or outside the window, are
//! reflected everywhere within the cutoff.
//!
//! Two modes ([`IntegrationMode`]): the paper's wavefronts and an exact
//! recomputation of the region the frame can affect. Both work on a dense
//! copy of that region ([`edtmap_core::region`]) and write back only the voxels
//! that changed, returning the blocks they touched.

use edtmap_core::region::Region;
use edtmap_core::{
    Backend, BackendError, BlockKey, CoreError, Cutoff, EdtField, EdtMap, GlobalParams, Grid3, IntegrationJob,
    IntegrationMode, IntegrationReport, IntegrationWork, LocalVolume, Obstacles,
};

/// Side of the tiles [`IntegrationStage::recompute`] works in, voxels: the
/// memory it needs stays bounded whatever the box.
const TILE: usize = 128;

/// The integration stage: what each frame's job is, from the parameters.
#[derive(Debug, Clone)]
pub struct IntegrationStage {
    mode: IntegrationMode,
    cutoff: Cutoff,
    offsets: Vec<[i32; 3]>,
}

impl IntegrationStage {
    /// A stage for voxels of `voxel_size_m`; fails on a bad cutoff.
    pub fn new(params: &GlobalParams, voxel_size_m: f64) -> Result<Self, CoreError> {
        Ok(IntegrationStage {
            mode: params.mode,
            cutoff: params.cutoff(voxel_size_m)?,
            offsets: params.connectivity.offsets(),
        })
    }

    /// The cutoff in voxels.
    pub fn cutoff(&self) -> Cutoff {
        self.cutoff
    }

    /// The integration mode.
    pub fn mode(&self) -> IntegrationMode {
        self.mode
    }

    /// Merges the frame whose window is `window` into `map` on `backend`.
    /// `batch` is the exact EDT of `window` with `obstacles` (unknown
    /// voxels free), used by the wavefront mode; the exact mode reads
    /// `obstacles` directly and looks for changes in every block of the
    /// window ([`Self::apply_changes`] with the blocks a frame changed is the
    /// mapper's way).
    pub fn merge_window<B: Backend + ?Sized>(
        &self,
        backend: &mut B,
        map: &mut EdtMap,
        obstacles: Obstacles<'_>,
        window: &LocalVolume,
        batch: &EdtField,
    ) -> Result<IntegrationReport, BackendError> {
        let work = IntegrationWork::Wavefront { window, batch, offsets: &self.offsets };
        self.wavefront(backend, map, obstacles, window, ("batch EDT", batch.dims()), work)
    }

    /// Wavefront mode, with the batch EDT of `mask` (the window's
    /// obstacles, unknown voxels free) computed by `backend` itself, where
    /// its integration reads it ([`IntegrationWork::WavefrontMask`]).
    pub fn merge_window_mask<B: Backend + ?Sized>(
        &self,
        backend: &mut B,
        map: &mut EdtMap,
        obstacles: Obstacles<'_>,
        window: &LocalVolume,
        mask: &Grid3<bool>,
    ) -> Result<IntegrationReport, BackendError> {
        let work = IntegrationWork::WavefrontMask { window, mask, offsets: &self.offsets };
        self.wavefront(backend, map, obstacles, window, ("obstacle mask", mask.dims()), work)
    }

    /// `work` (a wavefront job over `window`, whose input, `what`, has
    /// `dims` voxels) in wavefront mode; in exact mode an update of every
    /// block of the window.
    fn wavefront<B: Backend + ?Sized>(
        &self,
        backend: &mut B,
        map: &mut EdtMap,
        obstacles: Obstacles<'_>,
        window: &LocalVolume,
        (what, dims): (&str, [usize; 3]),
        work: IntegrationWork<'_>,
    ) -> Result<IntegrationReport, BackendError> {
        if dims != window.dims {
            return Err(
                CoreError::Unsupported(format!("{what} of {dims:?} voxels for a window of {:?}", window.dims)).into()
            );
        }
        match self.mode {
            IntegrationMode::Wavefront => {
                backend.integrate(IntegrationJob { map, obstacles, cutoff: self.cutoff, work })
            }
            IntegrationMode::Exact => self.apply_changes(backend, map, obstacles, &window.region().blocks()),
        }
    }

    /// Exact mode: brings `map` up to date with `obstacles`, which changed
    /// only inside the blocks `changed` (a frame's `FuseReport`), on
    /// `backend`. Needs no batch EDT of the window.
    pub fn apply_changes<B: Backend + ?Sized>(
        &self,
        backend: &mut B,
        map: &mut EdtMap,
        obstacles: Obstacles<'_>,
        changed: &[BlockKey],
    ) -> Result<IntegrationReport, BackendError> {
        backend.integrate(IntegrationJob {
            map,
            obstacles,
            cutoff: self.cutoff,
            work: IntegrationWork::Changes { blocks: changed },
        })
    }

    /// Recomputes exactly every voxel within the cutoff of the box `bounds`
    /// (forbidden zones, a prior map laid down), in tiles of at most
    /// `TILE`³ voxels so memory stays bounded (`TILE`² by one layer on a
    /// planar map).
    pub fn recompute<B: Backend + ?Sized>(
        &self,
        backend: &mut B,
        map: &mut EdtMap,
        obstacles: Obstacles<'_>,
        bounds: &Region,
    ) -> Result<IntegrationReport, BackendError> {
        let mut total = IntegrationReport::default();
        // A planar map's tiles are one layer thick: a batch EDT of one
        // layer measures distances within it.
        let tile_dims = [TILE, TILE, if self.cutoff.planar { 1 } else { TILE }];
        for z in (0..bounds.dims[2]).step_by(tile_dims[2]) {
            for y in (0..bounds.dims[1]).step_by(tile_dims[1]) {
                for x in (0..bounds.dims[0]).step_by(tile_dims[0]) {
                    let c = [x, y, z];
                    let tile = Region {
                        origin: [0, 1, 2].map(|a| bounds.origin[a] + c[a] as i32),
                        dims: [0, 1, 2].map(|a| tile_dims[a].min(bounds.dims[a] - c[a])),
                    };
                    let work = IntegrationWork::Recompute { region: tile.grown_by(self.cutoff.pad()) };
                    let w = backend.integrate(IntegrationJob { map, obstacles, cutoff: self.cutoff, work })?;
                    total.voxels_changed += w.voxels_changed;
                    total.change_sum_vox += w.change_sum_vox;
                    total.changed_blocks.extend(w.changed_blocks);
                    total.region_voxels += w.region_voxels;
                }
            }
        }
        total.changed_blocks.sort_unstable();
        total.changed_blocks.dedup();
        Ok(total)
    }
}
