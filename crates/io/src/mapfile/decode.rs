//! Reading a map: the framing (magic, version, length, checksum) first,
//! then the parameters and the sections, every count checked against the
//! bytes that remain before anything is allocated.

use edtmap_core::{BlockKey, BlockMap, EdtBlock, FixedBlock, GlobalMap, OccupancyBlock};

use super::layout::{
    get_key, layer_mask, le_u32, ParamsText, Payload, CHECKSUM_LEN, FIRST_LAYERED_VERSION, KEY_LEN, LAYERS, LENGTH_END,
    MIN_FILE_LEN,
};
use super::{check, MapFileError, MAP_FORMAT_VERSION, MAP_MAGIC};

/// The map held by `bytes`.
pub(super) fn decode(bytes: &[u8]) -> Result<GlobalMap, MapFileError> {
    let (version, body) = framing(bytes)?;
    let mut cur = Cursor { bytes: body, pos: 12 };
    let flags = cur.u32("the flags")?;
    if flags != 0 {
        return Err(MapFileError::Corrupt(format!("unknown flags {flags:#x} (format version {version} defines none)")));
    }
    cur.take(8, "the file length")?;
    let voxel_size_m = f64::from_bits(cur.u64("the voxel size")?);
    let params_len = cur.u32("the parameter text length")? as usize;
    let text = cur.take(params_len, "the parameter text")?;
    let text =
        std::str::from_utf8(text).map_err(|e| MapFileError::InvalidParams(format!("the text is not UTF-8 ({e})")))?;
    let params: ParamsText = toml::from_str(text).map_err(|e| MapFileError::InvalidParams(e.message().to_string()))?;
    check::check_params(voxel_size_m, &params.occupancy, &params.global)?;
    let occupancy = read_section::<OccupancyBlock>(&mut cur, version)?;
    let edt = read_section::<EdtBlock>(&mut cur, version)?;
    let fixed = read_section::<FixedBlock>(&mut cur, version)?;
    if cur.remaining() != 0 {
        return Err(MapFileError::Corrupt(format!(
            "{} unused bytes between the last section and the checksum",
            cur.remaining()
        )));
    }
    let map = GlobalMap::from_layers(voxel_size_m, params.occupancy, params.global, occupancy, edt, fixed)
        .map_err(|e| MapFileError::InvalidParams(e.to_string()))?;
    check::check_contents(&map)?;
    Ok(map)
}

/// Checks the magic, version, stated length and checksum; returns the
/// version and the bytes before the checksum.
fn framing(bytes: &[u8]) -> Result<(u32, &[u8]), MapFileError> {
    let actual = bytes.len() as u64;
    if bytes.is_empty() {
        return Err(MapFileError::NotMapFile("the file is empty".into()));
    }
    let start = &bytes[..bytes.len().min(MAP_MAGIC.len())];
    if start != &MAP_MAGIC[..start.len()] {
        let shown = start.escape_ascii();
        return Err(MapFileError::NotMapFile(format!("it starts with b\"{shown}\", not b\"EDTMAP\\r\\n\"")));
    }
    let short = MapFileError::TruncatedHeader { actual, header: LENGTH_END as u64 };
    let version = bytes.get(8..12).map(le_u32).ok_or(short.clone())?;
    if version == 0 {
        return Err(MapFileError::Corrupt("format version 0 does not exist".into()));
    }
    if version > MAP_FORMAT_VERSION {
        return Err(MapFileError::NewerVersion { found: version, supported: MAP_FORMAT_VERSION });
    }
    let stated = bytes.get(16..24).map(le_u64).ok_or(short)?;
    if stated < MIN_FILE_LEN {
        return Err(MapFileError::Corrupt(format!(
            "the header states a length of {stated} bytes, below the {MIN_FILE_LEN}-byte minimum"
        )));
    }
    if actual < stated {
        return Err(MapFileError::Truncated { expected: stated, actual });
    }
    if actual > stated {
        return Err(MapFileError::Corrupt(format!(
            "{} bytes follow the end of the map (the header states {stated} bytes)",
            actual - stated
        )));
    }
    let (body, tail) = bytes.split_at(bytes.len() - CHECKSUM_LEN);
    let (stored, computed) = (le_u32(tail), crc32fast::hash(body));
    if stored != computed {
        return Err(MapFileError::Checksum { stored, computed });
    }
    Ok((version, body))
}

/// The block count, then the blocks of format `version`; keys must ascend
/// strictly.
fn read_section<B: Payload>(cur: &mut Cursor<'_>, version: u32) -> Result<BlockMap<B>, MapFileError> {
    let count = cur.u64("a block count")?;
    let layered = version >= FIRST_LAYERED_VERSION;
    let payload = B::len_in(version);
    // A layered record is at least its key and mask.
    let record = if layered { KEY_LEN + 1 } else { KEY_LEN + payload } as u64;
    let remaining = cur.remaining() as u64;
    if count > remaining / record {
        return Err(MapFileError::Corrupt(format!(
            "the {} section claims {count} blocks of {record} bytes, but only {remaining} bytes remain",
            B::SECTION
        )));
    }
    let mut map: BlockMap<B> = BlockMap::new();
    let mut previous: Option<BlockKey> = None;
    let mut full = Vec::with_capacity(payload);
    let mut empty = Vec::with_capacity(payload);
    B::default().put(BlockKey::default(), &mut empty);
    for _ in 0..count {
        let key = get_key(cur.take(KEY_LEN, "a block key")?);
        if let Some(p) = previous.filter(|&p| p >= key) {
            let what = if p == key { "duplicate block key" } else { "block keys out of order:" };
            return Err(MapFileError::Corrupt(format!(
                "{what} {:?} after {:?} in the {} section",
                key.0,
                p.0,
                B::SECTION
            )));
        }
        previous = Some(key);
        check::check_key::<B>(key)?;
        let (bytes, mask) = if layered {
            let mask = cur.take(1, "a block's layer mask")?[0];
            let layer = payload / LAYERS;
            let stored = cur.take(mask.count_ones() as usize * layer, "a block's layers")?;
            // The layers not stored as a new block holds them.
            full.clear();
            full.extend_from_slice(&empty);
            for (z, bytes) in (0..LAYERS).filter(|z| mask >> z & 1 == 1).zip(stored.chunks_exact(layer)) {
                full[z * layer..(z + 1) * layer].copy_from_slice(bytes);
            }
            (&full[..], Some(mask))
        } else {
            (cur.take(payload, "a block")?, None)
        };
        let block = map.get_or_insert(key);
        block.get(key, version, bytes).map_err(MapFileError::Corrupt)?;
        if mask.is_some_and(|m| m != layer_mask(block)) {
            return Err(MapFileError::Corrupt(format!(
                "block {:?} of the {} section stores a layer that holds only what a new block holds",
                key.0,
                B::SECTION
            )));
        }
    }
    Ok(map)
}

/// Reads the bytes before the checksum in order.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    /// The next `n` bytes; `what` names them in the error.
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], MapFileError> {
        if n > self.remaining() {
            return Err(MapFileError::Corrupt(format!(
                "{what} needs {n} bytes at offset {}, but only {} remain before the checksum",
                self.pos,
                self.remaining()
            )));
        }
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    fn u32(&mut self, what: &str) -> Result<u32, MapFileError> {
        self.take(4, what).map(le_u32)
    }

    fn u64(&mut self, what: &str) -> Result<u64, MapFileError> {
        self.take(8, what).map(le_u64)
    }
}

fn le_u64(c: &[u8]) -> u64 {
    u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]])
}
