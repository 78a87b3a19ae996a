//! What `export` and `compare` share: file names, the box, statistics.

use edtmap::region::Region;
use serde_json::{json, Value};
use std::path::Path;

/// Errors of this example: messages for the user.
pub(crate) type Error = Box<dyn std::error::Error>;

/// The changes file DynamicEDT3D replays.
pub(crate) const CHANGES_FILE: &str = "changes.txt";
/// Our per-frame times.
pub(crate) const TIMES_FILE: &str = "edtmap_times.csv";
/// Parameters, box and our results.
pub(crate) const SUMMARY_FILE: &str = "edtmap_summary.json";
/// The final map: the truth of both final errors.
pub(crate) const MAP_FILE: &str = "final.edtmap";

/// Median of `v` (mean of the middle two for an even count; NaN if empty).
pub(crate) fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => s[n / 2],
        n => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

/// Mean of `v` (NaN if empty).
pub(crate) fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// Median, mean and total of per-frame times, ms.
pub(crate) fn time_stats(ms: &[f64]) -> Value {
    json!({ "median_ms": median(ms), "mean_ms": mean(ms), "total_ms": ms.iter().sum::<f64>() })
}

/// The box as JSON.
pub(crate) fn region_json(r: &Region) -> Value {
    json!({ "origin": r.origin, "dims": r.dims, "voxels": r.len() })
}

/// The box back from [`region_json`].
pub(crate) fn region_from_json(v: &Value) -> Result<Region, Error> {
    let origin: [i32; 3] = serde_json::from_value(v["origin"].clone())?;
    let dims: [usize; 3] = serde_json::from_value(v["dims"].clone())?;
    Ok(Region { origin, dims })
}

/// Writes `value` as pretty JSON.
pub(crate) fn write_json(path: &Path, value: &Value) -> Result<(), Error> {
    std::fs::write(path, serde_json::to_string_pretty(value)? + "\n")
        .map_err(|e| format!("cannot write {}: {e}", path.display()).into())
}

/// Reads a JSON file.
pub(crate) fn read_json(path: &Path) -> Result<Value, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()).into())
}

/// Reads a CSV file with a header: the header's names and the rows as
/// numbers.
pub(crate) fn read_csv(path: &Path) -> Result<(Vec<String>, Vec<Vec<f64>>), Error> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header = lines.next().ok_or_else(|| format!("{}: empty", path.display()))?;
    let names: Vec<String> = header.split(',').map(str::to_owned).collect();
    let mut rows = Vec::new();
    for (k, line) in lines.enumerate() {
        let row = line
            .split(',')
            .map(str::parse::<f64>)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| format!("{}:{}: {e}", path.display(), k + 2))?;
        if row.len() != names.len() {
            return Err(format!("{}:{}: {} fields, expected {}", path.display(), k + 2, row.len(), names.len()).into());
        }
        rows.push(row);
    }
    Ok((names, rows))
}

/// The column `name` of a table from [`read_csv`].
pub(crate) fn column(path: &Path, table: &(Vec<String>, Vec<Vec<f64>>), name: &str) -> Result<Vec<f64>, Error> {
    let i = table.0.iter().position(|n| n == name).ok_or_else(|| format!("{}: no column {name}", path.display()))?;
    Ok(table.1.iter().map(|r| r[i]).collect())
}
