use edtmap_core::CoreError;
use edtmap_cpu::CpuError;
use thiserror::Error;

/// Errors of the mapping pipeline and its configuration.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum MapError {
    /// Bad parameters, pose or measurement.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// The CPU backend refused the input.
    #[error(transparent)]
    Cpu(#[from] CpuError),
    /// The backend failed (no GPU adapter, lost device, device limits).
    #[error(transparent)]
    Backend(#[from] edtmap_core::BackendError),
    /// A map file could not be written or read.
    #[error(transparent)]
    Io(#[from] edtmap_io::IoError),
    /// A configuration file could not be read or parsed.
    #[error("{path}: {message}")]
    ConfigFile {
        /// The file.
        path: String,
        /// What went wrong, with the line and field.
        message: String,
    },
    /// A configuration value is invalid.
    #[error("config [{section}] {source}")]
    Config {
        /// The section holding the bad value.
        section: &'static str,
        /// The problem, naming the field.
        source: CoreError,
    },
}
