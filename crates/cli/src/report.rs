//! `report.json`: per-frame stage times and counts, and their summary.
//!
//! A record costs about 400 bytes, so a run of an hour at 30 Hz keeps
//! about 45 MB of them: the named values sit in one slice per frame and
//! their names in a list shared by every frame with the same fields. The
//! file is written as it is serialized, frame after frame, without a
//! second copy of the records.

use std::io::{self, Write};
use std::path::Path;
use std::sync::Arc;

use serde::ser::{SerializeMap, Serializer};
use serde::Serialize;
use serde_json::{json, Map, Value};

/// One frame's record.
#[derive(Debug, Clone, Default)]
pub(crate) struct FrameRecord {
    pub(crate) index: usize,
    /// The name of the sensor the frame came from.
    pub(crate) sensor: Arc<str>,
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
    pub(crate) precision: Option<f64>,
    pub(crate) recall: Option<f64>,
    pub(crate) strict_recall: Option<f64>,
    /// Global EDT voxels changed, change score V (m), map blocks and bytes,
    /// wavefront and device counters, and with `--eval` the EDT errors.
    pub(crate) fields: Fields,
}

impl FrameRecord {
    /// The value of a named field.
    pub(crate) fn field(&self, key: &str) -> Option<f64> {
        self.fields.get(key)
    }
}

/// Named values: the names shared with the other frames that have the
/// same ones, the values the frame's own.
#[derive(Debug, Clone)]
pub(crate) struct Fields {
    keys: Arc<[&'static str]>,
    values: Box<[f64]>,
}

impl Default for Fields {
    fn default() -> Self {
        Fields { keys: Arc::from(Vec::new()), values: Box::default() }
    }
}

impl Fields {
    pub(crate) fn get(&self, key: &str) -> Option<f64> {
        self.keys.iter().position(|k| *k == key).map(|i| self.values[i])
    }

    pub(crate) fn iter(&self) -> impl Iterator<Item = (&'static str, f64)> + '_ {
        self.keys.iter().copied().zip(self.values.iter().copied())
    }
}

/// The name lists seen so far: a frame whose names match one of them
/// shares it.
#[derive(Default)]
pub(crate) struct FieldNames(Vec<Arc<[&'static str]>>);

impl FieldNames {
    /// `pairs` as [`Fields`], their names shared where an earlier frame
    /// had the same.
    pub(crate) fn fields(&mut self, pairs: &[(&'static str, f64)]) -> Fields {
        let same =
            |keys: &Arc<[&'static str]>| keys.len() == pairs.len() && keys.iter().zip(pairs).all(|(k, (p, _))| k == p);
        let keys = match self.0.iter().find(|k| same(k)) {
            Some(keys) => Arc::clone(keys),
            None => {
                let keys: Arc<[&'static str]> = pairs.iter().map(|(k, _)| *k).collect();
                self.0.push(Arc::clone(&keys));
                keys
            }
        };
        Fields { keys, values: pairs.iter().map(|(_, v)| *v).collect() }
    }
}

/// A value of a frame's JSON object.
enum Scalar<'a> {
    Count(usize),
    Real(f64),
    Text(&'a str),
}

impl Serialize for Scalar<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match *self {
            Scalar::Count(n) => s.serialize_u64(n as u64),
            // Like a JSON value: a number that is not finite is null.
            Scalar::Real(x) if x.is_finite() => s.serialize_f64(x),
            Scalar::Real(_) => s.serialize_unit(),
            Scalar::Text(t) => s.serialize_str(t),
        }
    }
}

/// A frame as its JSON object, the keys in order.
struct FrameJson<'a>(&'a FrameRecord);

impl Serialize for FrameJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let f = self.0;
        let mut entries = vec![
            ("index", Scalar::Count(f.index)),
            ("sensor", Scalar::Text(&f.sensor)),
            ("stamp_s", Scalar::Real(f.stamp_s)),
            ("ogm_ms", Scalar::Real(f.ogm_ms)),
            ("integrate_ms", Scalar::Real(f.integrate_ms)),
            ("total_ms", Scalar::Real(f.total_ms)),
            ("voxels_updated", Scalar::Count(f.voxels_updated)),
            ("voxels_changed", Scalar::Count(f.voxels_changed)),
            ("changed_blocks", Scalar::Count(f.changed_blocks)),
        ];
        let optional = [
            ("batch_edt_ms", f.batch_edt_ms),
            ("precision", f.precision),
            ("recall", f.recall),
            ("strict_recall", f.strict_recall),
        ];
        entries.extend(optional.into_iter().filter_map(|(k, v)| v.map(|x| (k, Scalar::Real(x)))));
        entries.extend(f.fields.iter().map(|(k, x)| (k, Scalar::Real(x))));
        // A key given twice keeps its last value, as in a JSON object.
        entries.reverse();
        entries.sort_by_key(|(k, _)| *k);
        entries.dedup_by_key(|(k, _)| *k);
        let mut map = s.serialize_map(Some(entries.len()))?;
        for (k, v) in &entries {
            map.serialize_entry(k, v)?;
        }
        map.end()
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

/// The summary of `frames`: the statistics of every stage and field.
pub(crate) fn summary(frames: &[FrameRecord]) -> Value {
    let col = |f: fn(&FrameRecord) -> Option<f64>| frames.iter().filter_map(f).collect::<Vec<f64>>();
    let mut summary = Map::new();
    summary.insert("frames".into(), json!(frames.len()));
    summary.insert("ogm_ms".into(), stats(&col(|f| Some(f.ogm_ms))));
    if frames.iter().any(|f| f.batch_edt_ms.is_some()) {
        summary.insert("batch_edt_ms".into(), stats(&col(|f| f.batch_edt_ms)));
    }
    summary.insert("integrate_ms".into(), stats(&col(|f| Some(f.integrate_ms))));
    summary.insert("total_ms".into(), stats(&col(|f| Some(f.total_ms))));
    let keys = frames.first().map(|f| f.fields.keys.clone()).unwrap_or_default();
    for key in keys.iter() {
        summary.insert((*key).into(), stats(&frames.iter().filter_map(|f| f.field(key)).collect::<Vec<_>>()));
    }
    summary.insert("voxels_updated".into(), stats(&col(|f| Some(f.voxels_updated as f64))));
    if frames.iter().any(|f| f.precision.is_some()) {
        summary.insert("precision".into(), stats(&col(|f| f.precision)));
        summary.insert("recall".into(), stats(&col(|f| f.recall)));
        summary.insert("strict_recall".into(), stats(&col(|f| f.strict_recall)));
    }
    Value::Object(summary)
}

/// The whole report, `header` fields with the frames and their summary,
/// its keys in order.
struct Report<'a> {
    header: &'a Map<String, Value>,
    frames: &'a [FrameRecord],
    summary: &'a Value,
}

impl Serialize for Report<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        enum Entry<'a> {
            Header(&'a Value),
            Frames,
            Summary,
        }
        let mut entries: Vec<(&str, Entry<'_>)> = self
            .header
            .iter()
            .filter(|(k, _)| !matches!(k.as_str(), "frames" | "summary"))
            .map(|(k, v)| (k.as_str(), Entry::Header(v)))
            .collect();
        entries.push(("frames", Entry::Frames));
        entries.push(("summary", Entry::Summary));
        entries.sort_by_key(|(k, _)| *k);
        let mut map = s.serialize_map(Some(entries.len()))?;
        for (k, e) in entries {
            match e {
                Entry::Header(v) => map.serialize_entry(k, v)?,
                Entry::Frames => map.serialize_entry(k, &FrameList(self.frames))?,
                Entry::Summary => map.serialize_entry(k, self.summary)?,
            }
        }
        map.end()
    }
}

struct FrameList<'a>(&'a [FrameRecord]);

impl Serialize for FrameList<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.iter().map(FrameJson))
    }
}

/// Writes the report, `header` with the frames and their summary, as
/// indented JSON ending in a newline.
pub(crate) fn write_report(
    out: &mut impl Write,
    header: &Map<String, Value>,
    frames: &[FrameRecord],
) -> io::Result<()> {
    let summary = summary(frames);
    serde_json::to_writer_pretty(&mut *out, &Report { header, frames, summary: &summary })?;
    out.write_all(b"\n")
}

/// Writes the report to `path` atomically.
pub(crate) fn write_report_file(
    path: &Path,
    header: &Map<String, Value>,
    frames: &[FrameRecord],
) -> Result<(), edtmap_io::IoError> {
    edtmap_io::files::write_atomic_with(path, |w| write_report(w, header, frames))
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

    /// A frame as a `serde_json` value, built field by field.
    fn value_of(f: &FrameRecord) -> Value {
        let mut v = json!({
            "index": f.index,
            "sensor": &*f.sensor,
            "stamp_s": f.stamp_s,
            "ogm_ms": f.ogm_ms,
            "integrate_ms": f.integrate_ms,
            "total_ms": f.total_ms,
            "voxels_updated": f.voxels_updated,
            "voxels_changed": f.voxels_changed,
            "changed_blocks": f.changed_blocks,
        });
        let obj = v.as_object_mut().expect("an object");
        let optional = [
            ("batch_edt_ms", f.batch_edt_ms),
            ("precision", f.precision),
            ("recall", f.recall),
            ("strict_recall", f.strict_recall),
        ];
        for (key, value) in optional {
            if let Some(x) = value {
                obj.insert(key.into(), json!(x));
            }
        }
        for (key, x) in f.fields.iter() {
            obj.insert(key.into(), json!(x));
        }
        v
    }

    /// Frames of two sensors, with and without the optional stages,
    /// device counters and errors, and values that are not finite.
    fn frames() -> Vec<FrameRecord> {
        let mut names = FieldNames::default();
        let (camera, lidar): (Arc<str>, Arc<str>) = (Arc::from("camera"), Arc::from("lidar"));
        (0..7)
            .map(|i| {
                let x = i as f64;
                let mut pairs =
                    vec![("edt_voxels_changed", 1000.0 + x), ("change_score_m", 0.125 * x), ("map_bytes", 3e6)];
                if i % 3 == 1 {
                    pairs.extend([("gpu_dispatches", 12.0), ("gpu_wait_ms", 0.3 + x / 7.0)]);
                }
                if i % 2 == 0 {
                    pairs.extend([("global_max_m", 0.0), ("global_rms_m", if i == 4 { f64::NAN } else { 1e-9 * x })]);
                }
                FrameRecord {
                    index: i,
                    sensor: if i % 2 == 0 { camera.clone() } else { lidar.clone() },
                    stamp_s: 0.1 * x,
                    ogm_ms: 2.0 / (1.0 + x),
                    batch_edt_ms: (i % 2 == 1).then_some(0.7),
                    integrate_ms: 1.0 + x / 3.0,
                    total_ms: if i == 5 { f64::INFINITY } else { 3.0 + x },
                    voxels_updated: 18_500 + i,
                    voxels_changed: 80 * i,
                    changed_blocks: i,
                    precision: (i == 2).then_some(0.96),
                    recall: (i == 2).then_some(0.9),
                    strict_recall: (i == 2).then_some(0.85),
                    fields: names.fields(&pairs),
                }
            })
            .collect()
    }

    #[test]
    fn the_streamed_report_is_the_json_value_written_whole() {
        let frames = frames();
        let mut header = Map::new();
        header.insert("backend".into(), json!("cpu"));
        header.insert("threads".into(), json!(2));
        header.insert("sensors".into(), json!([{"name": "camera"}, {"name": "lidar"}]));
        header.insert("stopped".into(), Value::Null);
        let mut whole = header.clone();
        whole.insert("frames".into(), Value::Array(frames.iter().map(value_of).collect()));
        whole.insert("summary".into(), summary(&frames));
        let expected = serde_json::to_string_pretty(&Value::Object(whole)).expect("serializes") + "\n";
        let mut written = Vec::new();
        write_report(&mut written, &header, &frames).expect("writes");
        assert_eq!(String::from_utf8(written).expect("UTF-8"), expected);
    }

    #[test]
    fn frames_with_the_same_names_share_them() {
        let frames = frames();
        assert!(Arc::ptr_eq(&frames[0].fields.keys, &frames[6].fields.keys));
        assert!(!Arc::ptr_eq(&frames[1].fields.keys, &frames[4].fields.keys));
        assert_eq!(frames[1].field("gpu_dispatches"), Some(12.0));
        assert_eq!(frames[2].field("gpu_dispatches"), None);
        assert_eq!(frames[3].field("change_score_m"), Some(0.375));
    }
}
