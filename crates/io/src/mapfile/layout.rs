//! Sizes, offsets and block payloads of format version 1, shared by the
//! writer and the reader (specified in `docs/FORMAT.md`).

use edtmap_core::{
    BlockKey, EdtBlock, GlobalParams, OccupancyBlock, OccupancyParams, StaticBlock, VoxelIndex, BLOCK_VOXELS,
};
use serde::{Deserialize, Serialize};

/// Bytes needed to read the file's stated length: magic, version, flags,
/// total length.
pub(super) const LENGTH_END: usize = 24;
/// Bytes of the fixed header: the above, voxel size, parameter text length.
pub(super) const HEADER_LEN: usize = 36;
/// Bytes of the trailing CRC-32.
pub(super) const CHECKSUM_LEN: usize = 4;
/// Bytes of a block count.
pub(super) const COUNT_LEN: usize = 8;
/// Bytes of a block key: three `i32`.
pub(super) const KEY_LEN: usize = 12;
/// The smallest valid file: header, empty parameter text, three empty
/// sections, checksum.
pub(super) const MIN_FILE_LEN: u64 = (HEADER_LEN + 3 * COUNT_LEN + CHECKSUM_LEN) as u64;

/// The parameter text: TOML with an `[occupancy]` and a `[global]` table.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ParamsText {
    pub(super) occupancy: OccupancyParams,
    pub(super) global: GlobalParams,
}

/// A block type stored in a section: its name and raw little-endian payload.
pub(super) trait Payload: Default + Clone {
    /// Name of the section, for messages.
    const SECTION: &'static str;
    /// Bytes of one block's payload (the key not included).
    const LEN: usize;
    /// Appends the payload of the block at `key` to `out`.
    fn put(&self, key: BlockKey, out: &mut Vec<u8>);
    /// Reads the payload of the block at `key` from `bytes`, exactly
    /// [`Self::LEN`] long; fails with what it cannot hold.
    fn get(&mut self, key: BlockKey, bytes: &[u8]) -> Result<(), String>;
}

impl Payload for OccupancyBlock {
    const SECTION: &'static str = "occupancy";
    const LEN: usize = 4 * BLOCK_VOXELS;
    fn put(&self, _: BlockKey, out: &mut Vec<u8>) {
        self.log_odds.iter().for_each(|v| out.extend_from_slice(&v.to_bits().to_le_bytes()));
    }
    fn get(&mut self, _: BlockKey, bytes: &[u8]) -> Result<(), String> {
        for (v, c) in self.log_odds.iter_mut().zip(bytes.chunks_exact(4)) {
            *v = f32::from_bits(le_u32(c));
        }
        Ok(())
    }
}

impl Payload for EdtBlock {
    const SECTION: &'static str = "EDT";
    const LEN: usize = 4 * BLOCK_VOXELS + 12 * BLOCK_VOXELS;
    fn put(&self, key: BlockKey, out: &mut Vec<u8>) {
        (0..BLOCK_VOXELS).for_each(|i| out.extend_from_slice(&self.dist_sq(i).to_le_bytes()));
        (0..BLOCK_VOXELS).for_each(|i| put_triple(self.nearest(key, i).0, out));
    }
    fn get(&mut self, key: BlockKey, bytes: &[u8]) -> Result<(), String> {
        let (dist, nearest) = bytes.split_at(4 * BLOCK_VOXELS);
        for (i, (d, n)) in dist.chunks_exact(4).zip(nearest.chunks_exact(12)).enumerate() {
            self.set(key, i, le_u32(d), VoxelIndex(get_triple(n))).map_err(|e| format!("EDT {e}"))?;
        }
        Ok(())
    }
}

impl Payload for StaticBlock {
    const SECTION: &'static str = "fixed";
    const LEN: usize = 64;
    fn put(&self, _: BlockKey, out: &mut Vec<u8>) {
        self.bits.iter().for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
    }
    fn get(&mut self, _: BlockKey, bytes: &[u8]) -> Result<(), String> {
        for (w, c) in self.bits.iter_mut().zip(bytes.chunks_exact(8)) {
            *w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
        }
        Ok(())
    }
}

/// Appends a block key.
pub(super) fn put_key(key: BlockKey, out: &mut Vec<u8>) {
    put_triple(key.0, out);
}

/// Reads a block key from `bytes`, [`KEY_LEN`] long.
pub(super) fn get_key(bytes: &[u8]) -> BlockKey {
    BlockKey(get_triple(bytes))
}

fn put_triple(t: [i32; 3], out: &mut Vec<u8>) {
    t.iter().for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
}

fn get_triple(bytes: &[u8]) -> [i32; 3] {
    [0, 4, 8].map(|o| le_u32(&bytes[o..o + 4]) as i32)
}

/// The little-endian `u32` in the first 4 bytes of `c`.
pub(super) fn le_u32(c: &[u8]) -> u32 {
    u32::from_le_bytes([c[0], c[1], c[2], c[3]])
}
