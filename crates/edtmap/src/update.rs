//! The global EDT's update after each frame's fusion (paper §IV-B and
//! §IV-C), with the integration mode as a strategy that owns its buffers:
//! the mapper calls [`GlobalUpdate::run`] once a frame, on its backend, and
//! once more on the CPU when the backend failed, whatever the mode.

use crate::stages::{BatchEdtStage, IntegrationStage};
use crate::MapError;
use edtmap_core::{
    Backend, BlockKey, EdtField, GlobalMap, GlobalParams, IntegrationMode, IntegrationReport, LocalVolume, Region,
};
use std::time::Instant;

/// How each frame brings the global EDT up to date.
#[derive(Debug)]
enum Strategy {
    /// The exact EDT of the map's obstacles, updated from the blocks whose
    /// obstacles the frame changed. No batch EDT of the window.
    Exact,
    /// The paper's: the window's batch EDT (Algorithm 1), merged by raise
    /// and lower wavefronts (Algorithms 2 and 3).
    Wavefront {
        /// The window's batch EDT and its buffers (boxed: the exact
        /// strategy holds nothing).
        batch: Box<BatchEdtStage>,
        /// Whether `batch` holds this frame's fields: not when the backend
        /// computed the window's EDT on its device.
        on_host: bool,
    },
}

/// The global EDT's update: the integration stage and its strategy.
#[derive(Debug)]
pub(crate) struct GlobalUpdate {
    stage: IntegrationStage,
    strategy: Strategy,
}

/// What one frame's update did.
#[derive(Debug)]
pub(crate) struct Updated {
    /// The window's batch EDT, ms (0 in exact mode).
    pub(crate) batch_edt_ms: f64,
    /// The integration into the global EDT, ms.
    pub(crate) integrate_ms: f64,
    /// What the integration changed.
    pub(crate) report: IntegrationReport,
}

impl GlobalUpdate {
    /// The update `global` asks for at `voxel_size_m`; the wavefront mode's
    /// batch EDT counts unknown voxels as obstacles in the local field when
    /// `unknown_as_occupied` is set.
    pub(crate) fn new(global: &GlobalParams, voxel_size_m: f64, unknown_as_occupied: bool) -> Result<Self, MapError> {
        let stage = IntegrationStage::new(global, voxel_size_m)?;
        let strategy = match stage.mode() {
            IntegrationMode::Exact => Strategy::Exact,
            IntegrationMode::Wavefront => {
                Strategy::Wavefront { batch: Box::new(BatchEdtStage::new(unknown_as_occupied)), on_host: false }
            }
        };
        Ok(GlobalUpdate { stage, strategy })
    }

    /// Whether the update is exact (the global EDT is the exact EDT of the
    /// map's obstacles after every frame).
    pub(crate) fn is_exact(&self) -> bool {
        matches!(self.strategy, Strategy::Exact)
    }

    /// Brings `map`'s global EDT up to date on `backend` after a frame over
    /// `volume` whose fusion changed the obstacles of the blocks `changed`.
    pub(crate) fn run(
        &mut self,
        backend: &mut dyn Backend,
        map: &mut GlobalMap,
        volume: &LocalVolume,
        changed: &[BlockKey],
    ) -> Result<Updated, MapError> {
        let start = Instant::now();
        let report = match &mut self.strategy {
            Strategy::Exact => {
                let (edt, obstacles) = map.edt_and_obstacles();
                self.stage.apply_changes(backend, edt, obstacles, changed)?
            }
            Strategy::Wavefront { batch, on_host } => {
                // A device computes the window's EDT inside the integration,
                // where it stays; the host computes it otherwise.
                *on_host = false;
                if backend.batch_stays_on_device() {
                    batch.global_mask(map, volume)?;
                } else {
                    batch.run(backend, map, volume)?;
                    *on_host = true;
                }
                let batch_edt_ms = ms_since(start);
                let t = Instant::now();
                let (edt, obstacles) = map.edt_and_obstacles();
                let report = if *on_host {
                    self.stage.merge_window(backend, edt, obstacles, volume, batch.for_global())?
                } else {
                    self.stage.merge_window_mask(backend, edt, obstacles, volume, batch.mask_for_global())?
                };
                return Ok(Updated { batch_edt_ms, integrate_ms: ms_since(t), report });
            }
        };
        Ok(Updated { batch_edt_ms: 0.0, integrate_ms: ms_since(start), report })
    }

    /// The obstacles of the blocks `gone` vanished (map clearing): the
    /// exact update over them. Exact mode only.
    pub(crate) fn apply_changes(
        &self,
        backend: &mut dyn Backend,
        map: &mut GlobalMap,
        gone: &[BlockKey],
    ) -> Result<IntegrationReport, MapError> {
        let (edt, obstacles) = map.edt_and_obstacles();
        Ok(self.stage.apply_changes(backend, edt, obstacles, gone)?)
    }

    /// Recomputes the global EDT exactly within the cutoff of `region`
    /// (fixed obstacles laid down), in either mode.
    pub(crate) fn recompute(
        &self,
        backend: &mut dyn Backend,
        map: &mut GlobalMap,
        region: &Region,
    ) -> Result<IntegrationReport, MapError> {
        let (edt, obstacles) = map.edt_and_obstacles();
        Ok(self.stage.recompute(backend, edt, obstacles, region)?)
    }

    /// The local field the last frame's update computed on the host (the
    /// wavefront mode's batch EDT), if it did.
    pub(crate) fn local_field(&self) -> Option<&EdtField> {
        match &self.strategy {
            Strategy::Wavefront { batch, on_host: true } => Some(batch.local()),
            _ => None,
        }
    }
}

/// Milliseconds since `t`.
pub(crate) fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
