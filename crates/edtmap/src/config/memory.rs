//! `[memory]`: the memory budget of a run.

use serde::Deserialize;

use crate::MapError;

/// `[memory]`: how much memory a run may use.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MemorySection {
    /// Most memory one frame may need, as a size (`"8G"`, `"512M"`,
    /// bytes); default: what the system has free, within the process's
    /// address-space limit. `--max-memory` overrides it.
    #[serde(default)]
    pub max: Option<String>,
}

impl MemorySection {
    /// The budget in bytes, if one is set.
    pub fn max_bytes(&self) -> Result<Option<u64>, MapError> {
        self.max
            .as_deref()
            .map(|text| {
                edtmap_core::memory::parse_size(text).map_err(|reason| MapError::ConfigFile {
                    path: "config [memory]".into(),
                    message: format!("max = {reason}"),
                })
            })
            .transpose()
    }
}
