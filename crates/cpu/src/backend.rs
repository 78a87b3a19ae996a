//! [`CpuBackend`]: the CPU as a [`Backend`] of the mapper.

use crate::edt::{edt_into, ScanLayout};
use crate::CpuError;
use edtmap_core::{Backend, BackendError, BatchEdt, EdtField, Grid3};

/// Every stage on all cores with rayon; the reference backend.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CpuBackend {
    /// Memory layout of the batch EDT's scans.
    pub layout: ScanLayout,
}

impl BatchEdt for CpuBackend {
    fn batch_edt(&mut self, mask: &Grid3<bool>, out: &mut EdtField) -> Result<(), BackendError> {
        edt_into(mask, |&o| o, self.layout, out).map_err(BackendError::from)
    }
}

impl Backend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu ({} threads)", rayon::current_num_threads())
    }
}

impl From<CpuError> for BackendError {
    fn from(e: CpuError) -> Self {
        match e {
            CpuError::Core(c) => BackendError::Core(c),
            CpuError::Backend(b) => b,
            other => BackendError::Device(other.to_string()),
        }
    }
}
