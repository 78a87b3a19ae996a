//! The run's memory budget: `--max-memory`, else the config's
//! `[memory] max`, else what the system has (see
//! `edtmap_core::memory`); and the process's peak working set, for
//! `report.json`.

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

/// The process's peak resident set so far, bytes: `VmHWM` of
/// `/proc/self/status` (Linux); `None` where that is unavailable.
pub(crate) fn peak_rss_bytes() -> Option<u64> {
    parse_vm_hwm(&std::fs::read_to_string("/proc/self/status").ok()?)
}

/// `VmHWM` of a `/proc/PID/status` text, bytes (the kernel writes kB).
fn parse_vm_hwm(status: &str) -> Option<u64> {
    let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    let kib: u64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
    kib.checked_mul(1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vm_hwm_is_read_in_bytes() {
        let status = "Name:\tedtmap\nVmPeak:\t  20000 kB\nVmHWM:\t    1536 kB\nVmRSS:\t 1000 kB\n";
        assert_eq!(parse_vm_hwm(status), Some(1536 * 1024));
        assert_eq!(parse_vm_hwm("Name:\tedtmap\n"), None);
        assert_eq!(parse_vm_hwm("VmHWM:\t lots kB\n"), None);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn this_process_has_a_peak() {
        assert!(peak_rss_bytes().is_some_and(|b| b > 0));
    }
}
