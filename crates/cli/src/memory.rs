//! The run's memory budget: `--max-memory`, else the config's
//! `[memory] max`, else what the system has (see
//! `edtmap_core::memory`).

use std::sync::OnceLock;

use anyhow::Result;
use edtmap::MemoryBudget;

/// `--max-memory`, parsed, set once by `main`.
static MAX_MEMORY: OnceLock<Option<u64>> = OnceLock::new();

/// Records `--max-memory` for the command.
pub(crate) fn set_max(bytes: Option<u64>) {
    let _ = MAX_MEMORY.set(bytes);
}

/// `--max-memory` in bytes, if given.
pub(crate) fn max_bytes() -> Option<u64> {
    MAX_MEMORY.get().copied().flatten()
}

/// The budget of a job not configured by a file.
pub(crate) fn budget() -> MemoryBudget {
    max_bytes().map_or_else(MemoryBudget::from_system, MemoryBudget::with_limit)
}

/// Fails with a message naming `what` and `setting` if `needed` bytes
/// exceed the budget.
pub(crate) fn ensure_fits(what: &str, needed: u64, setting: &str) -> Result<()> {
    Ok(budget().check(what, needed, setting)?)
}
