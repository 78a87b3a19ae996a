//! PNG pictures of 2D scalar slices (distance maps) with a colour bar.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use crate::font::{self, glyph};
use crate::IoError;
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
    pub fn save_png(&self, path: &Path) -> Result<(), IoError> {
        let file = File::create(path).map_err(|e| IoError::io(path, e))?;
        let png_err = |error| IoError::Png { path: path.into(), error };
        let mut enc = png::Encoder::new(BufWriter::new(file), self.width as u32, self.height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(png_err)?;
        writer.write_image_data(&self.rgb).map_err(png_err)?;
        writer.finish().map_err(png_err)
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

/// Renders `slice` with viridis colours, obstacles (0) black and cells
/// without a finite value grey, plus a labelled colour bar.
pub fn render_slice(slice: Slice<'_>, style: &SliceStyle) -> Canvas {
    let vmax = style
        .max_value
        .unwrap_or_else(|| slice.values.iter().copied().filter(|v| v.is_finite()).fold(0.0, f32::max))
        .max(f32::MIN_POSITIVE);
    let scale = (512 / slice.width.max(slice.height)).max(1);
    let (map_w, map_h) = (slice.width * scale, slice.height * scale);
    let text_h = font::HEIGHT * TEXT_SCALE;
    let top = MARGIN + text_h + MARGIN;
    let labels = [format!("{vmax:.2}"), format!("{:.2}", vmax / 2.0), "0".to_string()];
    let label_w = labels.iter().chain([&style.unit]).map(|l| Canvas::text_width(l, TEXT_SCALE)).max();
    let bar_x = MARGIN + map_w + MARGIN;
    let width = (bar_x + BAR_WIDTH + 6 + label_w.unwrap_or(0) + MARGIN)
        .max(MARGIN + Canvas::text_width(&style.title, TEXT_SCALE) + MARGIN);
    let height = top + map_h.max(3 * text_h) + MARGIN + text_h + MARGIN;
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
            let py = top + (slice.height - 1 - y) * scale;
            canvas.fill_rect(MARGIN + x * scale, py, scale, scale, color);
        }
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
pub fn write_slice_png(path: &Path, slice: Slice<'_>, style: &SliceStyle) -> Result<(), IoError> {
    if slice.values.len() != slice.width * slice.height || slice.values.is_empty() {
        return Err(IoError::BadData {
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
/// black; `y` upwards) with a legend.
pub fn render_states(width: usize, height: usize, states: &[VoxelState], title: &str) -> Canvas {
    let scale = (512 / width.max(height)).max(1);
    let (map_w, map_h) = (width * scale, height * scale);
    let text_h = font::HEIGHT * TEXT_SCALE;
    let top = MARGIN + text_h + MARGIN;
    let names = ["unknown", "free", "occupied"];
    let legend_w = names.iter().map(|n| Canvas::text_width(n, TEXT_SCALE)).max().unwrap_or(0) + text_h + 6;
    let canvas_w = (MARGIN + map_w + MARGIN + legend_w + MARGIN).max(MARGIN + Canvas::text_width(title, TEXT_SCALE) + MARGIN);
    let canvas_h = top + map_h.max(3 * (text_h + MARGIN)) + MARGIN;
    let mut canvas = Canvas::new(canvas_w, canvas_h);
    canvas.text(MARGIN, MARGIN, title, TEXT_SCALE, TEXT_RGB);
    for y in 0..height {
        for x in 0..width {
            let color = STATE_RGB[states[y * width + x] as usize];
            canvas.fill_rect(MARGIN + x * scale, top + (height - 1 - y) * scale, scale, scale, color);
        }
    }
    let lx = MARGIN + map_w + MARGIN;
    for (i, name) in names.iter().enumerate() {
        let y = top + i * (text_h + MARGIN);
        canvas.fill_rect(lx, y, text_h, text_h, TEXT_RGB);
        canvas.fill_rect(lx + 1, y + 1, text_h - 2, text_h - 2, STATE_RGB[i]);
        canvas.text(lx + text_h + 6, y, name, TEXT_SCALE, TEXT_RGB);
    }
    canvas
}

/// Renders a slice of states (see [`render_states`]) and writes it as a PNG.
pub fn write_states_png(path: &Path, width: usize, height: usize, states: &[VoxelState], title: &str) -> Result<(), IoError> {
    if states.len() != width * height || states.is_empty() {
        return Err(IoError::BadData {
            path: path.into(),
            reason: format!("slice of {width} x {height} cells needs {} states, got {}", width * height, states.len()),
        });
    }
    render_states(width, height, states, title).save_png(path)
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
        let style = SliceStyle { title: "t".into(), unit: "vox".into(), max_value: None };
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
        let c = render_states(2, 2, &states, "occupancy");
        let scale = 256;
        let top = MARGIN + font::HEIGHT * TEXT_SCALE + MARGIN;
        let bottom = top + scale + scale / 2;
        assert_eq!(c.pixel(MARGIN + scale / 2, bottom), Some(STATE_RGB[0]));
        assert_eq!(c.pixel(MARGIN + scale + scale / 2, bottom), Some(STATE_RGB[1]));
        assert_eq!(c.pixel(MARGIN + scale / 2, top + scale / 2), Some(STATE_RGB[2]));
    }
}
