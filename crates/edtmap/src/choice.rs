//! Which backend runs a mapper's stages: one choice for the command line,
//! the Python package and the C API.

use crate::cpu::CpuBackend;
use crate::{Backend, MapError};
use std::str::FromStr;

/// A backend behind a box, as a mapper that chooses it at run time holds
/// it.
pub type DynBackend = Box<dyn Backend + Send>;

/// A backend choice: `cpu`, `gpu` or `auto`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BackendChoice {
    /// The CPU backend (rayon), the reference.
    #[default]
    Cpu,
    /// The wgpu backend (builds with the `gpu` feature).
    Gpu,
    /// A hardware GPU where there is one, else the CPU (also for maps only
    /// the CPU integrates, and in builds without the `gpu` feature).
    Auto,
}

impl FromStr for BackendChoice {
    type Err = MapError;

    fn from_str(s: &str) -> Result<Self, MapError> {
        match s {
            "cpu" => Ok(BackendChoice::Cpu),
            "gpu" => Ok(BackendChoice::Gpu),
            "auto" => Ok(BackendChoice::Auto),
            other => Err(MapError::UnknownBackend(other.to_string())),
        }
    }
}

/// An opened backend, and why `auto` took the CPU where it did.
pub struct OpenedBackend {
    /// The backend.
    pub backend: DynBackend,
    /// Why `auto` chose the CPU (no GPU, a software adapter, a planar map,
    /// a build without the `gpu` feature), for the caller to log.
    pub fell_back: Option<String>,
}

impl std::fmt::Debug for OpenedBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OpenedBackend")
            .field("backend", &self.backend.name())
            .field("fell_back", &self.fell_back)
            .finish()
    }
}

/// Opens `choice` for a mapper whose map is planar or not
/// ([`crate::GlobalParams::planar`]: integrated on the CPU only); `cpu` is
/// the CPU backend to use (its batch EDT's layout, say). `gpu` fails where
/// the build has no GPU backend ([`MapError::NoGpuBackend`]), no adapter
/// opens, or the map is planar; `auto` then takes the CPU and says why.
pub fn open_backend(choice: BackendChoice, cpu: CpuBackend, planar: bool) -> Result<OpenedBackend, MapError> {
    let fell_back = match choice {
        BackendChoice::Cpu => None,
        BackendChoice::Gpu if planar => {
            return Err(MapError::Core(edtmap_core::CoreError::Unsupported(
                "a planar map ([global] planar = true) on the GPU backend; it is integrated on the CPU".into(),
            )))
        }
        BackendChoice::Auto if planar => Some("a planar map is integrated on the CPU".to_string()),
        BackendChoice::Gpu => return Ok(OpenedBackend { backend: gpu()?.0, fell_back: None }),
        BackendChoice::Auto => match gpu() {
            Ok((_, Some(adapter))) => Some(format!("{adapter} is a software adapter")),
            Ok((backend, None)) => return Ok(OpenedBackend { backend, fell_back: None }),
            Err(e) => Some(e.to_string()),
        },
    };
    Ok(OpenedBackend { backend: Box::new(cpu), fell_back })
}

/// The GPU backend, with its adapter's name where that is a software one.
#[cfg(feature = "gpu")]
fn gpu() -> Result<(DynBackend, Option<String>), MapError> {
    let gpu = edtmap_gpu::GpuBackend::new().map_err(MapError::Backend)?;
    let software = gpu.context().is_software().then(|| gpu.context().name());
    Ok((Box::new(gpu), software))
}

#[cfg(not(feature = "gpu"))]
fn gpu() -> Result<(DynBackend, Option<String>), MapError> {
    Err(MapError::NoGpuBackend)
}
