//! Writing a map: the header, the parameter text, three sections of blocks
//! in sorted key order, then the CRC-32 of everything before it.

use std::io::{self, Write};

use edtmap_core::{BlockKey, BlockMap, EdtBlock, FixedBlock, GlobalMap, OccupancyBlock};

use super::layout::{layer_mask, put_key, ParamsText, Payload, CHECKSUM_LEN, COUNT_LEN, HEADER_LEN, KEY_LEN, LAYERS};
use super::{check, MapFileError, MAP_FORMAT_VERSION, MAP_MAGIC};

/// A checked map with its parameter text and its sections' blocks in
/// order, ready to be written.
pub(super) struct Prepared<'a> {
    map: &'a GlobalMap,
    params: String,
    occupancy: Section<'a, OccupancyBlock>,
    edt: Section<'a, EdtBlock>,
    fixed: Section<'a, FixedBlock>,
}

impl<'a> Prepared<'a> {
    /// Checks `map`, renders its parameters and sorts its blocks.
    pub(super) fn new(map: &'a GlobalMap) -> Result<Self, MapFileError> {
        check::check_contents(map)?;
        let text = ParamsText { occupancy: map.occupancy_params().clone(), global: map.params().clone() };
        let params = toml::to_string(&text)
            .map_err(|e| MapFileError::InvalidParams(format!("cannot write them as TOML: {e}")))?;
        if u32::try_from(params.len()).is_err() {
            return Err(MapFileError::InvalidParams("their text exceeds 4 GiB".into()));
        }
        let (occupancy, edt, fixed) =
            (Section::new(map.occupancy()), Section::new(map.edt()), Section::new(map.fixed_obstacles()));
        Ok(Prepared { map, params, occupancy, edt, fixed })
    }

    /// Length of the file in bytes, as stated in its header.
    pub(super) fn total_len(&self) -> u64 {
        let fixed = (HEADER_LEN + self.params.len() + 3 * COUNT_LEN + CHECKSUM_LEN) as u64;
        fixed + self.occupancy.len() + self.edt.len() + self.fixed.len()
    }

    /// Writes the whole file to `out`.
    pub(super) fn write<W: Write>(&self, out: W) -> io::Result<()> {
        let mut out = Checksummed { inner: out, crc: crc32fast::Hasher::new() };
        out.write_all(&MAP_MAGIC)?;
        out.write_all(&MAP_FORMAT_VERSION.to_le_bytes())?;
        out.write_all(&0u32.to_le_bytes())?;
        out.write_all(&self.total_len().to_le_bytes())?;
        out.write_all(&self.map.voxel_size_m().to_le_bytes())?;
        // Checked to fit in `new`.
        out.write_all(&(self.params.len() as u32).to_le_bytes())?;
        out.write_all(self.params.as_bytes())?;
        self.occupancy.write(&mut out)?;
        self.edt.write(&mut out)?;
        self.fixed.write(&mut out)?;
        let crc = out.crc.finalize();
        out.inner.write_all(&crc.to_le_bytes())?;
        out.inner.flush()
    }
}

/// A section's blocks, keys ascending so the same map always gives the
/// same bytes, each with its layer mask (found once, for the length and
/// the record).
struct Section<'a, B> {
    blocks: Vec<(BlockKey, &'a B, u8)>,
}

impl<'a, B: Payload> Section<'a, B> {
    fn new(map: &'a BlockMap<B>) -> Self {
        let mut blocks: Vec<_> = map.iter().map(|(key, b)| (key, b, layer_mask(b))).collect();
        blocks.sort_unstable_by_key(|&(key, _, _)| key);
        Section { blocks }
    }

    /// Bytes of the section's records (its count not included).
    fn len(&self) -> u64 {
        let layer = (B::LEN / LAYERS) as u64;
        self.blocks.iter().map(|&(_, _, mask)| (KEY_LEN + 1) as u64 + u64::from(mask.count_ones()) * layer).sum()
    }

    /// The block count, then each block's key, layer mask and stored layers.
    fn write<W: Write>(&self, out: &mut W) -> io::Result<()> {
        out.write_all(&(self.blocks.len() as u64).to_le_bytes())?;
        let layer = B::LEN / LAYERS;
        let (mut payload, mut record) = (Vec::with_capacity(B::LEN), Vec::with_capacity(KEY_LEN + 1 + B::LEN));
        for &(key, block, mask) in &self.blocks {
            payload.clear();
            block.put(key, &mut payload);
            record.clear();
            put_key(key, &mut record);
            record.push(mask);
            for z in (0..LAYERS).filter(|z| mask >> z & 1 == 1) {
                record.extend_from_slice(&payload[z * layer..(z + 1) * layer]);
            }
            out.write_all(&record)?;
        }
        Ok(())
    }
}

/// A writer that keeps the CRC-32 of the bytes written through it.
struct Checksummed<W> {
    inner: W,
    crc: crc32fast::Hasher,
}

impl<W: Write> Write for Checksummed<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n.min(buf.len())]);
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}
