//! A memory budget: every allocation whose size comes from input (a
//! window's voxel count, a grid's shape) is checked against it before it
//! happens, and refused with an error that says how much would be needed
//! and which setting to change, instead of aborting the process.
//!
//! The budget is what the system can give: 80 % of `MemAvailable` (Linux), and
//! the room left under the process's address-space limit (`RLIMIT_AS`,
//! `prlimit --as`, `ulimit -v`), read from `/proc/self/limits` and
//! `/proc/self/status`. A limit set by the user (`--max-memory`, the
//! config's `[memory] max`) replaces `MemAvailable`; the
//! address-space limit always applies, since going past it can only abort.

use crate::CoreError;

/// How much memory a job may use, and where that figure comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryBudget {
    /// Bytes; `None` when no limit is known.
    limit_bytes: Option<u64>,
    /// What set the limit, for messages.
    origin: &'static str,
}

impl Default for MemoryBudget {
    fn default() -> Self {
        Self::from_system()
    }
}

impl MemoryBudget {
    /// No limit at all (the system's still applies to the allocator).
    pub fn unlimited() -> Self {
        MemoryBudget { limit_bytes: None, origin: "no limit" }
    }

    /// What the system can give now: the smaller of 80 % of `MemAvailable`
    /// (the rest is left to the system and the allocator's slack) and the
    /// room under `RLIMIT_AS`; unlimited where neither is known.
    pub fn from_system() -> Self {
        let avail = available_bytes().map(|b| (b / 5 * 4, "80 % of the available memory (MemAvailable)"));
        let room = address_space_room().map(|b| (b, "the room left under the address-space limit (RLIMIT_AS)"));
        match (avail, room) {
            (Some(a), Some(r)) => Self::from_pair(if r.0 < a.0 { r } else { a }),
            (Some(x), None) | (None, Some(x)) => Self::from_pair(x),
            (None, None) => Self::unlimited(),
        }
    }

    /// A limit of `bytes` set by the user, capped by the room under
    /// `RLIMIT_AS`.
    pub fn with_limit(bytes: u64) -> Self {
        match address_space_room() {
            Some(r) if r < bytes => Self::from_pair((r, "the room left under the address-space limit (RLIMIT_AS)")),
            _ => Self::from_pair((bytes, "the memory limit set (--max-memory / [memory] max)")),
        }
    }

    fn from_pair((bytes, origin): (u64, &'static str)) -> Self {
        MemoryBudget { limit_bytes: Some(bytes), origin }
    }

    /// The limit in bytes, if any.
    pub fn limit_bytes(&self) -> Option<u64> {
        self.limit_bytes
    }

    /// Refuses `needed` bytes for `what` if they exceed the budget;
    /// `setting` names what the user can change to need less.
    pub fn check(&self, what: &str, needed: u64, setting: &str) -> Result<(), CoreError> {
        match self.limit_bytes {
            Some(limit) if needed > limit => Err(CoreError::OutOfMemory {
                what: what.to_string(),
                needed,
                limit,
                origin: self.origin,
                setting: setting.to_string(),
            }),
            _ => Ok(()),
        }
    }
}

/// `bytes` in the largest binary unit that keeps it readable, e.g. `1.5 GiB`.
pub fn format_bytes(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", UNITS[unit])
    }
}

/// Parses a size such as `8G`, `512MiB`, `1.5 GB` or `1000000` (bytes).
/// Units are binary (`K`, `M`, `G`, `T`, with or without `iB`/`B`).
pub fn parse_size(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let split = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (num, unit) = (t[..split].trim(), t[split..].trim());
    let value: f64 = num.parse().map_err(|_| format!("{text:?} is not a size (examples: 8G, 512M, 1000000)"))?;
    let scale: u64 = match unit.to_ascii_lowercase().as_str() {
        "" | "b" => 1,
        "k" | "kb" | "kib" => 1 << 10,
        "m" | "mb" | "mib" => 1 << 20,
        "g" | "gb" | "gib" => 1 << 30,
        "t" | "tb" | "tib" => 1 << 40,
        _ => return Err(format!("{text:?}: unknown unit {unit:?} (use K, M, G or T)")),
    };
    let bytes = value * scale as f64;
    if !bytes.is_finite() || bytes < 1.0 || bytes > u64::MAX as f64 {
        return Err(format!("{text:?} is not a size of at least one byte"));
    }
    Ok(bytes as u64)
}

/// Bytes available to new allocations (Linux `MemAvailable`).
fn available_bytes() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    kib_field(&info, "MemAvailable:")
}

/// Bytes the process may still map under its soft `RLIMIT_AS`.
fn address_space_room() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = limits.lines().find(|l| l.starts_with("Max address space"))?;
    let soft = line.split_whitespace().nth(3)?;
    let limit: u64 = soft.parse().ok()?; // "unlimited" does not parse
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let used = kib_field(&status, "VmSize:")?;
    Some(limit.saturating_sub(used))
}

fn kib_field(text: &str, key: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib.saturating_mul(1024))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_in_binary_units() {
        assert_eq!(parse_size("8G"), Ok(8 << 30));
        assert_eq!(parse_size("512 MiB"), Ok(512 << 20));
        assert_eq!(parse_size("1.5gb"), Ok(3 << 29));
        assert_eq!(parse_size("1000"), Ok(1000));
        assert!(parse_size("0").is_err());
        assert!(parse_size("-1G").is_err());
        assert!(parse_size("8X").is_err());
        assert!(parse_size("nan").is_err());
    }

    #[test]
    fn a_budget_refuses_what_exceeds_it_and_names_the_setting() {
        let budget = MemoryBudget::from_pair((1 << 30, "a test limit"));
        budget.check("a window", 1 << 29, "voxel_size_m").expect("fits");
        let err = budget.check("a window", 3 << 30, "[occupancy] voxel_size_m").expect_err("too big");
        let text = err.to_string();
        assert!(text.contains("3.0 GiB") && text.contains("1.0 GiB") && text.contains("voxel_size_m"), "{text}");
    }

    #[test]
    fn the_system_budget_is_known_on_linux() {
        if cfg!(target_os = "linux") {
            assert!(MemoryBudget::from_system().limit_bytes().is_some_and(|b| b > 0));
        }
    }
}
