//! The GIE-mapping paper's Fig. 6 (EDT error against voxel size and
//! connectivity) and Fig. 7 (global EDT time over a run, global error
//! against voxel size), drawn from `edtmap run --eval` reports.
//!
//! ```text
//! cargo run --release -p edtmap --example paper_figures -- IN_DIR OUT_DIR
//! ```
//!
//! `bench/figures.sh` fills IN_DIR with one folder per run, each holding
//! the `report.json` of `edtmap run --eval`. Folders named `sweep_*` are
//! the short runs of the parameter sweeps (Fig. 6 and Fig. 7b), folders
//! named `run_*` the whole runs (Fig. 7a and the per-frame error); the
//! parameters (scene, voxel size, connectivity, mode) are read from each
//! report, not from the folder name. The example writes `fig6_*.png` and
//! `fig7_*.png` in OUT_DIR and prints a markdown table of every run.
//!
//! Errors are drawn on linear axes: an error of exactly 0 (the EDT equals
//! the exact EDT of the mapper's own occupancy) sits on the axis, where a
//! log axis could not show it.

use std::cmp::Reverse;
use std::collections::BTreeSet;
use std::error::Error;
use std::path::{Path, PathBuf};

use edtmap_viz::plot::{Chart, Series, SeriesStyle};
use serde_json::Value;

type Result<T> = std::result::Result<T, Box<dyn Error>>;

/// The paper's GIE local RMS error at 0.05 m voxels (Fig. 6a), metres, as
/// read from the figure: the paper's text gives no number.
const PAPER_LOCAL_RMS_AT_5CM_M: f64 = 0.005;
/// The paper's GIE global RMS error at 0.1 m voxels (Fig. 7b), metres, as
/// read from the figure.
const PAPER_GLOBAL_RMS_AT_10CM_M: f64 = 0.02;
/// A unit errors are drawn in.
#[derive(Clone, Copy)]
struct Unit {
    /// Units per metre.
    per_m: f64,
    /// Its symbol.
    symbol: &'static str,
}
/// Millimetres: the scale of the paper's errors.
const MM: Unit = Unit { per_m: 1e3, symbol: "mm" };
/// Micrometres: the scale of our wavefront errors.
const UM: Unit = Unit { per_m: 1e6, symbol: "µm" };
/// Voxel size of the connectivity sweep (Fig. 6b), metres.
const CONNECTIVITY_VOXEL_M: f64 = 0.1;

/// One `edtmap run` report and the folder it came from.
struct Run {
    /// Folder name, e.g. `sweep_room_v0.05_c26_wavefront`.
    name: String,
    /// Built-in scene name.
    scene: String,
    /// Voxel side, metres.
    voxel_m: f64,
    /// Neighbours per voxel in the wavefronts: 6, 18 or 26.
    connectivity: u64,
    /// Global integration mode: `wavefront` or `exact`.
    mode: String,
    /// The whole report.
    report: Value,
}

impl Run {
    /// Reads `dir/report.json`.
    fn load(dir: &Path) -> Result<Run> {
        let text = std::fs::read_to_string(dir.join("report.json"))?;
        let report: Value = serde_json::from_str(&text)?;
        let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let text_of = |key: &str| report[key].as_str().map(str::to_owned).ok_or(format!("{name}: no {key}"));
        let (scene, mode) = (text_of("scene")?, text_of("integration")?);
        let voxel_m = report["voxel_size_m"].as_f64().ok_or(format!("{name}: no voxel_size_m"))?;
        let connectivity = report["connectivity"].as_u64().ok_or(format!("{name}: no connectivity"))?;
        Ok(Run { name, scene, voxel_m, connectivity, mode, report })
    }

    /// Whether the run belongs to the sweeps (else it is a whole run).
    fn is_sweep(&self) -> bool {
        self.name.starts_with("sweep_")
    }

    /// A statistic (`mean`, `median`, `max`, ...) of a per-frame field.
    fn stat(&self, field: &str, stat: &str) -> f64 {
        self.report["summary"][field][stat].as_f64().unwrap_or(f64::NAN)
    }

    /// Frames replayed.
    fn frames(&self) -> usize {
        self.report["frames"].as_array().map_or(0, Vec::len)
    }

    /// `(frame index, value)` of a per-frame quantity.
    fn per_frame(&self, value: impl Fn(&Value) -> Option<f64>) -> Vec<(f64, f64)> {
        let frames = self.report["frames"].as_array().map(Vec::as_slice).unwrap_or_default();
        frames.iter().enumerate().filter_map(|(i, f)| Some((i as f64, value(f)?))).collect()
    }
}

/// Reads every `IN_DIR/*/report.json`, sorted by folder name.
fn load_runs(dir: &Path) -> Result<Vec<Run>> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(dir)?.filter_map(|e| e.ok().map(|e| e.path())).collect();
    dirs.retain(|d| d.join("report.json").is_file());
    dirs.sort();
    dirs.iter().map(|d| Run::load(d)).collect()
}

/// Sweep runs kept by `keep` as `(x, mean of the error field in unit)`
/// points with x from `x_of`, sorted by x.
fn sweep_points(
    runs: &[&Run],
    keep: impl Fn(&Run) -> bool,
    x_of: impl Fn(&Run) -> f64,
    field: &str,
    unit: Unit,
) -> Vec<(f64, f64)> {
    let mut points: Vec<(f64, f64)> =
        runs.iter().filter(|r| keep(r)).map(|r| (x_of(r), r.stat(field, "mean") * unit.per_m)).collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// Distinct values of a run property, in order.
fn distinct<T: Ord>(runs: &[&Run], key: impl Fn(&Run) -> T) -> Vec<T> {
    runs.iter().map(|r| key(r)).collect::<BTreeSet<T>>().into_iter().collect()
}

/// The y label of an error chart: `local` or `global` RMS, in `unit`.
fn error_label(field: &str, unit: Unit) -> String {
    let scope = if field.starts_with("local") { "local" } else { "global" };
    format!("{scope} RMS error ({}), 0 = exact", unit.symbol)
}

/// A value of the paper drawn as a lone black marker: `(x, error in
/// metres, legend)`.
type PaperPoint = (f64, f64, &'static str);

/// Error against voxel size: one series per scene and connectivity of the
/// wavefront sweep, and the paper's value if given.
fn error_vs_voxel(sweep: &[&Run], field: &str, title: &str, unit: Unit, paper: Option<PaperPoint>) -> Chart {
    let wave: Vec<&Run> = sweep.iter().copied().filter(|r| r.mode == "wavefront").collect();
    let mut chart = Chart::new(title).x_label("voxel size (m)").y_label(error_label(field, unit)).x_range(0.0, 0.25);
    for scene in distinct(&wave, |r| r.scene.clone()) {
        for Reverse(conn) in distinct(&wave, |r| Reverse(r.connectivity)) {
            let keep = |r: &Run| r.scene == scene && r.connectivity == conn;
            let points = sweep_points(&wave, keep, |r| r.voxel_m, field, unit);
            if points.len() > 1 {
                chart =
                    chart.series(Series::new(format!("{scene}, {conn}-conn."), points, SeriesStyle::LineAndMarkers));
            }
        }
    }
    match paper {
        Some((x, y_m, label)) => {
            chart.series(Series::new(label, [(x, y_m * unit.per_m)], SeriesStyle::Markers).color([0, 0, 0]))
        }
        None => chart,
    }
}

/// Error against connectivity at [`CONNECTIVITY_VOXEL_M`], one series per
/// scene.
fn error_vs_connectivity(sweep: &[&Run], field: &str, title: &str, unit: Unit) -> Chart {
    let at_voxel = |r: &Run| r.mode == "wavefront" && (r.voxel_m - CONNECTIVITY_VOXEL_M).abs() < 1e-9;
    let runs: Vec<&Run> = sweep.iter().copied().filter(|r| at_voxel(r)).collect();
    let x_label = format!("connectivity (neighbours), voxel {CONNECTIVITY_VOXEL_M} m");
    let mut chart = Chart::new(title).x_label(x_label).y_label(error_label(field, unit)).x_range(4.0, 28.0);
    let mut all_zero = true;
    for scene in distinct(&runs, |r| r.scene.clone()) {
        let points = sweep_points(&runs, |r| r.scene == scene, |r| r.connectivity as f64, field, unit);
        all_zero &= points.iter().all(|p| p.1 == 0.0);
        chart = chart.series(Series::new(scene, points, SeriesStyle::LineAndMarkers));
    }
    // Errors are never negative: keep the axis of an all-zero chart at 0..1.
    if all_zero {
        chart = chart.y_range(0.0, 1.0);
    }
    chart
}

/// Fig. 7a for one scene: per-frame global EDT time (batch EDT + global
/// integration, and integration alone) of each whole run of that scene,
/// with head room above the curves for the legend.
fn edt_time_chart(whole: &[&Run], scene: &str) -> Option<Chart> {
    let runs: Vec<&&Run> = whole.iter().filter(|r| r.scene == scene).collect();
    let title = format!("Fig. 7a: global EDT time per frame, {scene} at {} m", runs.first()?.voxel_m);
    let mut chart = Chart::new(title).x_label("frame").y_label("time (ms)");
    let mut top = 0.0f64;
    for run in &runs {
        let tag = run_tag(run);
        let both = run.per_frame(|f| Some(f["batch_edt_ms"].as_f64()? + f["integrate_ms"].as_f64()?));
        let integrate = run.per_frame(|f| f["integrate_ms"].as_f64());
        top = both.iter().fold(top, |m, p| m.max(p.1));
        chart = chart.series(Series::new(format!("{tag}: batch EDT + integrate"), both, SeriesStyle::Line));
        chart = chart.series(Series::new(format!("{tag}: integrate"), integrate, SeriesStyle::Line));
    }
    Some(chart.y_range(0.0, top * 1.6))
}

/// Per-frame global RMS error of each whole run of one scene.
fn rms_over_run_chart(whole: &[&Run], scene: &str, unit: Unit) -> Option<Chart> {
    let runs: Vec<&&Run> = whole.iter().filter(|r| r.scene == scene).collect();
    let title = format!("Global RMS error per frame, {scene} at {} m", runs.first()?.voxel_m);
    let mut chart = Chart::new(title).x_label("frame").y_label(error_label("global", unit));
    for run in &runs {
        let rms = run.per_frame(|f| Some(f["global_rms_m"].as_f64()? * unit.per_m));
        chart = chart.series(Series::new(run_tag(run), rms, SeriesStyle::Line));
    }
    Some(chart)
}

/// `wavefront 26-conn.` or `exact`.
fn run_tag(run: &Run) -> String {
    match run.mode.as_str() {
        "exact" => "exact".into(),
        mode => format!("{mode} {}-conn.", run.connectivity),
    }
}

/// The Fig. 6 and Fig. 7b charts of the sweeps, with their file names.
fn sweep_charts(sweep: &[&Run]) -> Vec<(String, Chart)> {
    let local_paper = (0.05, PAPER_LOCAL_RMS_AT_5CM_M, "GIE, paper Fig. 6a (approx.)");
    let global_paper = (0.1, PAPER_GLOBAL_RMS_AT_10CM_M, "GIE, paper Fig. 7b (approx.)");
    let (local, global) = ("local_rms_m", "global_rms_m");
    vec![
        (
            "fig6_a_local_rms_vs_voxel",
            error_vs_voxel(sweep, local, "Fig. 6a: local EDT error vs voxel size", MM, Some(local_paper)),
        ),
        (
            "fig6_b_local_rms_vs_connectivity",
            error_vs_connectivity(sweep, local, "Fig. 6b: local EDT error vs connectivity", UM),
        ),
        (
            "fig6_b_global_rms_vs_connectivity",
            error_vs_connectivity(sweep, global, "Fig. 6b: global EDT error vs connectivity", UM),
        ),
        (
            "fig7_b_global_rms_vs_voxel",
            error_vs_voxel(sweep, global, "Fig. 7b: global EDT error vs voxel size", MM, Some(global_paper)),
        ),
        (
            "fig7_b_global_rms_vs_voxel_um",
            error_vs_voxel(sweep, global, "Fig. 7b in µm: global EDT error vs voxel size", UM, None),
        ),
    ]
    .into_iter()
    .map(|(name, chart)| (name.to_owned(), chart))
    .collect()
}

/// Draws every figure into `out`, returning the files written.
fn draw_figures(runs: &[Run], out: &Path) -> Result<Vec<PathBuf>> {
    let sweep: Vec<&Run> = runs.iter().filter(|r| r.is_sweep()).collect();
    let whole: Vec<&Run> = runs.iter().filter(|r| !r.is_sweep()).collect();
    let mut charts = sweep_charts(&sweep);
    for scene in distinct(&whole, |r| r.scene.clone()) {
        charts.extend(edt_time_chart(&whole, &scene).map(|c| (format!("fig7_a_edt_time_{scene}"), c)));
        charts.extend(
            rms_over_run_chart(&whole, &scene, UM).map(|c| (format!("fig7_b_global_rms_per_frame_{scene}"), c)),
        );
    }
    let mut written = Vec::new();
    for (name, chart) in charts {
        let path = out.join(format!("{name}.png"));
        chart.size(1000, 560).write_png(&path)?;
        written.push(path);
    }
    Ok(written)
}

/// An error in metres for the table: `0` when exactly zero.
fn metres(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.2e}")
    }
}

/// Sweeps first, then by scene, mode, connectivity (high first), voxel.
fn table_order(a: &Run, b: &Run) -> std::cmp::Ordering {
    let key = |r: &Run| (!r.is_sweep(), r.scene.clone(), r.mode.clone(), Reverse(r.connectivity));
    key(a).cmp(&key(b)).then(a.voxel_m.total_cmp(&b.voxel_m))
}

/// The markdown table of every run.
fn table(runs: &[Run]) -> String {
    let mut text = String::from(
        "| set | scene | voxel (m) | conn. | mode | frames | local RMS mean (m) | global RMS mean (m) | global max (m) \
         | batch EDT median (ms) | integrate median (ms) |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in runs {
        let set = if r.is_sweep() { "sweep" } else { "whole run" };
        text += &format!(
            "| {set} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} | {:.1} |\n",
            r.scene,
            r.voxel_m,
            r.connectivity,
            r.mode,
            r.frames(),
            metres(r.stat("local_rms_m", "mean")),
            metres(r.stat("global_rms_m", "mean")),
            metres(r.stat("global_max_m", "max")),
            r.stat("batch_edt_ms", "median"),
            r.stat("integrate_ms", "median"),
        );
    }
    text
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output] = args.as_slice() else {
        return Err("usage: paper_figures IN_DIR OUT_DIR".into());
    };
    let mut runs = load_runs(Path::new(input))?;
    if runs.is_empty() {
        return Err(format!("no */report.json under {input}").into());
    }
    runs.sort_by(table_order);
    std::fs::create_dir_all(output)?;
    for path in draw_figures(&runs, Path::new(output))? {
        eprintln!("wrote {}", path.display());
    }
    print!("{}", table(&runs));
    Ok(())
}
