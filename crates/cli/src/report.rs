//! `report.json`: per-frame stage times and counts, and their summary.

use serde_json::{json, Map, Value};

/// One frame's record.
#[derive(Debug, Clone, Default)]
pub(crate) struct FrameRecord {
    pub(crate) index: usize,
    /// The name of the sensor the frame came from.
    pub(crate) sensor: String,
    pub(crate) stamp_s: f64,
    pub(crate) ogm_ms: f64,
    /// The window's batch EDT, where it runs as a stage of its own
    /// (wavefront mode on the CPU); `None` in exact mode, which has no
    /// such stage, and where a device runs it inside the integration.
    pub(crate) batch_edt_ms: Option<f64>,
    pub(crate) integrate_ms: f64,
    pub(crate) total_ms: f64,
    pub(crate) voxels_updated: usize,
    pub(crate) voxels_changed: usize,
    pub(crate) changed_blocks: usize,
    /// Global EDT voxels changed, change score V (m), map blocks and bytes,
    /// wavefront counters.
    pub(crate) global: Vec<(&'static str, f64)>,
    pub(crate) precision: Option<f64>,
    pub(crate) recall: Option<f64>,
    pub(crate) strict_recall: Option<f64>,
    /// With `--eval`: local and global EDT errors.
    pub(crate) edt_errors: Vec<(&'static str, f64)>,
}

impl FrameRecord {
    /// The value of a named global or error field.
    pub(crate) fn field(&self, key: &str) -> Option<f64> {
        self.global.iter().chain(&self.edt_errors).find(|(k, _)| *k == key).map(|(_, v)| *v)
    }
}

impl FrameRecord {
    fn to_json(&self) -> Value {
        let mut v = json!({
            "index": self.index,
            "sensor": self.sensor,
            "stamp_s": self.stamp_s,
            "ogm_ms": self.ogm_ms,
            "integrate_ms": self.integrate_ms,
            "total_ms": self.total_ms,
            "voxels_updated": self.voxels_updated,
            "voxels_changed": self.voxels_changed,
            "changed_blocks": self.changed_blocks,
        });
        if let Some(obj) = v.as_object_mut() {
            for (key, value) in [
                ("batch_edt_ms", self.batch_edt_ms),
                ("precision", self.precision),
                ("recall", self.recall),
                ("strict_recall", self.strict_recall),
            ] {
                if let Some(x) = value {
                    obj.insert(key.into(), json!(x));
                }
            }
            for (key, x) in self.global.iter().chain(&self.edt_errors) {
                obj.insert((*key).into(), json!(x));
            }
        }
        v
    }
}

/// The median of `values`: the middle value, or the mean of the two
/// middle values of an even count; `None` when there are none. The one
/// definition of the printed summary and of `report.json`.
pub(crate) fn median(values: &[f64]) -> Option<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some((v[n / 2 - 1] + v[n / 2]) / 2.0),
    }
}

/// Mean, median and 95th percentile (nearest rank) of `values`.
pub(crate) fn stats(values: &[f64]) -> Value {
    let Some(median) = median(values) else { return Value::Null };
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let p95 = v[((0.95 * n as f64).ceil() as usize).clamp(1, n) - 1];
    json!({ "mean": v.iter().sum::<f64>() / n as f64, "median": median, "p95": p95, "min": v[0], "max": v[n - 1] })
}

/// The whole report: `header` fields, the frames and their summary.
pub(crate) fn report(header: Map<String, Value>, frames: &[FrameRecord]) -> Value {
    let col = |f: fn(&FrameRecord) -> Option<f64>| frames.iter().filter_map(f).collect::<Vec<f64>>();
    let mut summary = Map::new();
    summary.insert("frames".into(), json!(frames.len()));
    summary.insert("ogm_ms".into(), stats(&col(|f| Some(f.ogm_ms))));
    if frames.iter().any(|f| f.batch_edt_ms.is_some()) {
        summary.insert("batch_edt_ms".into(), stats(&col(|f| f.batch_edt_ms)));
    }
    summary.insert("integrate_ms".into(), stats(&col(|f| Some(f.integrate_ms))));
    summary.insert("total_ms".into(), stats(&col(|f| Some(f.total_ms))));
    let keys = frames
        .first()
        .map(|f| f.global.iter().chain(&f.edt_errors).map(|(k, _)| *k).collect::<Vec<_>>())
        .unwrap_or_default();
    for key in keys {
        summary.insert(key.into(), stats(&frames.iter().filter_map(|f| f.field(key)).collect::<Vec<_>>()));
    }
    summary.insert("voxels_updated".into(), stats(&col(|f| Some(f.voxels_updated as f64))));
    if frames.iter().any(|f| f.precision.is_some()) {
        summary.insert("precision".into(), stats(&col(|f| f.precision)));
        summary.insert("recall".into(), stats(&col(|f| f.recall)));
        summary.insert("strict_recall".into(), stats(&col(|f| f.strict_recall)));
    }
    let mut out = header;
    out.insert("frames".into(), Value::Array(frames.iter().map(FrameRecord::to_json).collect()));
    out.insert("summary".into(), Value::Object(summary));
    Value::Object(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_statistics() {
        let s = stats(&[4.0, 1.0, 3.0, 2.0]);
        assert_eq!(s["mean"], 2.5);
        assert_eq!(s["median"], 2.5);
        assert_eq!(s["p95"], 4.0);
        let s = stats(&(1..=100).map(f64::from).collect::<Vec<_>>());
        assert_eq!(s["p95"], 95.0);
        assert_eq!(stats(&[]), Value::Null);
    }

    #[test]
    fn median_of_an_even_count_is_the_mean_of_the_middle_two() {
        // Sorted: 1, 2, 10, 40: the middle two are 2 and 10.
        assert_eq!(median(&[40.0, 2.0, 1.0, 10.0]), Some(6.0));
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[7.5]), Some(7.5));
        assert_eq!(median(&[]), None);
        assert_eq!(stats(&[40.0, 2.0, 1.0, 10.0])["median"], 6.0);
    }
}
