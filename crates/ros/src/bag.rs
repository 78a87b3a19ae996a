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
//!
//! ```
//! use edtmap_ros::bag::{BagReader, BagWriter};
//!
//! # fn main() -> Result<(), edtmap_io::IoError> {
//! let path = std::env::temp_dir().join(format!("edtmap-doc-{}.bag", std::process::id()));
//! let mut writer = BagWriter::create(&path)?;
//! let odom = writer.add_connection("/odom", "nav_msgs/Odometry", "*", "")?;
//! writer.write(odom, 1_700_000_000_000_000_000, &[1, 2, 3])?;
//! writer.finish()?;
//!
//! let bag = BagReader::open(&path)?;
//! assert_eq!(bag.topics()?[0].messages, 1);
//! for message in bag.messages(&[]) {
//!     let message = message?;
//!     assert_eq!((message.topic.as_str(), message.data.as_slice()), ("/odom", &[1u8, 2, 3][..]));
//! }
//! # std::fs::remove_file(&path).ok();
//! # Ok(()) }
//! ```

mod format;
mod messages;
mod reader;
mod writer;

#[cfg(test)]
mod tests;

pub use reader::BagReader;
pub use writer::{BagWriter, DEFAULT_CHUNK_BYTES};
