//! Memory for the transforms' outputs: checked against the room the
//! process has before it is taken, and taken fallibly, so that an array too
//! large raises `MemoryError` instead of aborting the interpreter.

use edtmap_core::memory::format_bytes;
use edtmap_core::MemoryBudget;
use pyo3::exceptions::PyMemoryError;
use pyo3::{PyErr, PyResult};
use rayon::prelude::*;

/// The shape as Python writes it.
fn py_shape(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")),
    }
}

fn memory_error(shape: &[usize], needed: u64, why: &str) -> PyErr {
    PyMemoryError::new_err(format!(
        "the distance transform of an array of shape {} needs {needed} bytes ({}) besides the input: {why}",
        py_shape(shape),
        format_bytes(needed),
    ))
}

/// Refuses `needed` bytes for an array of `shape` where the address-space
/// limit (`RLIMIT_AS`) leaves less room. Other limits are the system's:
/// SciPy and the `edt` package are not refused more either.
pub(crate) fn check_memory(shape: &[usize], needed: u64) -> PyResult<()> {
    let budget = MemoryBudget::with_limit(u64::MAX);
    match budget.limit_bytes() {
        Some(room) if needed > room => Err(memory_error(
            shape,
            needed,
            &format!("only {} are left under the address-space limit (RLIMIT_AS)", format_bytes(room)),
        )),
        _ => Ok(()),
    }
}

/// `n` copies of `fill`, or `MemoryError` if the allocator refuses them.
pub(crate) fn try_vec<V: Copy + Send + Sync>(n: usize, fill: V, shape: &[usize]) -> PyResult<Vec<V>> {
    let mut v = Vec::new();
    let bytes = (n as u64).saturating_mul(std::mem::size_of::<V>() as u64);
    v.try_reserve_exact(n).map_err(|_| memory_error(shape, bytes, "the allocation failed"))?;
    v.par_extend(rayon::iter::repeat_n(fill, n));
    Ok(v)
}
