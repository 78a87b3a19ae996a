//! Line and scatter charts as PNG pictures, for benchmark results and
//! per-frame run reports (times against change scores, errors against
//! voxel sizes, stage times over a run).
//!
//! A [`Chart`] is built with chained calls and drawn on the crate's own
//! [`Canvas`] with its bitmap font, so no plotting or font dependency is
//! needed. Axis ranges are automatic unless given: the finite data range
//! widened to "nice" ticks (1, 2 or 5 × 10^k; whole decades on a log axis).
//!
//! Points that cannot be drawn (NaN, infinite, or ≤ 0 on a log axis) are
//! skipped, and a line breaks where one is skipped. A chart without any
//! drawable point is not an error: it draws empty axes over 0..1 (1..10 on
//! a log axis), or over the ranges given. Only an unusable explicit range
//! or picture size is an error ([`VizError::BadChart`]).
//!
//! The legend lists the series that have a name. It sits in the corner of
//! the plot area where it hides the fewest drawn pixels, or beside the plot
//! area when every corner would hide some.
//!
//! ```
//! use edtmap_viz::plot::{Chart, Series, SeriesStyle};
//!
//! let frames = (0..50).map(|i| (i as f64, 2.0 + (i as f64 / 7.0).sin()));
//! let chart = Chart::new("Stage times")
//!     .x_label("frame")
//!     .y_label("time (ms)")
//!     .series(Series::new("EDT", frames, SeriesStyle::Line));
//! let path = std::env::temp_dir().join("edtmap_plot_doc.png");
//! chart.write_png(&path)?;
//! # std::fs::remove_file(&path).ok();
//! # Ok::<(), edtmap_viz::VizError>(())
//! ```

mod draw;
mod ticks;

use std::path::Path;

use crate::font;
use crate::picture::{Canvas, Rgb};
use crate::VizError;

/// Default colours of the series, in order of addition (matplotlib's
/// "tab10"); the eleventh series takes the first colour again.
pub const PALETTE: [Rgb; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [127, 127, 127],
    [188, 189, 34],
    [23, 190, 207],
];
/// Default picture width in pixels.
pub const DEFAULT_WIDTH: usize = 800;
/// Default picture height in pixels.
pub const DEFAULT_HEIGHT: usize = 500;
/// Largest picture side in pixels.
pub const MAX_SIDE: usize = 16384;

const MARGIN: usize = 12;
const GAP: usize = 6;
const TICK_LEN: usize = 5;
const TEXT_SCALE: usize = 2;
const TITLE_SCALE: usize = 3;
/// Smallest plot area side in pixels; a smaller picture is refused.
const MIN_PLOT_SIDE: usize = 32;
/// Least free space between neighbouring x tick labels, in pixels.
const LABEL_SPACING: f64 = 16.0;

/// A range of values `(min, max)` along an axis.
type Range = (f64, f64);

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SeriesStyle {
    /// Straight lines between consecutive points.
    #[default]
    Line,
    /// A filled disc at each point (a scatter plot).
    Markers,
    /// Lines and discs.
    LineAndMarkers,
}

/// A named sequence of `(x, y)` points and how to draw them.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    name: String,
    points: Vec<(f64, f64)>,
    style: SeriesStyle,
    color: Option<Rgb>,
}

impl Series {
    /// A series drawn in the palette colour of its place in the chart. An
    /// empty name leaves it out of the legend.
    pub fn new(name: impl Into<String>, points: impl IntoIterator<Item = (f64, f64)>, style: SeriesStyle) -> Self {
        Series { name: name.into(), points: points.into_iter().collect(), style, color: None }
    }

    /// Draws the series in `color` instead of its palette colour.
    pub fn color(mut self, color: Rgb) -> Self {
        self.color = Some(color);
        self
    }
}

/// One axis as configured.
#[derive(Debug, Clone, Default, PartialEq)]
struct Axis {
    label: String,
    log: bool,
    range: Option<Range>,
}

/// A line or scatter chart: title, two labelled axes, series and a legend.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    title: String,
    x: Axis,
    y: Axis,
    series: Vec<Series>,
    width: usize,
    height: usize,
}

impl Chart {
    /// An empty chart of [`DEFAULT_WIDTH`] x [`DEFAULT_HEIGHT`] pixels
    /// titled `title` (empty for none).
    pub fn new(title: impl Into<String>) -> Self {
        let (x, y) = (Axis::default(), Axis::default());
        Chart { title: title.into(), x, y, series: Vec::new(), width: DEFAULT_WIDTH, height: DEFAULT_HEIGHT }
    }

    /// Sets the picture size in pixels (each side at most [`MAX_SIDE`]).
    pub fn size(mut self, width: usize, height: usize) -> Self {
        (self.width, self.height) = (width, height);
        self
    }

    /// Labels the x axis, units included, e.g. `"voxel size (m)"`.
    pub fn x_label(mut self, label: impl Into<String>) -> Self {
        self.x.label = label.into();
        self
    }

    /// Labels the y axis (drawn reading upwards).
    pub fn y_label(mut self, label: impl Into<String>) -> Self {
        self.y.label = label.into();
        self
    }

    /// Draws the x axis on a log10 scale.
    pub fn log_x(mut self) -> Self {
        self.x.log = true;
        self
    }

    /// Draws the y axis on a log10 scale.
    pub fn log_y(mut self) -> Self {
        self.y.log = true;
        self
    }

    /// Fixes the x axis range to `[min, max]` (finite, `min < max`,
    /// `min > 0` on a log axis); points outside are clipped.
    pub fn x_range(mut self, min: f64, max: f64) -> Self {
        self.x.range = Some((min, max));
        self
    }

    /// Fixes the y axis range to `[min, max]`, as [`Chart::x_range`].
    pub fn y_range(mut self, min: f64, max: f64) -> Self {
        self.y.range = Some((min, max));
        self
    }

    /// Adds a series, drawn over the ones added before.
    pub fn series(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }

    /// Draws the chart and writes it as an 8-bit RGB PNG at `path`.
    ///
    /// Fails with [`VizError::BadChart`] on an explicit range that is empty,
    /// not finite or not positive on a log axis, on a picture side over
    /// [`MAX_SIDE`], or on a picture too small for its labels; and with
    /// [`VizError::Io`] or [`VizError::Png`] when writing fails.
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<(), VizError> {
        let path = path.as_ref();
        let (canvas, _) = self.render().map_err(|reason| VizError::BadChart { path: path.into(), reason })?;
        canvas.save_png(path)
    }

    /// Draws the chart with the legend in a corner of the plot area, or
    /// beside it when every corner would cover data; also returns where
    /// the plot area lies.
    fn render(&self) -> Result<(Canvas, draw::PlotArea), String> {
        let (canvas, area, covered) = self.render_with(false)?;
        if covered == 0 {
            return Ok((canvas, area));
        }
        Ok(self.render_with(true).map_or((canvas, area), |(canvas, area, _)| (canvas, area)))
    }

    /// Draws the chart, the legend beside the plot area when
    /// `legend_beside`; also returns the plot area and how many drawn
    /// pixels the legend covers.
    fn render_with(&self, legend_beside: bool) -> Result<(Canvas, draw::PlotArea, usize), String> {
        let colors: Vec<Rgb> =
            self.series.iter().enumerate().map(|(i, s)| s.color.unwrap_or(PALETTE[i % PALETTE.len()])).collect();
        let named = self.series.iter().zip(&colors).filter(|(s, _)| !s.name.is_empty());
        let entries: Vec<_> = named.map(|(s, &c)| (s.name.as_str(), s.style, c)).collect();
        let legend = draw::Legend::new(&entries);
        let beside_w = match (legend_beside, &legend) {
            (false, _) => 0,
            (true, Some(legend)) => legend.width + GAP,
            (true, None) => return Err("no legend to draw".into()),
        };
        let layout = self.layout(beside_w)?;
        let area = layout.area;
        if legend_beside && legend.as_ref().is_some_and(|l| l.height > area.height) {
            return Err("legend taller than the plot".into());
        }
        let mut canvas = Canvas::new(self.width, self.height);
        area.grid(&mut canvas, &layout.x_ticks, &layout.y_ticks);
        for (series, &color) in self.series.iter().zip(&colors) {
            let (x, y) = (layout.x, layout.y);
            let fractions = series.points.iter().map(|&(px, py)| Some((x.fraction(px)?, y.fraction(py)?)));
            area.series(&mut canvas, fractions, series.style, color);
        }
        area.frame(&mut canvas, &layout.x_ticks, &layout.y_ticks);
        let covered = match legend {
            None => 0,
            Some(legend) if legend_beside => {
                legend.draw(&mut canvas, (area.left + area.width + 2 * GAP, area.top));
                0
            }
            Some(legend) => match legend.best_corner(&canvas, &area) {
                Some((corner, covered)) => {
                    legend.draw(&mut canvas, corner);
                    covered
                }
                None => usize::MAX,
            },
        };
        area.titles(&mut canvas, &self.title, layout.title_scale, &self.x.label, &self.y.label);
        Ok((canvas, area, covered))
    }

    /// Where the plot area and the ticks go, with `beside_w` pixels kept
    /// free right of the plot area.
    fn layout(&self, beside_w: usize) -> Result<Layout, String> {
        let (width, height) = (self.width, self.height);
        if width > MAX_SIDE || height > MAX_SIDE {
            return Err(format!("size {width} x {height} exceeds {MAX_SIDE} pixels a side"));
        }
        let text_h = font::HEIGHT * TEXT_SCALE;
        let title_scale = draw::fit_scale(&self.title, width.saturating_sub(2 * MARGIN), TITLE_SCALE);
        let top = MARGIN + if self.title.is_empty() { 0 } else { font::HEIGHT * title_scale + MARGIN };
        let x_label_h = if self.x.label.is_empty() { 0 } else { GAP + text_h };
        let bottom = TICK_LEN + GAP + text_h + x_label_h + MARGIN;
        let too_small = || format!("size {width} x {height} leaves no room to plot");
        let plot_h = height.checked_sub(top + bottom).filter(|&h| h >= MIN_PLOT_SIDE).ok_or_else(too_small)?;
        let (x_data, y_data) = self.extents();
        let (y, y_ticks) = resolve(&self.y, "y", y_data, plot_h / (3 * text_h))?;
        let y_labels = ticks::labels(&y_ticks);
        let y_labels_w = y_labels.iter().map(|l| Canvas::text_width(l, TEXT_SCALE)).max().unwrap_or(0);
        let y_label_w = if self.y.label.is_empty() { 0 } else { text_h + GAP };
        let left = MARGIN + y_label_w + y_labels_w + GAP + TICK_LEN;
        let right = MARGIN + if beside_w > 0 { GAP + beside_w } else { 2 * text_h };
        let plot_w = width.checked_sub(left + right).filter(|&w| w >= MIN_PLOT_SIDE).ok_or_else(too_small)?;
        let (x, x_ticks, x_labels) = self.fit_x_ticks(x_data, plot_w)?;
        let place = |scale: Scale, ticks: Vec<f64>, labels: Vec<String>| -> Vec<(f64, String)> {
            ticks.into_iter().zip(labels).filter_map(|(t, l)| Some((scale.fraction(t)?, l))).collect()
        };
        Ok(Layout {
            area: draw::PlotArea { left, top, width: plot_w, height: plot_h },
            title_scale,
            x,
            y,
            x_ticks: place(x, x_ticks, x_labels),
            y_ticks: place(y, y_ticks, y_labels),
        })
    }

    /// The x axis with as many ticks as fit without their labels touching.
    fn fit_x_ticks(&self, data: Option<Range>, plot_w: usize) -> Result<(Scale, Vec<f64>, Vec<String>), String> {
        let mut max_count = (plot_w / 40).max(1);
        loop {
            let (scale, ticks) = resolve(&self.x, "x", data, max_count)?;
            let labels = ticks::labels(&ticks);
            let px = |t: f64| scale.fraction(t).unwrap_or(0.0) * (plot_w - 1) as f64;
            let half_w = |l: &String| Canvas::text_width(l, TEXT_SCALE) as f64 / 2.0;
            let room = |i: usize| half_w(&labels[i]) + half_w(&labels[i - 1]) + LABEL_SPACING;
            let fits = (1..ticks.len()).all(|i| px(ticks[i]) - px(ticks[i - 1]) >= room(i));
            if fits || max_count == 1 {
                return Ok((scale, ticks, labels));
            }
            max_count -= 1;
        }
    }

    /// The ranges of the drawable points along x and along y.
    fn extents(&self) -> (Option<Range>, Option<Range>) {
        let drawable = |v: f64, log: bool| v.is_finite() && (!log || v > 0.0);
        let widen = |r: Option<Range>, v: f64| Some(r.map_or((v, v), |(lo, hi)| (v.min(lo), v.max(hi))));
        let points = self.series.iter().flat_map(|s| &s.points);
        let points = points.filter(|&&(x, y)| drawable(x, self.x.log) && drawable(y, self.y.log));
        points.fold((None, None), |(xr, yr), &(x, y)| (widen(xr, x), widen(yr, y)))
    }
}

/// Where a chart's parts go.
struct Layout {
    area: draw::PlotArea,
    title_scale: usize,
    x: Scale,
    y: Scale,
    /// Ticks as axis fractions, with their labels.
    x_ticks: Vec<(f64, String)>,
    y_ticks: Vec<(f64, String)>,
}

/// An axis resolved for drawing.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Scale {
    lo: f64,
    hi: f64,
    log: bool,
}

impl Scale {
    /// How far along the axis `v` lies (0 at `lo`, 1 at `hi`), or `None`
    /// when it cannot be drawn on this axis.
    fn fraction(&self, v: f64) -> Option<f64> {
        let t = match self.log {
            _ if !v.is_finite() => return None,
            true if v <= 0.0 => return None,
            true => (v.log10() - self.lo.log10()) / (self.hi.log10() - self.lo.log10()),
            false => (v - self.lo) / (self.hi - self.lo),
        };
        t.is_finite().then_some(t)
    }
}

/// The range and ticks of `axis` (named `name` in errors), from its
/// explicit range or else from the `data` range, with about `max_count`
/// tick intervals.
fn resolve(axis: &Axis, name: &str, data: Option<Range>, max_count: usize) -> Result<(Scale, Vec<f64>), String> {
    let max_count = max_count.max(1);
    let (lo, hi) = match (axis.range, data) {
        (Some(range), _) => range,
        (None, Some((min, max))) => ticks::auto_range(min, max, axis.log, max_count),
        (None, None) if axis.log => (1.0, 10.0),
        (None, None) => (0.0, 1.0),
    };
    if !(lo < hi && (hi - lo).is_finite()) {
        return Err(format!("{name} range {lo}..{hi} is empty or not finite"));
    }
    if axis.log && lo <= 0.0 {
        return Err(format!("{name} range {lo}..{hi} is not positive, as a log axis needs"));
    }
    let ticks = match axis.log {
        true => ticks::log_ticks(lo, hi, max_count),
        false => ticks::linear_ticks(lo, hi, ticks::nice_step(hi - lo, max_count)),
    };
    Ok((Scale { lo, hi, log: axis.log }, ticks))
}

#[cfg(test)]
mod tests;
