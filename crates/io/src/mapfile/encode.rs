//! Writing a map: the header, the parameter text, three sections of blocks
//! in sorted key order, then the CRC-32 of everything before it.

use std::io::{self, Write};

use edtmap_core::{BlockMap, GlobalMap};

use super::layout::{layer_mask, put_key, ParamsText, Payload, CHECKSUM_LEN, COUNT_LEN, HEADER_LEN, KEY_LEN, LAYERS};
use super::{check, MapFileError, MAP_FORMAT_VERSION, MAP_MAGIC};

/// A checked map with its parameter text, ready to be written.
pub(super) struct Prepared<'a> {
    map: &'a GlobalMap,
    params: String,
}

impl<'a> Prepared<'a> {
    /// Checks `map` and renders its parameters.
    pub(super) fn new(map: &'a GlobalMap) -> Result<Self, MapFileError> {
        check::check_contents(map)?;
        let text = ParamsText { occupancy: map.occupancy_params().clone(), global: map.params().clone() };
        let params = toml::to_string(&text)
            .map_err(|e| MapFileError::InvalidParams(format!("cannot write them as TOML: {e}")))?;
        if u32::try_from(params.len()).is_err() {
            return Err(MapFileError::InvalidParams("their text exceeds 4 GiB".into()));
        }
        Ok(Prepared { map, params })
    }

    /// Length of the file in bytes, as stated in its header.
    pub(super) fn total_len(&self) -> u64 {
        let fixed = (HEADER_LEN + self.params.len() + 3 * COUNT_LEN + CHECKSUM_LEN) as u64;
        fixed + blocks_len(self.map.occupancy()) + blocks_len(self.map.edt()) + blocks_len(self.map.fixed_obstacles())
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
        write_section(&mut out, self.map.occupancy())?;
        write_section(&mut out, self.map.edt())?;
        write_section(&mut out, self.map.fixed_obstacles())?;
        let crc = out.crc.finalize();
        out.inner.write_all(&crc.to_le_bytes())?;
        out.inner.flush()
    }
}

fn blocks_len<B: Payload>(map: &BlockMap<B>) -> u64 {
    let layer = (B::LEN / LAYERS) as u64;
    map.iter().map(|(_, b)| (KEY_LEN + 1) as u64 + u64::from(layer_mask(b).count_ones()) * layer).sum()
}

/// The block count, then each block's key, layer mask and stored layers,
/// keys ascending so the same map always gives the same bytes.
fn write_section<B: Payload, W: Write>(out: &mut W, map: &BlockMap<B>) -> io::Result<()> {
    let mut blocks: Vec<_> = map.iter().collect();
    blocks.sort_unstable_by_key(|&(key, _)| key);
    out.write_all(&(blocks.len() as u64).to_le_bytes())?;
    let layer = B::LEN / LAYERS;
    let (mut payload, mut record) = (Vec::with_capacity(B::LEN), Vec::with_capacity(KEY_LEN + 1 + B::LEN));
    for (key, block) in blocks {
        payload.clear();
        block.put(key, &mut payload);
        record.clear();
        put_key(key, &mut record);
        let mask = layer_mask(block);
        record.push(mask);
        for z in (0..LAYERS).filter(|z| mask >> z & 1 == 1) {
            record.extend_from_slice(&payload[z * layer..(z + 1) * layer]);
        }
        out.write_all(&record)?;
    }
    Ok(())
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
