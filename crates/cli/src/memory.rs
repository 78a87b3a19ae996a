//! A check that a job fits in the memory the machine has free.

use anyhow::{bail, Result};

/// Bytes of memory available to new allocations, where the system says
/// (Linux `MemAvailable`); `None` elsewhere.
fn available_bytes() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Fails with a message naming `what` if `needed` bytes exceed the
/// available memory.
pub(crate) fn ensure_fits(what: &str, needed: u64) -> Result<()> {
    if let Some(avail) = available_bytes() {
        if needed > avail {
            let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
            bail!(
                "{what} needs about {:.1} GiB of memory, only {:.1} GiB is available",
                gib(needed),
                gib(avail)
            );
        }
    }
    Ok(())
}
