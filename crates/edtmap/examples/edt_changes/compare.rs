//! `edt_changes compare`: DynamicEDT3D's times and final field against
//! ours, a table row and Fig. 4.

use crate::common::{
    column, mean, median, read_csv, read_json, region_from_json, time_stats, write_json, Error, MAP_FILE, SUMMARY_FILE,
    TIMES_FILE,
};
use edtmap::eval::{edt_errors, EdtErrors};
use edtmap::region::Region;
use edtmap::stages::exact::exact_region;
use edtmap::{GlobalMap, FAR_DIST_SQ};
use edtmap_viz::plot::{Chart, Series, SeriesStyle};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Arguments of `compare`.
#[derive(Debug)]
pub(crate) struct CompareArgs {
    pub(crate) dir: PathBuf,
    pub(crate) dynamicedt_prefix: String,
}

/// The table's header lines (markdown).
const TABLE_HEADER: &str = "| scene | voxel (m) | frames | box voxels | edtmap median / mean (ms) | DynamicEDT3D median / mean (ms) | ratio of medians | ratio of totals | edtmap RMS / max error (m) | DynamicEDT3D RMS / max error (m) |\n|---|---|---|---|---|---|---|---|---|---|";

/// Per-frame times and change scores of both sides.
struct Times {
    ours_ms: Vec<f64>,
    theirs_ms: Vec<f64>,
    change_score_m: Vec<f64>,
}

/// Runs `compare`.
pub(crate) fn run(args: &CompareArgs) -> Result<(), Error> {
    let summary = read_json(&args.dir.join(SUMMARY_FILE))?;
    let region = region_from_json(&summary["box"])?;
    let map = edtmap::load_map(&args.dir.join(MAP_FILE))?;
    let ours = edt_errors(&map, &region)?;
    let field_path = PathBuf::from(format!("{}.final.f32", args.dynamicedt_prefix));
    let theirs = field_errors(&map, &region, &read_field(&field_path, region.len())?)?;
    let times = read_times(&args.dir, &args.dynamicedt_prefix)?;
    let comparison = json!({
        "scene": summary["scene"],
        "voxel_size_m": map.voxel_size_m(),
        "max_distance_m": map.params().max_distance_m,
        "integration": map.params().mode,
        "connectivity": map.params().connectivity,
        "threads": summary["threads"],
        "frames": times.ours_ms.len(),
        "box": summary["box"],
        "edtmap": { "time": time_stats(&times.ours_ms), "error": errors_json(&ours) },
        "dynamicedt3d": { "time": time_stats(&times.theirs_ms), "error": errors_json(&theirs) },
        "ratio_of_medians": median(&times.theirs_ms) / median(&times.ours_ms),
        "ratio_of_totals": times.theirs_ms.iter().sum::<f64>() / times.ours_ms.iter().sum::<f64>(),
    });
    write_json(&args.dir.join("comparison.json"), &comparison)?;
    let table = format!("{TABLE_HEADER}\n{}\n", table_row(&comparison, &times, &ours, &theirs));
    std::fs::write(args.dir.join("table.md"), &table).map_err(|e| format!("cannot write table.md: {e}"))?;
    draw_fig4(&args.dir.join("fig4_time_vs_change.png"), &summary, map.voxel_size_m(), &times)?;
    print!("{table}");
    Ok(())
}

/// Reads DynamicEDT3D's final field: `voxels` little-endian f32, voxels.
fn read_field(path: &Path, voxels: usize) -> Result<Vec<f32>, Error> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    if bytes.len() != 4 * voxels {
        return Err(format!("{}: {} bytes, expected {} for the box", path.display(), bytes.len(), 4 * voxels).into());
    }
    Ok(bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
}

/// [`EdtErrors`] of a field in voxels (+inf beyond the cutoff, x fastest
/// over `region`) against the exact EDT of `map`'s obstacles, defined as
/// [`edt_errors`] defines them: voxels with an obstacle within the cutoff
/// on either side, distances beyond the cutoff counting as the cutoff.
fn field_errors(map: &GlobalMap, region: &Region, field: &[f32]) -> Result<EdtErrors, Error> {
    let exact = exact_region(&mut edtmap::cpu::CpuBackend::default(), &map.obstacles(), region, map.cutoff())?;
    let vs = map.voxel_size_m();
    let cap_sq = f64::from(map.cutoff().max_dist_sq);
    let (mut sum_sq, mut max, mut wrong, mut voxels) = (0.0, 0.0f64, 0usize, 0usize);
    for (&truth, &got) in exact.iter().zip(field) {
        let (truth_far, got_far) = (truth == FAR_DIST_SQ, !got.is_finite());
        if truth_far && got_far {
            continue;
        }
        let truth_sq = if truth_far { cap_sq } else { f64::from(truth) };
        let got_sq = if got_far { cap_sq } else { f64::from(got).powi(2) };
        let err = (got_sq.sqrt() - truth_sq.sqrt()).abs() * vs;
        (sum_sq, max, voxels) = (sum_sq + err * err, max.max(err), voxels + 1);
        wrong += usize::from(truth_far != got_far || (got_sq - truth_sq).abs() > 0.01);
    }
    let n = voxels.max(1) as f64;
    Ok(EdtErrors { rms_m: (sum_sq / n).sqrt(), max_m: max, wrong_fraction: wrong as f64 / n, voxels })
}

fn errors_json(e: &EdtErrors) -> Value {
    json!({ "rms_m": e.rms_m, "max_m": e.max_m, "wrong_fraction": e.wrong_fraction, "voxels": e.voxels })
}

/// Both sides' per-frame times, checking they replayed the same changes.
fn read_times(dir: &Path, prefix: &str) -> Result<Times, Error> {
    let ours_path = dir.join(TIMES_FILE);
    let theirs_path = PathBuf::from(format!("{prefix}.times.csv"));
    let ours = read_csv(&ours_path)?;
    let theirs = read_csv(&theirs_path)?;
    for name in ["set", "clear"] {
        if column(&ours_path, &ours, name)? != column(&theirs_path, &theirs, name)? {
            return Err(format!(
                "{} and {} list other {name} counts: not the same changes",
                ours_path.display(),
                theirs_path.display()
            )
            .into());
        }
    }
    Ok(Times {
        ours_ms: column(&ours_path, &ours, "edt_ms")?,
        theirs_ms: column(&theirs_path, &theirs, "update_ms")?,
        change_score_m: column(&ours_path, &ours, "change_score_m")?,
    })
}

/// One markdown row of the comparison table.
fn table_row(c: &Value, t: &Times, ours: &EdtErrors, theirs: &EdtErrors) -> String {
    let scene = c["scene"].as_str().unwrap_or("?");
    let b = &c["box"]["dims"];
    format!(
        "| {scene} | {} | {} | {}x{}x{} = {} | {:.3} / {:.3} | {:.3} / {:.3} | {:.2} | {:.2} | {:.4} / {:.4} | {:.4} / {:.4} |",
        c["voxel_size_m"],
        t.ours_ms.len(),
        b[0],
        b[1],
        b[2],
        c["box"]["voxels"],
        median(&t.ours_ms),
        mean(&t.ours_ms),
        median(&t.theirs_ms),
        mean(&t.theirs_ms),
        c["ratio_of_medians"].as_f64().unwrap_or(f64::NAN),
        c["ratio_of_totals"].as_f64().unwrap_or(f64::NAN),
        ours.rms_m,
        ours.max_m,
        theirs.rms_m,
        theirs.max_m,
    )
}

/// Fig. 4 of the paper: per-frame EDT update time against the change score.
fn draw_fig4(path: &Path, summary: &Value, voxel_size_m: f64, t: &Times) -> Result<(), Error> {
    let points = |ms: &[f64]| t.change_score_m.iter().copied().zip(ms.iter().copied()).collect::<Vec<_>>();
    let scene = summary["scene"].as_str().unwrap_or("?");
    // A log axis skips frames with V = 0; the title says how many.
    let unchanged = t.change_score_m.iter().filter(|&&v| v <= 0.0).count();
    let note = if unchanged > 0 { format!(", {unchanged} frames with V = 0 not shown") } else { String::new() };
    Chart::new(format!("EDT update time vs change score ({scene}, {voxel_size_m} m{note})"))
        .x_label("change score V (m)")
        .log_x()
        .y_label("EDT update time per frame (ms)")
        .log_y()
        .series(Series::new("edtmap (batch EDT + integration)", points(&t.ours_ms), SeriesStyle::Markers))
        .series(Series::new("DynamicEDT3D", points(&t.theirs_ms), SeriesStyle::Markers))
        .write_png(path)?;
    Ok(())
}
