//! ROS 1 bags (format 2.0, <http://wiki.ros.org/Bags/Format/2.0>): a
//! reader that keeps what a damaged bag holds, and a writer.
//!
//! Design choices:
//! * [`BagReader`] reads the chunk section record after record rather than
//!   through the index, so a bag never closed (header `index_pos` 0) or cut
//!   short gives every message before the damage, then one error naming
//!   the byte offset. The index is used only for the topic list, when it is
//!   whole, and for connections a chunk does not define.
//! * The record framing is parsed here, every length checked against the
//!   bytes present before anything is allocated; the `rosbag` crate decodes
//!   `bz2` and `lz4` chunks, after the checks that keep it from panicking.
//! * [`BagWriter`] writes uncompressed chunks the way `rosbag record` does
//!   (header patched when a chunk closes, connection records in the first
//!   chunk that uses them), so the tests can make bags killed mid-run.

mod format;
mod messages;
mod reader;
mod writer;

#[cfg(test)]
mod tests;

pub use reader::BagReader;
pub use writer::{BagWriter, DEFAULT_CHUNK_BYTES};
