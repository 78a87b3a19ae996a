//! The batch EDT stage (paper §IV-B, Algorithm 1): the exact EDT of the
//! local volume's obstacles on the backend, into the local field the
//! planners read, and, when unknown voxels count as obstacles locally,
//! the second field the global integration needs (unknown voxels free).

use edtmap_core::region::fill_mask;
use edtmap_core::{BackendError, BatchEdt, CoreError, EdtField, GlobalMap, Grid3, LocalVolume};

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
    pub fn run<B: BatchEdt + ?Sized>(
        &mut self,
        backend: &mut B,
        map: &GlobalMap,
        volume: &LocalVolume,
    ) -> Result<(), BackendError> {
        local_into(backend, map, volume, self.unknown_as_occupied, &mut self.mask, &mut self.field)?;
        if let Some((mask, field)) = &mut self.global {
            local_into(backend, map, volume, false, mask, field)?;
        }
        Ok(())
    }

    /// The window's obstacles as the global integration counts them
    /// (unknown voxels free), without their EDT: for a backend that
    /// computes it where it integrates ([`edtmap_core::IntegrationWork::WavefrontMask`]).
    /// [`Self::local`] and [`Self::for_global`] then hold an older frame's.
    pub fn global_mask(&mut self, map: &GlobalMap, volume: &LocalVolume) -> Result<&Grid3<bool>, CoreError> {
        let mut obstacles = map.obstacles();
        obstacles.unknown_as_occupied = false;
        let mask = match &mut self.global {
            Some((mask, _)) => mask,
            None => &mut self.mask,
        };
        fill_mask(&obstacles, &volume.region(), mask)?;
        Ok(mask)
    }

    /// The mask [`Self::global_mask`] filled last.
    pub fn mask_for_global(&self) -> &Grid3<bool> {
        self.global.as_ref().map_or(&self.mask, |(m, _)| m)
    }

    /// The local field: exact EDT of the latest volume, in its voxel units.
    pub fn local(&self) -> &EdtField {
        &self.field
    }

    /// The field the global integration merges (unknown voxels free).
    pub fn for_global(&self) -> &EdtField {
        self.global.as_ref().map_or(&self.field, |(_, f)| f)
    }
}

/// The local field alone (what [`BatchEdtStage::local`] holds after a
/// run), in fresh buffers: for a caller that needs it only sometimes.
pub fn local_field<B: BatchEdt + ?Sized>(
    backend: &mut B,
    map: &GlobalMap,
    volume: &LocalVolume,
    unknown_as_occupied: bool,
) -> Result<EdtField, BackendError> {
    let (mut mask, mut field) = (Grid3::default(), EdtField::empty());
    local_into(backend, map, volume, unknown_as_occupied, &mut mask, &mut field)?;
    Ok(field)
}

/// The batch EDT of `volume`'s obstacles, unknown voxels obstacles when
/// `unknown_as_occupied`, into `field` through `mask`.
fn local_into<B: BatchEdt + ?Sized>(
    backend: &mut B,
    map: &GlobalMap,
    volume: &LocalVolume,
    unknown_as_occupied: bool,
    mask: &mut Grid3<bool>,
    field: &mut EdtField,
) -> Result<(), BackendError> {
    let mut obstacles = map.obstacles();
    obstacles.unknown_as_occupied = unknown_as_occupied;
    fill_mask(&obstacles, &volume.region(), mask)?;
    backend.batch_edt(mask, field)
}
