//! Pictures and charts of edtmap, as PNG files.
//!
//! * [`picture`]: a small RGB [`Canvas`](picture::Canvas) and the pictures
//!   drawn on it: 2D slices of distances with a colour bar (viridis), and
//!   slices of occupancy states with a legend, both with axes in metres.
//! * [`top_view`]: top views of the whole global map ([`TopView`]): the
//!   states and distances at a height, and their projection through a
//!   band of heights, in cells that keep a huge map's picture small.
//! * [`plot`]: line and scatter charts of results ([`Chart`]): per-frame
//!   stage times, errors against voxel sizes, times against change scores.
//!
//! Every picture is written through `edtmap-io`'s atomic writer
//! ([`edtmap_io::files::AtomicFile`]), so this crate depends on the formats
//! and never the reverse: reading and saving maps builds no drawing code.
//!
//! # Why not `plotters`
//!
//! The hand-made code is about 1,200 lines (charts and their ticks ~720,
//! slices ~380, the 5 × 7 bitmap font ~120, of which ~100 are the glyph
//! table) plus ~320 lines of tests, and needs only `png`, already a
//! dependency of `edtmap-io` for depth images. `plotters` 0.3.7 with its
//! default features resolves to 46 crates, among them `font-kit` with
//! `freetype-sys` and `yeslogic-fontconfig-sys`: C libraries and system
//! fonts, which a headless robot or a CI container may lack. Cut down to
//! the bitmap backend it is still 20 crates, including `image` 0.24 with a
//! second, older `png` (0.17), and draws no text at all; text without
//! system fonts (`ab_glyph`, 25 crates) needs a TrueType font embedded in
//! the binary. Switching would also change every picture's pixels. The
//! charts drawn here are simple (lines, markers, ticks, a legend), so the
//! own code stays.
#![warn(missing_docs)]

mod error;
mod font;
pub mod picture;
pub mod plot;
pub mod top_view;

pub use error::VizError;
pub use plot::Chart;
pub use top_view::TopView;
