//! 16-bit greyscale depth PNGs, read without trusting their header: the
//! size the header (IHDR) gives is checked against the size the caller
//! expects, or against [`MAX_DEPTH_IMAGE_BYTES`], before a byte of the
//! image is decoded. A 5 MB file whose header claims 50000 × 50000 pixels
//! is refused at once instead of allocating 5 GB.

use crate::folder::frames::bad;
use crate::{files, IoError};
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

/// Largest decoded depth image read when the caller expects no size (the
/// first image of a folder, which gives the folder its size): 256 MiB of
/// 16-bit pixels, e.g. 11585 × 11585; a depth camera's is under 2 MB.
pub const MAX_DEPTH_IMAGE_BYTES: u64 = 1 << 28;

/// Largest depth PNG file opened: room for the largest image stored
/// uncompressed, with its ancillary chunks.
const MAX_DEPTH_PNG_FILE_BYTES: u64 = 2 * MAX_DEPTH_IMAGE_BYTES;

/// The size a depth image must have, and what gives that size (named in
/// the error when an image's header differs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExpectedSize<'a> {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Where the size comes from, e.g. `the folder's first image` or
    /// `[sensor] width, height`.
    pub source: &'a str,
}

/// A depth PNG whose header has been checked, ready to decode.
pub(crate) struct DepthPng {
    reader: png::Reader<BufReader<File>>,
    /// Width, pixels.
    pub(crate) width: u32,
    /// Height, pixels.
    pub(crate) height: u32,
}

impl DepthPng {
    /// Opens `path` and checks its header: a PNG of 16-bit greyscale of
    /// the `expected` size or, without one, of at most
    /// [`MAX_DEPTH_IMAGE_BYTES`] decoded. Nothing of the image is decoded.
    pub(crate) fn open(path: &Path, expected: Option<ExpectedSize<'_>>) -> Result<Self, IoError> {
        let (file, _) = files::open_input(path, MAX_DEPTH_PNG_FILE_BYTES)?;
        let mut decoder = png::Decoder::new(BufReader::new(file));
        decoder.set_ignore_text_chunk(true);
        let info = decoder.read_header_info().map_err(|e| bad(path, format!("not a PNG: {e}")))?;
        let (width, height) = (info.width, info.height);
        check_header(path, width, height, info.color_type, info.bit_depth, expected)?;
        let reader = decoder.read_info().map_err(|e| bad(path, format!("corrupt PNG before the image data: {e}")))?;
        Ok(DepthPng { reader, width, height })
    }

    /// Decodes the image: its depth values, row by row.
    pub(crate) fn decode(mut self, path: &Path) -> Result<Vec<u16>, IoError> {
        let size = self.reader.output_buffer_size().ok_or_else(|| bad(path, "image too large"))?;
        let mut buf = vec![0; size];
        let frame = self.reader.next_frame(&mut buf).map_err(|e| bad(path, format!("corrupt PNG data: {e}")))?;
        let data = buf.get(..frame.buffer_size()).unwrap_or_default();
        Ok(data.chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect())
    }
}

/// Reads the 16-bit greyscale PNG at `path`: its width, height and values,
/// row by row. Its header is checked before anything is decoded: the
/// image must have the `expected` size, or without one be at most
/// [`MAX_DEPTH_IMAGE_BYTES`] decoded.
pub fn read_depth_png(path: &Path, expected: Option<ExpectedSize<'_>>) -> Result<(u32, u32, Vec<u16>), IoError> {
    let png = DepthPng::open(path, expected)?;
    let (width, height) = (png.width, png.height);
    Ok((width, height, png.decode(path)?))
}

/// Refuses a header that is not 16-bit greyscale, or whose size is not
/// the expected one or, without one, over [`MAX_DEPTH_IMAGE_BYTES`].
fn check_header(
    path: &Path,
    width: u32,
    height: u32,
    colour: png::ColorType,
    depth: png::BitDepth,
    expected: Option<ExpectedSize<'_>>,
) -> Result<(), IoError> {
    if colour != png::ColorType::Grayscale || depth != png::BitDepth::Sixteen {
        return Err(bad(path, format!("depth must be 16-bit greyscale, the PNG header says {colour:?} {depth:?}")));
    }
    match expected {
        Some(e) if (width, height) != (e.width, e.height) => Err(bad(
            path,
            format!(
                "the PNG header says {width} x {height} pixels, {} says {} x {}: refused before decoding",
                e.source, e.width, e.height
            ),
        )),
        Some(_) => Ok(()),
        None => {
            let bytes = u64::from(width) * u64::from(height) * 2;
            if bytes > MAX_DEPTH_IMAGE_BYTES {
                return Err(bad(
                    path,
                    format!(
                        "the PNG header says {width} x {height} pixels of 16 bits, {bytes} bytes decoded, more than the \
                         {MAX_DEPTH_IMAGE_BYTES} bytes read for a depth image: refused before decoding (a damaged or hostile file?)"
                    ),
                ));
            }
            Ok(())
        }
    }
}
