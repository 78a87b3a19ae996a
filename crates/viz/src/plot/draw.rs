//! Pixels of a chart: grid, series, frame with ticks, legend and titles.

use super::{SeriesStyle, GAP, MARGIN, TEXT_SCALE, TICK_LEN};
use crate::font;
use crate::picture::{Canvas, Rgb};

const BACKGROUND_RGB: Rgb = [255, 255, 255];
const TEXT_RGB: Rgb = [20, 20, 20];
const FRAME_RGB: Rgb = [60, 60, 60];
const GRID_RGB: Rgb = [225, 225, 225];
const LEGEND_BORDER_RGB: Rgb = [170, 170, 170];
/// Radius of a marker disc in pixels.
const MARKER_RADIUS: i64 = 3;
/// Line width in pixels.
const LINE_WIDTH: usize = 2;
/// Length of the line drawn for a series in the legend, in pixels.
const LEGEND_SAMPLE: usize = 24;

/// Where the data are drawn: `width` x `height` pixels from `(left, top)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct PlotArea {
    pub(super) left: usize,
    pub(super) top: usize,
    pub(super) width: usize,
    pub(super) height: usize,
}

/// The largest text scale up to `max` at which `text` fits in `room`
/// pixels (1 when none does: the text is then cut at the picture edge).
pub(super) fn fit_scale(text: &str, room: usize, max: usize) -> usize {
    (1..=max).rev().find(|&s| Canvas::text_width(text, s) <= room).unwrap_or(1)
}

impl PlotArea {
    /// The pixel of the axis fractions `(tx, ty)`, y upwards.
    pub(super) fn pixel(&self, (tx, ty): (f64, f64)) -> (f64, f64) {
        let x = self.left as f64 + tx * (self.width - 1) as f64;
        (x, self.top as f64 + (1.0 - ty) * (self.height - 1) as f64)
    }

    fn right(&self) -> usize {
        self.left + self.width
    }

    fn bottom(&self) -> usize {
        self.top + self.height
    }

    /// Light lines across the plot at the ticks (given as axis fractions).
    pub(super) fn grid(&self, canvas: &mut Canvas, x_ticks: &[(f64, String)], y_ticks: &[(f64, String)]) {
        for (t, _) in x_ticks {
            let (x, _) = self.pixel((*t, 0.0));
            canvas.fill_rect(x.round() as usize, self.top, 1, self.height, GRID_RGB);
        }
        for (t, _) in y_ticks {
            let (_, y) = self.pixel((0.0, *t));
            canvas.fill_rect(self.left, y.round() as usize, self.width, 1, GRID_RGB);
        }
    }

    /// Draws a series from its points as axis fractions (`None` for a
    /// point that cannot be drawn, which breaks the line). Lines are
    /// clipped to the plot area; markers of points inside it are drawn
    /// whole.
    pub(super) fn series(
        &self,
        canvas: &mut Canvas,
        points: impl Iterator<Item = Option<(f64, f64)>>,
        style: SeriesStyle,
        color: Rgb,
    ) {
        let lines = style != SeriesStyle::Markers;
        let markers = style != SeriesStyle::Line;
        let mut previous = None;
        for point in points {
            if let (true, Some(a), Some(b)) = (lines, previous, point) {
                if let Some((a, b)) = clip(a, b) {
                    segment(canvas, self.pixel(a), self.pixel(b), color);
                }
            }
            if let (true, Some(p)) = (markers, point) {
                let inside = |t: f64| (-1e-9..=1.0 + 1e-9).contains(&t);
                if inside(p.0) && inside(p.1) {
                    disc(canvas, self.pixel(p), color);
                }
            }
            previous = point;
        }
    }

    /// The frame, its tick marks and tick labels.
    pub(super) fn frame(&self, canvas: &mut Canvas, x_ticks: &[(f64, String)], y_ticks: &[(f64, String)]) {
        let (l, t, r, b) = (self.left, self.top, self.right(), self.bottom());
        canvas.fill_rect(l - 1, t - 1, self.width + 2, 1, FRAME_RGB);
        canvas.fill_rect(l - 1, b, self.width + 2, 1, FRAME_RGB);
        canvas.fill_rect(l - 1, t - 1, 1, self.height + 2, FRAME_RGB);
        canvas.fill_rect(r, t - 1, 1, self.height + 2, FRAME_RGB);
        let (canvas_w, _) = canvas.size();
        for (f, label) in x_ticks {
            let x = self.pixel((*f, 0.0)).0.round() as usize;
            canvas.fill_rect(x, b, 1, TICK_LEN + 1, FRAME_RGB);
            let w = Canvas::text_width(label, TEXT_SCALE);
            let lx = x.saturating_sub(w / 2).min(canvas_w.saturating_sub(w));
            canvas.text(lx, b + TICK_LEN + GAP, label, TEXT_SCALE, TEXT_RGB);
        }
        let text_h = font::HEIGHT * TEXT_SCALE;
        for (f, label) in y_ticks {
            let y = self.pixel((0.0, *f)).1.round() as usize;
            canvas.fill_rect(l - 1 - TICK_LEN, y, TICK_LEN, 1, FRAME_RGB);
            let lx = (l - 1 - TICK_LEN - GAP).saturating_sub(Canvas::text_width(label, TEXT_SCALE));
            canvas.text(lx, y.saturating_sub(text_h / 2), label, TEXT_SCALE, TEXT_RGB);
        }
    }

    /// The title above the plot and the axis labels beside it.
    pub(super) fn titles(&self, canvas: &mut Canvas, title: &str, title_scale: usize, x_label: &str, y_label: &str) {
        let (canvas_w, canvas_h) = canvas.size();
        let centred = |w: usize| (self.left + self.width / 2).saturating_sub(w / 2).min(canvas_w.saturating_sub(w));
        let title_w = Canvas::text_width(title, title_scale);
        let title_x = centred(title_w).max(MARGIN).min(canvas_w.saturating_sub(title_w));
        canvas.text(title_x, MARGIN, title, title_scale, TEXT_RGB);
        let text_h = font::HEIGHT * TEXT_SCALE;
        let x_w = Canvas::text_width(x_label, TEXT_SCALE);
        canvas.text(centred(x_w), canvas_h - MARGIN - text_h, x_label, TEXT_SCALE, TEXT_RGB);
        let y_w = Canvas::text_width(y_label, TEXT_SCALE);
        let bottom = (self.top + self.height / 2 + y_w / 2).min(canvas_h);
        text_upwards(canvas, MARGIN, bottom, y_label, TEXT_SCALE, TEXT_RGB);
    }
}

/// A boxed list of the named series: `(name, style, colour)` entries.
pub(super) struct Legend<'a> {
    entries: &'a [(&'a str, SeriesStyle, Rgb)],
    /// Width of the box in pixels.
    pub(super) width: usize,
    /// Height of the box in pixels.
    pub(super) height: usize,
}

impl<'a> Legend<'a> {
    /// The legend of `entries`, or `None` when there are none.
    pub(super) fn new(entries: &'a [(&'a str, SeriesStyle, Rgb)]) -> Option<Self> {
        let names_w = entries.iter().map(|(n, ..)| Canvas::text_width(n, TEXT_SCALE)).max()?;
        let row_h = font::HEIGHT * TEXT_SCALE + GAP;
        Some(Legend { entries, width: 3 * GAP + LEGEND_SAMPLE + names_w + GAP, height: GAP + entries.len() * row_h })
    }

    /// The corner of `area` where the legend covers the fewest drawn
    /// pixels, with their count; `None` when it does not fit inside.
    pub(super) fn best_corner(&self, canvas: &Canvas, area: &PlotArea) -> Option<((usize, usize), usize)> {
        let inset = GAP + 2;
        let x1 = area.right().checked_sub(inset + self.width).filter(|&x| x >= area.left + inset)?;
        let y1 = area.bottom().checked_sub(inset + self.height).filter(|&y| y >= area.top + inset)?;
        let (x0, y0) = (area.left + inset, area.top + inset);
        let drawn = |px, py| canvas.pixel(px, py).is_some_and(|c| c != BACKGROUND_RGB && c != GRID_RGB);
        let covered = |(x, y): (usize, usize)| {
            (y..y + self.height).map(|py| (x..x + self.width).filter(|&px| drawn(px, py)).count()).sum::<usize>()
        };
        [(x1, y0), (x0, y0), (x1, y1), (x0, y1)].into_iter().map(|c| (c, covered(c))).min_by_key(|&(_, n)| n)
    }

    /// Draws the legend with its top-left corner at `(x, y)`.
    pub(super) fn draw(&self, canvas: &mut Canvas, (x, y): (usize, usize)) {
        let text_h = font::HEIGHT * TEXT_SCALE;
        canvas.fill_rect(x, y, self.width, self.height, LEGEND_BORDER_RGB);
        canvas.fill_rect(x + 1, y + 1, self.width - 2, self.height - 2, BACKGROUND_RGB);
        for (i, &(name, style, color)) in self.entries.iter().enumerate() {
            let row_y = y + GAP + i * (text_h + GAP);
            let mid = (row_y + text_h / 2) as f64;
            let (a, b) = ((x + GAP) as f64, (x + GAP + LEGEND_SAMPLE) as f64);
            if style != SeriesStyle::Markers {
                segment(canvas, (a, mid), (b, mid), color);
            }
            if style != SeriesStyle::Line {
                disc(canvas, ((a + b) / 2.0, mid), color);
            }
            canvas.text(x + 2 * GAP + LEGEND_SAMPLE, row_y, name, TEXT_SCALE, TEXT_RGB);
        }
    }
}

/// A line of `LINE_WIDTH` pixels from `a` to `b` (pixel coordinates).
fn segment(canvas: &mut Canvas, a: (f64, f64), b: (f64, f64), color: Rgb) {
    let steps = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().max(1.0) as usize;
    let half = (LINE_WIDTH as f64 - 1.0) / 2.0;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let (x, y) = (a.0 + t * (b.0 - a.0) - half, a.1 + t * (b.1 - a.1) - half);
        canvas.fill_rect(x.round().max(0.0) as usize, y.round().max(0.0) as usize, LINE_WIDTH, LINE_WIDTH, color);
    }
}

/// A filled marker disc centred on pixel `(x, y)`.
fn disc(canvas: &mut Canvas, (x, y): (f64, f64), color: Rgb) {
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    let r = MARKER_RADIUS;
    for dy in -r..=r {
        let half = ((r * r + r - dy * dy) as f64).sqrt() as i64;
        if let (Ok(px), Ok(py)) = (usize::try_from(cx - half), usize::try_from(cy + dy)) {
            canvas.fill_rect(px, py, (2 * half + 1) as usize, 1, color);
        }
    }
}

/// The part of the segment from `a` to `b` (axis fractions) inside the unit
/// square, by Liang and Barsky's clipping.
fn clip(a: (f64, f64), b: (f64, f64)) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0), (dx, 1.0 - a.0), (-dy, a.1), (dy, 1.0 - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else if p < 0.0 {
            t0 = t0.max(q / p);
        } else {
            t1 = t1.min(q / p);
        }
    }
    (t0 <= t1).then_some(((a.0 + t0 * dx, a.1 + t0 * dy), (a.0 + t1 * dx, a.1 + t1 * dy)))
}

/// Draws `text` reading upwards (turned a quarter left), starting with its
/// baseline end at column `x`, row `bottom`.
fn text_upwards(canvas: &mut Canvas, x: usize, bottom: usize, text: &str, scale: usize, color: Rgb) {
    for (k, c) in text.chars().enumerate() {
        for (row, bits) in font::glyph(c).iter().enumerate() {
            for col in (0..font::WIDTH).filter(|col| bits >> (font::WIDTH - 1 - col) & 1 == 1) {
                let along = (k * (font::WIDTH + 1) + col + 1) * scale;
                if let Some(y) = bottom.checked_sub(along) {
                    canvas.fill_rect(x + row * scale, y, scale, scale, color);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_keeps_the_part_inside_the_unit_square() {
        assert_eq!(clip((0.2, 0.2), (0.8, 0.8)), Some(((0.2, 0.2), (0.8, 0.8))));
        assert_eq!(clip((-1.0, 0.5), (2.0, 0.5)), Some(((0.0, 0.5), (1.0, 0.5))));
        assert_eq!(clip((-1.0, 2.0), (-0.5, 3.0)), None);
        assert_eq!(clip((0.5, -3.0), (0.5, 5.0)), Some(((0.5, 0.0), (0.5, 1.0))));
    }
}
