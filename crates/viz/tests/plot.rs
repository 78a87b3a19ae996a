//! Charts written as PNG files: size, decodability and refusals.

use std::fs::File;
use std::path::Path;

use edtmap_viz::plot::{Chart, Series, SeriesStyle, DEFAULT_HEIGHT, DEFAULT_WIDTH};
use edtmap_viz::VizError;

/// Width, height and colour type of the PNG at `path`, decoding all of it.
fn decode(path: &Path) -> (u32, u32, png::ColorType) {
    let file = File::open(path).expect("chart file");
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().expect("PNG header");
    let mut buf = vec![0; reader.output_buffer_size().expect("buffer size")];
    let info = reader.next_frame(&mut buf).expect("PNG data");
    (info.width, info.height, info.color_type)
}

fn stage_times() -> Chart {
    let frame = |i: usize, ms: f64| (i as f64, ms + (i as f64 / 9.0).sin());
    Chart::new("Per-frame stage times (ms)")
        .x_label("frame")
        .y_label("time (ms)")
        .series(Series::new("occupancy", (0..100).map(|i| frame(i, 2.0)), SeriesStyle::Line))
        .series(Series::new("EDT", (0..100).map(|i| frame(i, 5.0)), SeriesStyle::LineAndMarkers))
}

#[test]
fn chart_writes_a_png_of_the_requested_size() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("sized.png");
    stage_times().size(640, 400).write_png(&path).expect("write");
    assert_eq!(decode(&path), (640, 400, png::ColorType::Rgb));
}

#[test]
fn chart_defaults_to_the_default_size() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("default.png");
    stage_times().write_png(&path).expect("write");
    assert_eq!(decode(&path), (DEFAULT_WIDTH as u32, DEFAULT_HEIGHT as u32, png::ColorType::Rgb));
}

#[test]
fn scatter_on_log_axes_with_bad_points_is_written() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("scatter.png");
    let points = [(10.0, 0.5), (0.0, 1.0), (-5.0, 2.0), (f64::NAN, 1.0), (1e4, f64::INFINITY), (1e3, 40.0)];
    let chart = Chart::new("EDT time against change score")
        .x_label("changed voxels")
        .y_label("EDT time (ms)")
        .log_x()
        .log_y()
        .series(Series::new("CPU", points, SeriesStyle::Markers));
    chart.write_png(&path).expect("write");
    assert_eq!(decode(&path).0, DEFAULT_WIDTH as u32);
}

#[test]
fn empty_chart_is_written_with_empty_axes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("empty.png");
    let all_nan = Series::new("nothing", [(f64::NAN, f64::NAN)], SeriesStyle::Line);
    Chart::new("no data").series(all_nan).write_png(&path).expect("write");
    assert_eq!(decode(&path).1, DEFAULT_HEIGHT as u32);
}

#[test]
fn log_range_that_is_not_positive_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("refused.png");
    let err = stage_times().log_y().y_range(0.0, 10.0).write_png(&path).expect_err("refused");
    assert!(matches!(err, VizError::BadChart { .. }), "{err:?}");
    let message = err.to_string();
    assert!(message.contains("refused.png") && message.contains("log"), "{message}");
    assert!(!path.exists());
}

#[test]
fn picture_too_small_for_its_labels_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let err = stage_times().size(60, 40).write_png(dir.path().join("tiny.png")).expect_err("refused");
    assert!(matches!(err, VizError::BadChart { .. }), "{err:?}");
}
