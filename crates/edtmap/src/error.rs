use edtmap_core::CoreError;
use edtmap_cpu::CpuError;
use std::fmt;

/// Errors of the mapping pipeline and its configuration.
///
/// Each message is whole on its own: `Display` says everything, and
/// `source()` returns only causes that `Display` does not already spell
/// out, so a printed chain (anyhow's `{:#}`) never repeats a message.
#[derive(Debug)]
#[non_exhaustive]
pub enum MapError {
    /// Bad parameters, pose or measurement.
    Core(CoreError),
    /// The CPU backend refused the input.
    Cpu(CpuError),
    /// The backend failed (no GPU adapter, lost device, device limits).
    Backend(edtmap_core::BackendError),
    /// A map file could not be written or read.
    Io(edtmap_io::IoError),
    /// A configuration file could not be read or parsed.
    ConfigFile {
        /// The file.
        path: String,
        /// What went wrong, with the line and field.
        message: String,
    },
    /// A configuration value is invalid; the message includes `source`'s.
    Config {
        /// The section holding the bad value.
        section: &'static str,
        /// The problem, naming the field.
        source: CoreError,
    },
    /// A thread panicked while it held this (a [`crate::SharedMapper`]'s
    /// mapper or snapshot); what it guards may be half-updated.
    Poisoned(&'static str),
    /// The GPU backend was asked for in a build without the `gpu` feature.
    NoGpuBackend,
    /// A backend name other than `cpu`, `gpu` or `auto`.
    UnknownBackend(String),
}

impl fmt::Display for MapError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MapError::Core(e) => e.fmt(f),
            MapError::Cpu(e) => e.fmt(f),
            MapError::Backend(e) => e.fmt(f),
            MapError::Io(e) => e.fmt(f),
            MapError::ConfigFile { path, message } => write!(f, "{path}: {message}"),
            MapError::Config { section, source } => write!(f, "config [{section}] {source}"),
            MapError::Poisoned(what) => write!(f, "{what} was left half-updated by a panic in another thread; make a new mapper (saving this one's map first may keep what it had)"),
            MapError::NoGpuBackend => write!(f, "this build of edtmap has no GPU backend (it was built without the `gpu` feature)"),
            MapError::UnknownBackend(name) => write!(f, "backend must be 'cpu', 'gpu' or 'auto', not {name:?}"),
        }
    }
}

impl std::error::Error for MapError {
    // The wrapped errors are transparent (their message is this one), and
    // `Config` prints its cause: none of them is a further source.
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            MapError::Core(e) => e.source(),
            MapError::Cpu(e) => e.source(),
            MapError::Backend(e) => e.source(),
            MapError::Io(e) => e.source(),
            MapError::ConfigFile { .. }
            | MapError::Config { .. }
            | MapError::Poisoned(_)
            | MapError::NoGpuBackend
            | MapError::UnknownBackend(_) => None,
        }
    }
}

impl From<CoreError> for MapError {
    fn from(e: CoreError) -> Self {
        MapError::Core(e)
    }
}

/// A CPU stage's backend error (a GPU lost during ray casting or
/// projection) is a backend failure like any other, so a lost device is
/// never taken for bad input.
impl From<CpuError> for MapError {
    fn from(e: CpuError) -> Self {
        match e {
            CpuError::Backend(b) => MapError::Backend(b),
            other => MapError::Cpu(other),
        }
    }
}

impl MapError {
    /// Whether the backend itself failed (a lost device, say): mapping on
    /// it cannot go on, whatever the frame.
    pub fn is_backend_failure(&self) -> bool {
        matches!(self, MapError::Backend(_))
    }
}

/// Bad input a backend refused is the frame's error, not the backend's.
impl From<edtmap_core::BackendError> for MapError {
    fn from(e: edtmap_core::BackendError) -> Self {
        match e {
            edtmap_core::BackendError::Core(c) => MapError::Core(c),
            other => MapError::Backend(other),
        }
    }
}

impl From<edtmap_io::IoError> for MapError {
    fn from(e: edtmap_io::IoError) -> Self {
        MapError::Io(e)
    }
}
