//! The batch EDT stage (paper §IV-B, Algorithm 1): the exact EDT of the
//! local volume's obstacles on the backend, into the local field the
//! planners read, and, when unknown voxels count as obstacles locally,
//! the second field the global integration needs (unknown voxels free).

use crate::region::fill_mask;
use crate::{BackendError, BatchEdt, EdtField, GlobalMap, Grid3, LocalVolume};

/// The batch EDT stage, owning its masks and fields across frames.
#[derive(Debug)]
pub struct BatchEdtStage {
    unknown_as_occupied: bool,
    mask: Grid3<bool>,
    field: EdtField,
    /// With unknown voxels obstacles locally: the mask and field with them
    /// free, for the global integration.
    global: Option<(Grid3<bool>, EdtField)>,
}

impl BatchEdtStage {
    /// A stage that counts unknown voxels as obstacles in the local field
    /// when `unknown_as_occupied` is set.
    pub fn new(unknown_as_occupied: bool) -> Self {
        BatchEdtStage {
            unknown_as_occupied,
            mask: Grid3::default(),
            field: EdtField::empty(),
            global: unknown_as_occupied.then(|| (Grid3::default(), EdtField::empty())),
        }
    }

    /// The exact EDT of `volume`'s obstacles in `map`, on `backend`.
    pub fn run<B: BatchEdt + ?Sized>(&mut self, backend: &mut B, map: &GlobalMap, volume: &LocalVolume) -> Result<(), BackendError> {
        let region = volume.region();
        let mut obstacles = map.obstacles();
        obstacles.unknown_as_occupied = self.unknown_as_occupied;
        fill_mask(&obstacles, &region, &mut self.mask)?;
        backend.batch_edt(&self.mask, &mut self.field)?;
        if let Some((mask, field)) = &mut self.global {
            fill_mask(&map.obstacles(), &region, mask)?;
            backend.batch_edt(mask, field)?;
        }
        Ok(())
    }

    /// The local field: exact EDT of the latest volume, in its voxel units.
    pub fn local(&self) -> &EdtField {
        &self.field
    }

    /// Gives the local field up.
    pub fn into_local(self) -> EdtField {
        self.field
    }

    /// The field the global integration merges (unknown voxels free).
    pub fn for_global(&self) -> &EdtField {
        self.global.as_ref().map_or(&self.field, |(_, f)| f)
    }
}
