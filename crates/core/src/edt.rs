use crate::grid::coords_of;
use crate::{CoreError, Grid3};

/// Squared distance stored for a voxel when the grid holds no obstacle at
/// all: the "saturated" value of the batch EDT (the CLI writes `inf`).
pub const UNREACHABLE_DIST_SQ: u32 = u32::MAX;

/// Nearest-obstacle index stored for a voxel with no obstacle in the grid.
pub const NO_SITE: u32 = u32::MAX;

/// Parameters of the batch EDT.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EdtParams {
    /// Treat unknown voxels as obstacles (default: unknown counts as free).
    pub unknown_as_occupied: bool,
}

/// Exact Euclidean distance transform of a dense grid.
///
/// For every voxel: the squared distance in voxel units to the nearest
/// obstacle voxel (`0` on obstacles) and that obstacle's linear index.
/// Voxels of a grid without obstacles hold [`UNREACHABLE_DIST_SQ`] and
/// [`NO_SITE`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EdtField {
    dims: [usize; 3],
    dist_sq_vox: Vec<u32>,
    nearest: Vec<u32>,
}

impl Default for EdtField {
    /// [`EdtField::empty`].
    fn default() -> Self {
        EdtField::empty()
    }
}

impl EdtField {
    /// Checks that a grid of `dims` fits the field's 32-bit storage: every
    /// linear index below [`NO_SITE`] and every squared distance below
    /// [`UNREACHABLE_DIST_SQ`]. Returns the voxel count.
    pub fn check_dims(dims: [usize; 3]) -> Result<usize, CoreError> {
        let count = Grid3::<()>::voxel_count(dims)?;
        if count >= NO_SITE as usize {
            return Err(CoreError::TooLarge { dims, reason: "more than 2^32 - 2 voxels" });
        }
        let diag_sq: u64 = dims.iter().map(|&n| (n as u64 - 1).pow(2)).sum();
        if diag_sq >= u64::from(UNREACHABLE_DIST_SQ) {
            return Err(CoreError::TooLarge { dims, reason: "squared diagonal does not fit in 32 bits" });
        }
        Ok(count)
    }

    /// Assembles a field from per-voxel squared distances and nearest
    /// obstacle indices (both in linear order).
    pub fn from_parts(dims: [usize; 3], dist_sq_vox: Vec<u32>, nearest: Vec<u32>) -> Result<Self, CoreError> {
        let expected = Self::check_dims(dims)?;
        for actual in [dist_sq_vox.len(), nearest.len()] {
            if actual != expected {
                return Err(CoreError::LengthMismatch { dims, expected, actual });
            }
        }
        Ok(EdtField { dims, dist_sq_vox, nearest })
    }

    /// An empty field (dimensions `[0, 0, 0]`), to be filled by
    /// [`prepare`](Self::prepare) and a backend; reusing one field across
    /// frames avoids reallocating and re-faulting its memory.
    pub fn empty() -> Self {
        EdtField { dims: [0; 3], dist_sq_vox: Vec::new(), nearest: Vec::new() }
    }

    /// Resizes the field for a grid of `dims`, keeping its allocations, and
    /// returns its squared distances and nearest indices for a backend to
    /// overwrite entirely (their contents are unspecified until then).
    pub fn prepare(&mut self, dims: [usize; 3]) -> Result<(&mut [u32], &mut [u32]), CoreError> {
        let count = Self::check_dims(dims)?;
        // A grid too large for the memory left is an error, not an abort.
        for buf in [&mut self.dist_sq_vox, &mut self.nearest] {
            if buf.try_reserve_exact(count.saturating_sub(buf.len())).is_err() {
                return Err(CoreError::OutOfMemory {
                    what: format!("the EDT field of a {dims:?} grid"),
                    needed: count as u64 * 8,
                    limit: crate::MemoryBudget::with_limit(u64::MAX).limit_bytes().unwrap_or(0),
                    origin: "the allocator refused it",
                    setting: "transform a smaller grid".to_string(),
                });
            }
        }
        self.dims = dims;
        self.dist_sq_vox.resize(count, UNREACHABLE_DIST_SQ);
        self.nearest.resize(count, NO_SITE);
        Ok((&mut self.dist_sq_vox, &mut self.nearest))
    }

    /// Dimensions `[nx, ny, nz]` in voxels.
    #[inline]
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Squared distances in voxel units, linear order.
    #[inline]
    pub fn dist_sq_vox(&self) -> &[u32] {
        &self.dist_sq_vox
    }

    /// Linear index of each voxel's nearest obstacle ([`NO_SITE`] if none).
    #[inline]
    pub fn nearest(&self) -> &[u32] {
        &self.nearest
    }

    /// Distance in voxels of voxel `linear`; `f32::INFINITY` with no obstacle.
    #[inline]
    pub fn distance_vox(&self, linear: usize) -> f32 {
        dist_sq_to_vox(self.dist_sq_vox[linear])
    }

    /// Coordinates `[x, y, z]` of the nearest obstacle of voxel `linear`.
    #[inline]
    pub fn nearest_coords(&self, linear: usize) -> Option<[usize; 3]> {
        let site = self.nearest[linear];
        (site != NO_SITE).then(|| coords_of(self.dims, site as usize))
    }

    /// Consumes the field, returning `(dist_sq_vox, nearest)`.
    pub fn into_parts(self) -> (Vec<u32>, Vec<u32>) {
        (self.dist_sq_vox, self.nearest)
    }
}

/// Converts a stored squared distance to a distance in voxels
/// (`f32::INFINITY` for [`UNREACHABLE_DIST_SQ`]).
#[inline]
pub fn dist_sq_to_vox(dist_sq: u32) -> f32 {
    if dist_sq == UNREACHABLE_DIST_SQ {
        f32::INFINITY
    } else {
        (dist_sq as f64).sqrt() as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dims_limits() {
        assert!(EdtField::check_dims([256, 256, 256]).is_ok());
        assert!(EdtField::check_dims([46341, 46341, 1]).is_ok());
        assert!(EdtField::check_dims([46342, 46342, 1]).is_err());
        assert!(EdtField::check_dims([1 << 16, 1 << 16, 1]).is_err());
        assert!(EdtField::check_dims([0, 3, 3]).is_err());
    }

    #[test]
    fn unreachable_is_infinite() {
        assert_eq!(dist_sq_to_vox(UNREACHABLE_DIST_SQ), f32::INFINITY);
        assert_eq!(dist_sq_to_vox(25), 5.0);
    }
}
