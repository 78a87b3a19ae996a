use super::*;

const RED: Rgb = [200, 0, 0];

fn one_point(x: f64, y: f64, style: SeriesStyle) -> Chart {
    Chart::new("").size(400, 300).series(Series::new("", [(x, y)], style).color(RED))
}

fn rendered(chart: &Chart) -> (Canvas, draw::PlotArea) {
    chart.render().unwrap_or_else(|e| panic!("chart does not render: {e}"))
}

fn pixel_at(canvas: &Canvas, area: &draw::PlotArea, fraction: (f64, f64)) -> Option<Rgb> {
    let (x, y) = area.pixel(fraction);
    canvas.pixel(x.round() as usize, y.round() as usize)
}

#[test]
fn marker_at_the_range_centre_lands_on_the_plot_centre() {
    let chart = one_point(1.0, 1.0, SeriesStyle::Markers).x_range(0.0, 2.0).y_range(0.0, 2.0);
    let (canvas, area) = rendered(&chart);
    assert_eq!(pixel_at(&canvas, &area, (0.5, 0.5)), Some(RED));
    assert_ne!(pixel_at(&canvas, &area, (0.25, 0.5)), Some(RED));
}

#[test]
fn marker_on_log_axes_lands_on_the_geometric_centre() {
    let chart = one_point(10.0, 0.1, SeriesStyle::Markers).log_x().log_y().x_range(1.0, 100.0).y_range(0.01, 1.0);
    let (canvas, area) = rendered(&chart);
    assert_eq!(pixel_at(&canvas, &area, (0.5, 0.5)), Some(RED));
}

#[test]
fn line_passes_through_its_points_and_between_them() {
    let chart = Chart::new("diagonal")
        .x_range(0.0, 2.0)
        .y_range(0.0, 2.0)
        .series(Series::new("", [(0.0, 0.0), (2.0, 2.0)], SeriesStyle::Line).color(RED));
    let (canvas, area) = rendered(&chart);
    for t in [0.1, 0.25, 0.5, 0.9] {
        assert_eq!(pixel_at(&canvas, &area, (t, t)), Some(RED), "at {t}");
    }
}

#[test]
fn line_breaks_at_a_point_that_cannot_be_drawn() {
    let points = [(0.0, 1.0), (1.0, f64::NAN), (2.0, 1.0)];
    let chart = Chart::new("")
        .x_range(0.0, 2.0)
        .y_range(0.0, 2.0)
        .series(Series::new("", points, SeriesStyle::LineAndMarkers).color(RED));
    let (canvas, area) = rendered(&chart);
    assert_eq!(pixel_at(&canvas, &area, (0.0, 0.5)), Some(RED));
    assert_ne!(pixel_at(&canvas, &area, (0.5, 0.5)), Some(RED));
}

#[test]
fn log_axes_skip_points_that_are_not_positive() {
    let points = [(-1.0, 5.0), (0.0, 5.0), (10.0, 1.0), (100.0, 2.0), (f64::NAN, 3.0), (f64::INFINITY, 4.0)];
    let chart = Chart::new("").log_x().series(Series::new("s", points, SeriesStyle::Markers));
    assert_eq!(chart.extents(), (Some((10.0, 100.0)), Some((1.0, 2.0))));
    let (x, _) = resolve(&chart.x, "x", chart.extents().0, 5).expect("x axis");
    assert_eq!((x.lo, x.hi), (10.0, 100.0));
    assert_eq!(x.fraction(0.0), None);
    assert_eq!(x.fraction(-3.0), None);
    rendered(&chart);
}

#[test]
fn charts_without_drawable_points_draw_empty_axes() {
    rendered(&Chart::new("nothing"));
    let nan = Series::new("nan", [(f64::NAN, 1.0), (1.0, f64::INFINITY), (f64::NEG_INFINITY, 0.0)], SeriesStyle::Line);
    rendered(&Chart::new("not finite").series(nan.clone()));
    rendered(&Chart::new("not positive").log_y().series(Series::new("", [(1.0, 0.0), (2.0, -1.0)], SeriesStyle::Line)));
    rendered(&Chart::new("log, not finite").log_x().log_y().series(nan));
}

#[test]
fn extreme_values_do_not_panic() {
    let points = [(f64::MAX, f64::MIN), (1e300, -1e300), (f64::MIN_POSITIVE, 0.0), (-f64::MAX, f64::MAX)];
    for chart in [Chart::new(""), Chart::new("").log_x(), Chart::new("").log_y().y_range(1e-300, 1e300)] {
        let _ = chart.series(Series::new("", points, SeriesStyle::LineAndMarkers)).render();
    }
    let _ = one_point(1e300, 1e-300, SeriesStyle::Markers).log_x().log_y().render();
    let _ = one_point(1e9, 1e9 + 1e-6, SeriesStyle::Line).render();
    let _ = one_point(0.0, 0.0, SeriesStyle::Markers).x_range(5.0, 6.0).render();
}

#[test]
fn unusable_ranges_and_sizes_are_refused() {
    let bad = [
        Chart::new("").x_range(1.0, 1.0),
        Chart::new("").y_range(2.0, 1.0),
        Chart::new("").x_range(f64::NAN, 1.0),
        Chart::new("").y_range(0.0, f64::INFINITY),
        Chart::new("").x_range(-f64::MAX, f64::MAX),
        Chart::new("").log_y().y_range(0.0, 10.0),
        Chart::new("").size(40, 30),
        Chart::new("").size(0, 0),
        Chart::new("").size(MAX_SIDE + 1, 100),
    ];
    for chart in bad {
        assert!(chart.render().is_err(), "{chart:?} renders");
    }
}

#[test]
fn legend_keeps_off_the_data() {
    // Markers fill the top-right corner, where the legend goes first.
    let corner = (0..2601).map(|i| (1.5 + 0.01 * (i % 51) as f64, 1.5 + 0.01 * (i / 51) as f64));
    let chart = Chart::new("")
        .x_range(0.0, 2.0)
        .y_range(0.0, 2.0)
        .series(Series::new("a long series name", corner, SeriesStyle::Markers).color(RED));
    let (canvas, area) = rendered(&chart);
    assert_eq!(pixel_at(&canvas, &area, (0.875, 0.875)), Some(RED));
}

#[test]
fn x_tick_labels_do_not_touch() {
    let wide = one_point(123456.0, 1.0, SeriesStyle::Markers).x_range(100000.0, 900000.0).size(500, 300);
    let area = rendered(&wide).1;
    let (scale, ticks, labels) = wide.fit_x_ticks(None, area.width).expect("x ticks");
    assert!(ticks.len() >= 2, "{labels:?}");
    let at = |t: f64| scale.fraction(t).unwrap_or(0.0) * area.width as f64;
    let half_w = |l: &String| Canvas::text_width(l, TEXT_SCALE) as f64 / 2.0;
    for i in 1..ticks.len() {
        assert!(at(ticks[i]) - at(ticks[i - 1]) > half_w(&labels[i]) + half_w(&labels[i - 1]), "{labels:?} overlap");
    }
}

#[test]
fn legend_moves_beside_the_plot_when_every_corner_has_data() {
    let full = |name: &str| {
        let lines = [(0.0, 0.1), (2.0, 0.1), (f64::NAN, 0.0), (0.0, 1.9), (2.0, 1.9)];
        Chart::new("").x_range(0.0, 2.0).y_range(0.0, 2.0).series(Series::new(name, lines, SeriesStyle::Line))
    };
    let (_, unnamed) = rendered(&full(""));
    let (canvas, named) = rendered(&full("border"));
    assert!(named.width < unnamed.width, "{named:?} is not narrower than {unnamed:?}");
    assert_eq!(pixel_at(&canvas, &named, (0.95, 0.95)), Some(PALETTE[0]));
}
