use edtmap_core::CoreError;
use thiserror::Error;

/// Errors of the CPU backend.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum CpuError {
    /// The input grid or parameters were rejected by a core type.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// Another backend failed at a stage it took over.
    #[error(transparent)]
    Backend(#[from] edtmap_core::BackendError),
    /// The requested operation does not apply to this input.
    #[error("not supported: {0}")]
    Unsupported(String),
}
