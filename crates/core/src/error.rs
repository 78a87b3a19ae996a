use thiserror::Error;

/// Errors raised when building core types from user-supplied sizes or data.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum CoreError {
    /// A grid axis has length zero.
    #[error("grid axis {axis} has length 0 (dimensions {dims:?})")]
    EmptyAxis {
        /// The axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// The dimensions that were asked for.
        dims: [usize; 3],
    },
    /// The grid has more voxels, or longer diagonals, than the 32-bit
    /// indices and squared distances can represent.
    #[error("grid {dims:?} is too large: {reason}")]
    TooLarge {
        /// The dimensions that were asked for.
        dims: [usize; 3],
        /// Which limit was exceeded.
        reason: &'static str,
    },
    /// A data buffer does not have one element per voxel.
    #[error("grid {dims:?} needs {expected} elements, got {actual}")]
    LengthMismatch {
        /// The dimensions of the grid.
        dims: [usize; 3],
        /// Number of voxels the dimensions imply.
        expected: usize,
        /// Number of elements supplied.
        actual: usize,
    },
    /// A parameter is out of its valid range.
    #[error("invalid {field} = {value}: {reason}")]
    InvalidParam {
        /// The parameter's name.
        field: &'static str,
        /// The value given, as text.
        value: String,
        /// What the value must be.
        reason: &'static str,
    },
    /// A job would need more memory than its budget allows
    /// ([`crate::MemoryBudget`]).
    #[error("{what} needs about {}, more than {} ({origin}): {setting}", crate::memory::format_bytes(*needed), crate::memory::format_bytes(*limit))]
    OutOfMemory {
        /// What would be allocated, with the sizes that make it.
        what: String,
        /// Bytes it would need.
        needed: u64,
        /// Bytes the budget allows.
        limit: u64,
        /// Where the budget comes from.
        origin: &'static str,
        /// What to change to need less, or to raise the budget.
        setting: String,
    },
    /// A pose is not a rigid transform.
    #[error("invalid pose: {0}")]
    BadPose(String),
    /// A measurement does not fit the sensor it claims to come from.
    #[error("measurement does not fit the sensor: {0}")]
    BadMeasurement(String),
    /// The requested operation does not apply to this input (projection
    /// from a sensor that cannot project, say).
    #[error("not supported: {0}")]
    Unsupported(String),
}
