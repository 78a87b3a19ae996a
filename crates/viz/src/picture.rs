//! PNG pictures of 2D scalar slices (distance maps) with a colour bar;
//! slices of a map can carry axes in metres and the slice's position.

use std::path::Path;

use crate::font::{self, glyph};
use crate::VizError;
use edtmap_core::VoxelState;

/// An RGB colour.
pub type Rgb = [u8; 3];

/// Colour of cells whose value is exactly zero (obstacles).
pub const OBSTACLE_RGB: Rgb = [0, 0, 0];
/// Colour of cells whose value is not finite (no obstacle, unknown).
pub const NO_VALUE_RGB: Rgb = [150, 150, 150];
const BACKGROUND_RGB: Rgb = [255, 255, 255];
const TEXT_RGB: Rgb = [20, 20, 20];

/// Viridis colour map anchors at t = 0, 0.1, ..., 1 (matplotlib's values).
const VIRIDIS: [Rgb; 11] = [
    [68, 1, 84],
    [72, 36, 117],
    [65, 68, 135],
    [53, 95, 141],
    [42, 120, 142],
    [33, 145, 140],
    [34, 168, 132],
    [68, 191, 112],
    [122, 209, 81],
    [189, 223, 38],
    [253, 231, 37],
];

/// The viridis colour of `t` in `[0, 1]` (clamped), linearly interpolated.
pub fn viridis(t: f32) -> Rgb {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } * 10.0;
    let i = (t.floor() as usize).min(9);
    let f = t - i as f32;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    std::array::from_fn(|c| (a[c] as f32 + (b[c] as f32 - a[c] as f32) * f).round() as u8)
}

/// An RGB image being drawn.
#[derive(Debug, Clone)]
pub struct Canvas {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Canvas {
    /// A white canvas of `width` x `height` pixels.
    pub fn new(width: usize, height: usize) -> Self {
        Canvas { width, height, rgb: BACKGROUND_RGB.repeat(width * height) }
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The colour at `(x, y)` (row 0 at the top), or `None` outside.
    pub fn pixel(&self, x: usize, y: usize) -> Option<Rgb> {
        (x < self.width && y < self.height).then(|| {
            let i = 3 * (y * self.width + x);
            [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
        })
    }

    /// Fills a rectangle, clipped to the canvas.
    pub fn fill_rect(&mut self, x0: usize, y0: usize, w: usize, h: usize, color: Rgb) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                let i = 3 * (y * self.width + x);
                self.rgb[i..i + 3].copy_from_slice(&color);
            }
        }
    }

    /// Draws `text` with its top-left corner at `(x, y)`, each font pixel
    /// `scale` pixels wide.
    pub fn text(&mut self, x: usize, y: usize, text: &str, scale: usize, color: Rgb) {
        for (k, c) in text.chars().enumerate() {
            let gx = x + k * (font::WIDTH + 1) * scale;
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..font::WIDTH {
                    if bits >> (font::WIDTH - 1 - col) & 1 == 1 {
                        self.fill_rect(gx + col * scale, y + row * scale, scale, scale, color);
                    }
                }
            }
        }
    }

    /// Width in pixels of `text` drawn at `scale`.
    pub fn text_width(text: &str, scale: usize) -> usize {
        text.chars().count() * (font::WIDTH + 1) * scale
    }

    /// Writes the canvas as an 8-bit RGB PNG.
    pub fn save_png(&self, path: &Path) -> Result<(), VizError> {
        let mut file = edtmap_io::files::AtomicFile::create(path)?;
        let png_err = |error| VizError::Png { path: path.into(), error };
        let mut enc = png::Encoder::new(&mut file, self.width as u32, self.height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(png_err)?;
        writer.write_image_data(&self.rgb).map_err(png_err)?;
        writer.finish().map_err(png_err)?;
        Ok(file.commit()?)
    }
}

/// Labels and scale of a slice picture.
#[derive(Debug, Clone, PartialEq)]
pub struct SliceStyle {
    /// Title drawn above the map.
    pub title: String,
    /// Unit of the values, drawn under the colour bar.
    pub unit: String,
    /// Value at the top of the colour bar; `None` uses the largest finite
    /// value of the slice.
    pub max_value: Option<f32>,
    /// Axes in metres and the slice's position, for slices of a map.
    pub axes: Option<MapAxes>,
}

/// Where a slice of a map lies in the world: drawn as ticked axes in
/// metres along x (right) and y (up) and a caption with the position.
#[derive(Debug, Clone, PartialEq)]
pub struct MapAxes {
    /// World x and y of the lower left corner of cell (0, 0), metres.
    pub origin_m: [f64; 2],
    /// Edge length of one cell, metres.
    pub cell_m: f64,
    /// The slice's position across the plane, e.g. `z = 1.25 m`.
    pub position: String,
}

/// A 2D scalar field of `width` x `height` cells, row `y` at
/// `values[y * width..]`, drawn with `y` increasing upwards (as a map).
#[derive(Debug, Clone, Copy)]
pub struct Slice<'a> {
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// Values, row-major.
    pub values: &'a [f32],
}

const MARGIN: usize = 12;
const BAR_WIDTH: usize = 20;
const TEXT_SCALE: usize = 2;
/// Length of an axis tick, pixels.
const TICK: usize = 4;
/// Map pixels per axis tick, about.
const PIXELS_PER_TICK: usize = 80;

/// Where a map of cells goes on a canvas: under the title, right of the
/// y axis labels, above the x axis labels and caption when it has axes.
pub(crate) struct MapLayout {
    left: usize,
    top: usize,
    pub(crate) scale: usize,
    map_w: usize,
    map_h: usize,
    /// Room under the map for the x labels and the caption, pixels.
    below: usize,
    /// Narrowest canvas that holds the caption.
    min_width: usize,
    x_ticks: Vec<(f64, String)>,
    y_ticks: Vec<(f64, String)>,
    caption: String,
}

impl MapLayout {
    /// The layout of `cells_x` x `cells_y` cells, each drawn as a square of
    /// the largest scale that keeps the map within 512 pixels.
    pub(crate) fn new(cells_x: usize, cells_y: usize, axes: Option<&MapAxes>) -> Self {
        let scale = (512 / cells_x.max(cells_y)).max(1);
        let (map_w, map_h) = (cells_x * scale, cells_y * scale);
        let text_h = font::HEIGHT * TEXT_SCALE;
        let mut layout = MapLayout {
            left: MARGIN,
            top: MARGIN + text_h + MARGIN,
            scale,
            map_w,
            map_h,
            below: 0,
            min_width: 0,
            x_ticks: Vec::new(),
            y_ticks: Vec::new(),
            caption: String::new(),
        };
        if let Some(a) = axes {
            layout.x_ticks = axis_ticks(a.origin_m[0], a.cell_m * cells_x as f64, map_w);
            layout.y_ticks = axis_ticks(a.origin_m[1], a.cell_m * cells_y as f64, map_h);
            let label_w = layout.y_ticks.iter().map(|(_, l)| Canvas::text_width(l, TEXT_SCALE)).max().unwrap_or(0);
            layout.left = MARGIN + label_w + TICK + 2;
            layout.below = TICK + 2 + text_h + 6 + text_h;
            layout.caption = format!("x, y in m; {}", a.position);
            layout.min_width = layout.left + Canvas::text_width(&layout.caption, TEXT_SCALE) + MARGIN;
        }
        layout
    }

    /// Top left pixel of cell `(x, y)` of a map `cells_y` cells high, `y` upwards.
    pub(crate) fn cell(&self, x: usize, y: usize, cells_y: usize) -> (usize, usize) {
        (self.left + x * self.scale, self.top + (cells_y - 1 - y) * self.scale)
    }

    /// Draws the ticks, their labels and the caption of `axes`.
    fn draw_axes(&self, canvas: &mut Canvas, axes: &MapAxes) {
        let text_h = font::HEIGHT * TEXT_SCALE;
        let bottom = self.top + self.map_h;
        let offset = |t: f64, origin: f64, len: usize| {
            (((t - origin) / axes.cell_m * self.scale as f64).round().max(0.0) as usize).min(len.saturating_sub(1))
        };
        for (t, label) in &self.x_ticks {
            let px = self.left + offset(*t, axes.origin_m[0], self.map_w);
            canvas.fill_rect(px, bottom, 1, TICK, TEXT_RGB);
            let w = Canvas::text_width(label, TEXT_SCALE);
            let x = px.saturating_sub(w / 2).min((self.left + self.map_w).saturating_sub(w));
            canvas.text(x, bottom + TICK + 2, label, TEXT_SCALE, TEXT_RGB);
        }
        for (t, label) in &self.y_ticks {
            let py = bottom - 1 - offset(*t, axes.origin_m[1], self.map_h);
            canvas.fill_rect(self.left - TICK, py, TICK, 1, TEXT_RGB);
            let x = (self.left - TICK - 2).saturating_sub(Canvas::text_width(label, TEXT_SCALE));
            canvas.text(x, py.saturating_sub(text_h / 2), label, TEXT_SCALE, TEXT_RGB);
        }
        canvas.text(self.left, bottom + TICK + 2 + text_h + 6, &self.caption, TEXT_SCALE, TEXT_RGB);
    }
}

/// The ticks of an axis from `lo` over `span` metres drawn `pixels`
/// long: multiples of a step of 1, 2 or 5 × 10^k, with labels of as many
/// decimals as the step needs.
fn axis_ticks(lo: f64, span: f64, pixels: usize) -> Vec<(f64, String)> {
    let step = tick_step(span, (pixels / PIXELS_PER_TICK).clamp(2, 8));
    let (first, last) = ((lo / step - 1e-9).ceil(), ((lo + span) / step + 1e-9).floor());
    if !(step > 0.0 && first.is_finite() && last.is_finite() && first <= last && last - first <= 50.0) {
        return Vec::new();
    }
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    // Adding 0.0 turns -0.0 into 0.0, so the origin never reads "-0".
    (0..=(last - first) as usize)
        .map(|i| (first + i as f64) * step)
        .map(|t| (t, format!("{:.*}", decimals, t + 0.0)))
        .collect()
}

/// The smallest step of 1, 2 or 5 × 10^k that splits `span` into at most
/// `count` intervals; NaN when `span` is not positive and finite.
fn tick_step(span: f64, count: usize) -> f64 {
    let raw = span / count as f64;
    if !(raw.is_finite() && raw > 0.0) {
        return f64::NAN;
    }
    let k = raw.log10().floor();
    [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * 10f64.powf(k)).find(|&s| s >= raw * (1.0 - 1e-9)).unwrap_or(f64::NAN)
}

/// Renders `slice` with viridis colours, obstacles (0) black and cells
/// without a finite value grey, plus a labelled colour bar, and with
/// `style.axes` axes in metres and the slice's position.
pub fn render_slice(slice: Slice<'_>, style: &SliceStyle) -> Canvas {
    let vmax = style
        .max_value
        .unwrap_or_else(|| slice.values.iter().copied().filter(|v| v.is_finite()).fold(0.0, f32::max))
        .max(f32::MIN_POSITIVE);
    let layout = MapLayout::new(slice.width, slice.height, style.axes.as_ref());
    let (top, map_h, scale) = (layout.top, layout.map_h, layout.scale);
    let text_h = font::HEIGHT * TEXT_SCALE;
    let labels = [format!("{vmax:.2}"), format!("{:.2}", vmax / 2.0), "0".to_string()];
    let label_w = labels.iter().chain([&style.unit]).map(|l| Canvas::text_width(l, TEXT_SCALE)).max();
    let bar_x = layout.left + layout.map_w + MARGIN;
    let width = (bar_x + BAR_WIDTH + 6 + label_w.unwrap_or(0) + MARGIN)
        .max(MARGIN + Canvas::text_width(&style.title, TEXT_SCALE) + MARGIN)
        .max(layout.min_width);
    let height = top + map_h.max(3 * text_h) + layout.below.max(MARGIN + text_h) + MARGIN;
    let mut canvas = Canvas::new(width, height);
    canvas.text(MARGIN, MARGIN, &style.title, TEXT_SCALE, TEXT_RGB);
    for y in 0..slice.height {
        for x in 0..slice.width {
            let v = slice.values[y * slice.width + x];
            let color = if !v.is_finite() {
                NO_VALUE_RGB
            } else if v == 0.0 {
                OBSTACLE_RGB
            } else {
                viridis(v / vmax)
            };
            let (px, py) = layout.cell(x, y, slice.height);
            canvas.fill_rect(px, py, scale, scale, color);
        }
    }
    if let Some(axes) = &style.axes {
        layout.draw_axes(&mut canvas, axes);
    }
    for row in 0..map_h {
        let t = 1.0 - row as f32 / (map_h.max(2) - 1) as f32;
        canvas.fill_rect(bar_x, top + row, BAR_WIDTH, 1, viridis(t));
    }
    let label_x = bar_x + BAR_WIDTH + 6;
    let last = map_h.saturating_sub(text_h);
    for (label, y) in labels.iter().zip([0, last / 2, last]) {
        canvas.text(label_x, top + y, label, TEXT_SCALE, TEXT_RGB);
    }
    canvas.text(label_x, top + map_h + MARGIN, &style.unit, TEXT_SCALE, TEXT_RGB);
    canvas
}

/// Renders `slice` (see [`render_slice`]) and writes it as a PNG.
pub fn write_slice_png(path: &Path, slice: Slice<'_>, style: &SliceStyle) -> Result<(), VizError> {
    if slice.values.len() != slice.width * slice.height || slice.values.is_empty() {
        return Err(VizError::BadData {
            path: path.into(),
            reason: format!(
                "slice of {} x {} cells needs {} values, got {}",
                slice.width,
                slice.height,
                slice.width * slice.height,
                slice.values.len()
            ),
        });
    }
    render_slice(slice, style).save_png(path)
}

/// Colours of the occupancy states: unknown, free, occupied.
pub const STATE_RGB: [Rgb; 3] = [[150, 150, 150], [245, 245, 235], [20, 20, 20]];

/// Renders a slice of occupancy states (unknown grey, free white, occupied
/// black; `y` upwards) with a legend, and with `axes` axes in metres and
/// the slice's position.
pub fn render_states(
    width: usize,
    height: usize,
    states: &[VoxelState],
    title: &str,
    axes: Option<&MapAxes>,
) -> Canvas {
    let layout = MapLayout::new(width, height, axes);
    let (top, scale) = (layout.top, layout.scale);
    let text_h = font::HEIGHT * TEXT_SCALE;
    let names = ["unknown", "free", "occupied"];
    let legend_w = names.iter().map(|n| Canvas::text_width(n, TEXT_SCALE)).max().unwrap_or(0) + text_h + 6;
    let lx = layout.left + layout.map_w + MARGIN;
    let canvas_w =
        (lx + legend_w + MARGIN).max(MARGIN + Canvas::text_width(title, TEXT_SCALE) + MARGIN).max(layout.min_width);
    let canvas_h = top + (layout.map_h + layout.below).max(3 * (text_h + MARGIN)) + MARGIN;
    let mut canvas = Canvas::new(canvas_w, canvas_h);
    canvas.text(MARGIN, MARGIN, title, TEXT_SCALE, TEXT_RGB);
    for y in 0..height {
        for x in 0..width {
            let color = STATE_RGB[states[y * width + x] as usize];
            let (px, py) = layout.cell(x, y, height);
            canvas.fill_rect(px, py, scale, scale, color);
        }
    }
    if let Some(axes) = axes {
        layout.draw_axes(&mut canvas, axes);
    }
    for (i, name) in names.iter().enumerate() {
        let y = top + i * (text_h + MARGIN);
        canvas.fill_rect(lx, y, text_h, text_h, TEXT_RGB);
        canvas.fill_rect(lx + 1, y + 1, text_h - 2, text_h - 2, STATE_RGB[i]);
        canvas.text(lx + text_h + 6, y, name, TEXT_SCALE, TEXT_RGB);
    }
    canvas
}

/// Renders a slice of states (see [`render_states`]) and writes it as a PNG.
pub fn write_states_png(
    path: &Path,
    width: usize,
    height: usize,
    states: &[VoxelState],
    title: &str,
    axes: Option<&MapAxes>,
) -> Result<(), VizError> {
    if states.len() != width * height || states.is_empty() {
        return Err(VizError::BadData {
            path: path.into(),
            reason: format!("slice of {width} x {height} cells needs {} states, got {}", width * height, states.len()),
        });
    }
    render_states(width, height, states, title, axes).save_png(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn viridis_endpoints() {
        assert_eq!(viridis(0.0), VIRIDIS[0]);
        assert_eq!(viridis(1.0), VIRIDIS[10]);
        assert_eq!(viridis(2.0), VIRIDIS[10]);
        assert_eq!(viridis(f32::NAN), VIRIDIS[0]);
    }

    #[test]
    fn slice_colours_obstacles_and_missing_values() {
        // 2 x 2 cells: obstacle at (0, 0), far at (1, 0), inf on row 1.
        let values = [0.0, 4.0, f32::INFINITY, 2.0];
        let style = SliceStyle { title: "t".into(), unit: "vox".into(), max_value: None, axes: None };
        let c = render_slice(Slice { width: 2, height: 2, values: &values }, &style);
        let scale = 256;
        let top = MARGIN + font::HEIGHT * TEXT_SCALE + MARGIN;
        // Row y = 0 is drawn at the bottom of the map.
        let bottom = top + scale + scale / 2;
        assert_eq!(c.pixel(MARGIN + scale / 2, bottom), Some(OBSTACLE_RGB));
        assert_eq!(c.pixel(MARGIN + scale + scale / 2, bottom), Some(VIRIDIS[10]));
        assert_eq!(c.pixel(MARGIN + scale / 2, top + scale / 2), Some(NO_VALUE_RGB));
        assert_eq!(c.pixel(MARGIN + scale + scale / 2, top + scale / 2), Some(viridis(0.5)));
    }

    #[test]
    fn state_slice_colours_each_state() {
        let states = [VoxelState::Unknown, VoxelState::Free, VoxelState::Occupied, VoxelState::Free];
        let c = render_states(2, 2, &states, "occupancy", None);
        let scale = 256;
        let top = MARGIN + font::HEIGHT * TEXT_SCALE + MARGIN;
        let bottom = top + scale + scale / 2;
        assert_eq!(c.pixel(MARGIN + scale / 2, bottom), Some(STATE_RGB[0]));
        assert_eq!(c.pixel(MARGIN + scale + scale / 2, bottom), Some(STATE_RGB[1]));
        assert_eq!(c.pixel(MARGIN + scale / 2, top + scale / 2), Some(STATE_RGB[2]));
    }

    /// Whether any pixel of the rectangle is drawn in the text colour.
    fn has_text(c: &Canvas, xs: std::ops::Range<usize>, ys: std::ops::Range<usize>) -> bool {
        ys.flat_map(|y| xs.clone().map(move |x| (x, y))).any(|(x, y)| c.pixel(x, y) == Some(TEXT_RGB))
    }

    #[test]
    fn map_slices_get_labelled_axes_and_their_position() {
        // 40 x 20 cells of 0.1 m from (-2, -1) m, drawn 480 x 240 pixels:
        // at most 6 and 3 intervals, so ticks every 1 m on both axes.
        let axes = MapAxes { origin_m: [-2.0, -1.0], cell_m: 0.1, position: "z = 1.25 m".into() };
        let values = vec![1.0; 40 * 20];
        let plain = SliceStyle { title: "t".into(), unit: "m".into(), max_value: None, axes: None };
        let with_axes = SliceStyle { axes: Some(axes.clone()), ..plain.clone() };
        let slice = Slice { width: 40, height: 20, values: &values };
        let (bare, drawn) = (render_slice(slice, &plain), render_slice(slice, &with_axes));
        let layout = MapLayout::new(40, 20, Some(&axes));
        let labels = |ticks: &[(f64, String)]| ticks.iter().map(|(_, l)| l.clone()).collect::<Vec<_>>();
        assert_eq!(labels(&layout.x_ticks), ["-2", "-1", "0", "1", "2"]);
        assert_eq!(labels(&layout.y_ticks), ["-1", "0", "1"]);
        assert_eq!(layout.caption, "x, y in m; z = 1.25 m");
        // The y labels widen the picture and sit left of the map; the x
        // labels and the caption sit under it.
        assert!(drawn.size().0 > bare.size().0 && drawn.size().1 > bare.size().1);
        let bottom = layout.top + layout.map_h;
        assert!(has_text(&drawn, MARGIN..layout.left - TICK, layout.top..bottom));
        assert!(has_text(&drawn, layout.left..layout.left + layout.map_w, bottom + TICK..drawn.size().1));
        assert!(!has_text(&bare, 0..MARGIN, layout.top..bottom));
        // The map itself is where the layout says.
        assert_eq!(drawn.pixel(layout.left + 1, layout.top + 1), Some(VIRIDIS[10]));
        let states = vec![VoxelState::Free; 40 * 20];
        let c = render_states(40, 20, &states, "occupancy", Some(&axes));
        assert!(has_text(&c, MARGIN..layout.left - TICK, layout.top..bottom));
        assert!(has_text(&c, layout.left..layout.left + layout.map_w, bottom + TICK..c.size().1));
    }

    #[test]
    fn tick_steps_are_one_two_or_five_times_a_power_of_ten() {
        assert_eq!(tick_step(10.0, 5), 2.0);
        assert_eq!(tick_step(3.0, 5), 1.0);
        assert_eq!(tick_step(0.8, 4), 0.2);
        assert!(tick_step(0.0, 4).is_nan() && tick_step(f64::NAN, 4).is_nan());
        assert!(axis_ticks(0.0, f64::INFINITY, 400).is_empty());
    }
}
