//! `edtmap._edtmap`, the compiled core of the `edtmap` Python package.
//!
//! The package itself (python/edtmap) checks arguments, normalises numpy
//! layouts and documents the API; this module does the work with the GIL
//! released.

use pyo3::prelude::*;

mod labelled;
mod mapper;
mod memory;
mod recording;
mod transforms;

/// The extension module.
#[pymodule]
fn _edtmap(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(transforms::transform, m)?)?;
    m.add_class::<mapper::PyMapper>()?;
    m.add_class::<recording::PyRecording>()?;
    Ok(())
}
