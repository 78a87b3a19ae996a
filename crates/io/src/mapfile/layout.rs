//! Sizes, offsets and block payloads, shared by the writer and the reader
//! (specified in `docs/FORMAT.md`). The writer writes the current version;
//! the reader reads each version's payloads.

use edtmap_core::{
    BlockHeap, BlockKey, EdtBlock, FixedBlock, GlobalParams, OccupancyBlock, OccupancyParams, VoxelIndex, BLOCK_VOXELS,
    NO_OBSTACLE, NO_OFFSET, UNOBSERVED,
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
pub(super) trait Payload: Default + Clone + BlockHeap {
    /// Name of the section, for messages.
    const SECTION: &'static str;
    /// Bytes of one block's payload (the key not included), as written.
    const LEN: usize;
    /// Bytes of one block's payload in a file of format `version`.
    fn len_in(_version: u32) -> usize {
        Self::LEN
    }
    /// Appends the payload of the block at `key` to `out`, as written.
    fn put(&self, key: BlockKey, out: &mut Vec<u8>);
    /// Reads the payload of the block at `key` from `bytes` of format
    /// `version`, exactly [`Self::len_in`] long; fails with what it cannot
    /// hold.
    fn get(&mut self, key: BlockKey, version: u32, bytes: &[u8]) -> Result<(), String>;
    /// Whether layer `z` of the block (its voxels `64 z .. 64 z + 64`)
    /// holds only what a new block holds.
    fn layer_empty(&self, z: usize) -> bool;
}

/// Layers of a block along z, each a contiguous eighth of a payload: a
/// voxel's offset is `x + 8 (y + 8 z)`.
pub(super) const LAYERS: usize = 8;

/// From version 3 on, a block's record is its key, one byte whose bit `z`
/// says whether layer `z` is stored, then the stored layers' payloads in
/// ascending `z`; a layer not stored holds what a new block holds (a
/// planar map's blocks store one layer of eight).
pub(super) const FIRST_LAYERED_VERSION: u32 = 3;

/// The layers of `block` that are not empty, as the record's mask byte.
pub(super) fn layer_mask<B: Payload>(block: &B) -> u8 {
    (0..LAYERS).filter(|&z| !block.layer_empty(z)).fold(0, |m, z| m | 1 << z)
}

impl Payload for OccupancyBlock {
    const SECTION: &'static str = "occupancy";
    const LEN: usize = 4 * BLOCK_VOXELS;
    fn put(&self, _: BlockKey, out: &mut Vec<u8>) {
        self.log_odds.iter().for_each(|v| out.extend_from_slice(&v.to_bits().to_le_bytes()));
    }
    fn get(&mut self, _: BlockKey, _: u32, bytes: &[u8]) -> Result<(), String> {
        for (o, c) in bytes.chunks_exact(4).enumerate() {
            self.log_odds.set(o, f32::from_bits(le_u32(c)));
        }
        Ok(())
    }
    fn layer_empty(&self, z: usize) -> bool {
        self.log_odds.layer(z).is_none_or(|l| l.iter().all(|v| v.to_bits() == UNOBSERVED.to_bits()))
    }
}

/// Bytes of a version 1 EDT payload: 512 `u32` squared distances, then 512
/// nearest obstacles as three `i32` world voxel indices.
const EDT_V1_LEN: usize = 4 * BLOCK_VOXELS + 12 * BLOCK_VOXELS;

/// From version 2 on, the EDT payload is the block as memory holds it: per
/// voxel the offset to its nearest obstacle, three `i16` ([`NO_OFFSET`]
/// beyond the cutoff); the squared distance follows from it.
impl Payload for EdtBlock {
    const SECTION: &'static str = "EDT";
    const LEN: usize = 6 * BLOCK_VOXELS;
    fn len_in(version: u32) -> usize {
        if version == 1 {
            EDT_V1_LEN
        } else {
            Self::LEN
        }
    }
    fn put(&self, _: BlockKey, out: &mut Vec<u8>) {
        self.to_nearest.iter().flatten().for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
    }
    fn get(&mut self, key: BlockKey, version: u32, bytes: &[u8]) -> Result<(), String> {
        if version == 1 {
            return get_edt_v1(self, key, bytes);
        }
        for (i, c) in bytes.chunks_exact(6).enumerate() {
            let o = [0, 2, 4].map(|at| i16::from_le_bytes([c[at], c[at + 1]]));
            self.to_nearest.set(i, checked_offset(key.voxel(i), o)?);
        }
        Ok(())
    }
    fn layer_empty(&self, z: usize) -> bool {
        self.to_nearest.layer(z).is_none_or(|l| l.iter().all(|&o| o == NO_OFFSET))
    }
}

/// Reads a version 1 EDT payload, [`EDT_V1_LEN`] long.
fn get_edt_v1(block: &mut EdtBlock, key: BlockKey, bytes: &[u8]) -> Result<(), String> {
    let (dist, nearest) = bytes.split_at(4 * BLOCK_VOXELS);
    for (i, (d, n)) in dist.chunks_exact(4).zip(nearest.chunks_exact(12)).enumerate() {
        block.set(key, i, le_u32(d), VoxelIndex(get_triple(n))).map_err(|e| format!("EDT {e}"))?;
    }
    Ok(())
}

/// Offset `o` read for voxel `v`, if it is either the no-obstacle sentinel
/// whole or an offset to a voxel with an `i32` index other than
/// [`NO_OBSTACLE`] (the entries a version 1 file can hold; the cutoff is
/// checked with the whole map's contents).
fn checked_offset(v: VoxelIndex, o: [i16; 3]) -> Result<[i16; 3], String> {
    if o == NO_OFFSET {
        return Ok(o);
    }
    if o.contains(&i16::MIN) {
        return Err(format!(
            "EDT voxel {:?} holds offset {o:?}: only the whole no-obstacle sentinel {NO_OFFSET:?} may hold {}",
            v.0,
            i16::MIN
        ));
    }
    let nearest = [0, 1, 2].map(|a| i32::try_from(i64::from(v.0[a]) + i64::from(o[a])).ok());
    match nearest {
        [Some(x), Some(y), Some(z)] if VoxelIndex([x, y, z]) != NO_OBSTACLE => Ok(o),
        _ => Err(format!("EDT voxel {:?} holds offset {o:?} to an obstacle outside the voxel index range", v.0)),
    }
}

impl Payload for FixedBlock {
    const SECTION: &'static str = "fixed";
    const LEN: usize = 64;
    fn put(&self, _: BlockKey, out: &mut Vec<u8>) {
        self.bits.iter().for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
    }
    fn get(&mut self, _: BlockKey, _: u32, bytes: &[u8]) -> Result<(), String> {
        for (w, c) in self.bits.iter_mut().zip(bytes.chunks_exact(8)) {
            *w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
        }
        Ok(())
    }
    fn layer_empty(&self, z: usize) -> bool {
        self.bits[z] == 0
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
