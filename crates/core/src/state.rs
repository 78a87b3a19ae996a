/// Occupancy state of one voxel, as the occupancy stage classifies it.
///
/// `#[repr(u8)]` so that state grids can be shared with GPU buffers as bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum VoxelState {
    /// Never observed.
    #[default]
    Unknown = 0,
    /// Observed and free.
    Free = 1,
    /// Observed and occupied: an obstacle for the EDT.
    Occupied = 2,
}

impl VoxelState {
    /// Whether the EDT treats this voxel as an obstacle (a site).
    ///
    /// Unknown voxels are free unless `unknown_as_occupied` is set.
    #[inline]
    pub fn is_obstacle(self, unknown_as_occupied: bool) -> bool {
        match self {
            VoxelState::Occupied => true,
            VoxelState::Unknown => unknown_as_occupied,
            VoxelState::Free => false,
        }
    }
}
