//! The `.edtmap` map file: bit-identical round trips, deterministic bytes,
//! and a clear error, never a panic, for every kind of bad file.

use std::fs;
use std::path::Path;

use edtmap_core::{
    BlockKey, BlockMap, Connectivity, EdtMap, FixedMap, ForbiddenZone, GlobalMap, GlobalParams, IntegrationMode,
    OccupancyMap, OccupancyParams, VoxelIndex, BLOCK_VOXELS, FAR_DIST_SQ, NO_OBSTACLE, NO_OFFSET, UNOBSERVED,
};
use edtmap_io::mapfile::{self, MapFileError, MAP_FORMAT_VERSION};
use edtmap_io::IoError;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const VOXEL_SIZE_M: f64 = 0.05;
/// Offset of the parameter text's length (docs/FORMAT.md).
const PARAMS_LEN_AT: usize = 32;
/// Bytes of an occupancy and EDT block record (key and payload) in
/// versions 1 and 2, which store every layer.
const OCC_RECORD: usize = 12 + 4 * 512;
const EDT_V2_RECORD: usize = 12 + 6 * 512;
/// Bytes of a version 1 EDT block record.
const EDT_V1_RECORD: usize = 12 + 16 * 512;
/// Bytes of one layer of an occupancy and an EDT block (version 3).
const OCC_LAYER: usize = 4 * 64;
const EDT_LAYER: usize = 6 * 64;

/// Bytes of the version 3 record at `at` (key, mask, stored layers) of a
/// section whose layers are `layer` bytes.
fn record_len(bytes: &[u8], at: usize, layer: usize) -> usize {
    13 + bytes[at + 12].count_ones() as usize * layer
}

/// The layers and parameters of a map as plain fields the tests can set,
/// and the [`GlobalMap`] they make.
#[derive(Debug, Clone)]
struct MapContents {
    voxel_size_m: f64,
    occupancy_params: OccupancyParams,
    global_params: GlobalParams,
    occupancy: OccupancyMap,
    edt: EdtMap,
    fixed: FixedMap,
}

impl MapContents {
    fn global(&self) -> Result<GlobalMap, edtmap_core::CoreError> {
        let (o, g) = (self.occupancy_params.clone(), self.global_params.clone());
        GlobalMap::from_layers(self.voxel_size_m, o, g, self.occupancy.clone(), self.edt.clone(), self.fixed.clone())
    }

    fn of(map: &GlobalMap) -> Self {
        MapContents {
            voxel_size_m: map.voxel_size_m(),
            occupancy_params: map.occupancy_params().clone(),
            global_params: map.params().clone(),
            occupancy: map.occupancy().clone(),
            edt: map.edt().clone(),
            fixed: map.fixed_obstacles().clone(),
        }
    }
}

fn encode_map(map: &MapContents) -> Result<Vec<u8>, MapFileError> {
    mapfile::encode_map(&map.global().expect("valid parameters"))
}

fn decode_map(bytes: &[u8]) -> Result<MapContents, MapFileError> {
    mapfile::decode_map(bytes).map(|m| MapContents::of(&m))
}

fn write_map(path: &Path, map: &MapContents) -> Result<(), IoError> {
    mapfile::write_map(path, &map.global().expect("valid parameters"))
}

fn read_map(path: &Path) -> Result<MapContents, IoError> {
    mapfile::read_map(path).map(|m| MapContents::of(&m))
}

fn empty_map() -> MapContents {
    let global_params = GlobalParams {
        max_distance_m: 0.5,
        connectivity: Connectivity::Six,
        mode: IntegrationMode::Exact,
        forbidden: vec![ForbiddenZone { min_m: [-1.0, -0.5, 0.0], max_m: [0.25, 0.5, 0.1] }],
        planar: false,
    };
    MapContents {
        voxel_size_m: VOXEL_SIZE_M,
        occupancy_params: OccupancyParams { prob_hit: 0.65, clamp_max: 0.971, ..Default::default() },
        global_params,
        occupancy: OccupancyMap::new(),
        edt: EdtMap::new(),
        fixed: FixedMap::new(),
    }
}

fn random_key(rng: &mut StdRng) -> BlockKey {
    BlockKey([0; 3].map(|_| rng.random_range(-20..=20)))
}

/// A map of about `blocks` occupancy blocks, half as many EDT blocks and a
/// quarter as many fixed blocks, with random but consistent contents; two
/// blocks sit at the ends of the key range.
fn random_map(seed: u64, blocks: usize) -> MapContents {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut map = empty_map();
    let lo = map.occupancy_params.log_odds().expect("valid");
    let cutoff = map.global_params.cutoff(VOXEL_SIZE_M).expect("valid");
    let edges = [BlockKey([-(1 << 28), (1 << 28) - 1, 0]), BlockKey([(1 << 28) - 1, 0, -(1 << 28)])];
    for i in 0..blocks {
        let key = edges.get(i).copied().unwrap_or_else(|| random_key(&mut rng));
        let block = map.occupancy.get_or_insert(key);
        for o in 0..BLOCK_VOXELS {
            block.log_odds.set(o, if rng.random_bool(0.3) { UNOBSERVED } else { rng.random_range(lo.min..=lo.max) });
        }
    }
    for i in 0..blocks / 2 {
        let key = edges.get(i).copied().unwrap_or_else(|| random_key(&mut rng));
        let block = map.edt.get_or_insert(key);
        for offset in 0..BLOCK_VOXELS {
            let v = key.voxel(offset);
            let d = [0; 3].map(|_| rng.random_range(-cutoff.reach..=cutoff.reach));
            let dist_sq = d.iter().map(|c| (c * c) as u32).sum::<u32>();
            let nearest = [0, 1, 2].map(|a| v.0[a].checked_add(d[a]));
            match nearest {
                [Some(x), Some(y), Some(z)] if dist_sq <= cutoff.max_dist_sq && rng.random_bool(0.6) => {
                    block.set(key, offset, dist_sq, VoxelIndex([x, y, z])).expect("within the reach");
                }
                _ => block.set(key, offset, FAR_DIST_SQ, NO_OBSTACLE).expect("none"),
            }
        }
    }
    for _ in 0..blocks / 4 {
        let block = map.fixed.get_or_insert(random_key(&mut rng));
        block.bits = [0; 8].map(|_| rng.random());
    }
    map
}

/// Every field and every block equal, log-odds compared bit for bit.
fn assert_same(a: &MapContents, b: &MapContents) {
    assert_eq!(a.voxel_size_m.to_bits(), b.voxel_size_m.to_bits());
    assert_eq!(a.occupancy_params, b.occupancy_params);
    assert_eq!(a.global_params, b.global_params);
    assert_eq!((a.occupancy.len(), a.edt.len(), a.fixed.len()), (b.occupancy.len(), b.edt.len(), b.fixed.len()));
    for (key, block) in a.occupancy.iter() {
        let other = b.occupancy.get(key).expect("same keys");
        assert!(
            block.log_odds.iter().zip(other.log_odds.iter()).all(|(x, y)| x.to_bits() == y.to_bits()),
            "block {key:?}"
        );
    }
    for (key, block) in a.edt.iter() {
        assert_eq!(Some(block), b.edt.get(key), "block {key:?}");
    }
    for (key, block) in a.fixed.iter() {
        assert_eq!(Some(block), b.fixed.get(key), "block {key:?}");
    }
}

/// Every voxel of every EDT block of `a` or `b`, and a shell of voxels
/// around each, has the same distance and nearest obstacle in both, as
/// the map answers them.
fn assert_same_entries(a: &GlobalMap, b: &GlobalMap) {
    let keys: Vec<BlockKey> = a.edt().iter().chain(b.edt().iter()).map(|(key, _)| key).collect();
    for key in keys {
        for offset in 0..BLOCK_VOXELS {
            let v = key.voxel(offset);
            for v in [v, VoxelIndex([v.0[0].saturating_sub(8), v.0[1], v.0[2].saturating_add(8)])] {
                assert_eq!(a.entry(v), b.entry(v), "voxel {:?}", v.0);
            }
        }
    }
}

/// The sorted blocks of a section.
fn sorted<B: Default>(map: &BlockMap<B>) -> Vec<(BlockKey, &B)> {
    let mut blocks: Vec<_> = map.iter().collect();
    blocks.sort_unstable_by_key(|&(key, _)| key);
    blocks
}

/// Appends a section as docs/FORMAT.md lays it out: the count, then each
/// key and the payload `put` appends.
fn put_section<B: Default>(out: &mut Vec<u8>, map: &BlockMap<B>, put: impl Fn(BlockKey, &B, &mut Vec<u8>)) {
    out.extend((map.len() as u64).to_le_bytes());
    for (key, block) in sorted(map) {
        key.0.iter().for_each(|c| out.extend(c.to_le_bytes()));
        put(key, block, out);
    }
}

/// The version 1 file of `map`, written from the version 1 layout of
/// docs/FORMAT.md (the EDT as 512 `u32` squared distances, then 512 nearest
/// obstacles as three `i32`), independently of the crate's writer.
fn encode_v1(map: &MapContents) -> Vec<u8> {
    encode_old(map, 1)
}

/// The version 1 or 2 file of `map` (every layer of every block, no mask;
/// version 2's EDT as three `i16` offsets), from docs/FORMAT.md,
/// independently of the crate's writer.
fn encode_old(map: &MapContents, version: u32) -> Vec<u8> {
    #[derive(serde::Serialize)]
    struct Params<'a> {
        occupancy: &'a OccupancyParams,
        global: &'a GlobalParams,
    }
    let text = toml::to_string(&Params { occupancy: &map.occupancy_params, global: &map.global_params }).expect("TOML");
    let mut out = b"EDTMAP\r\n".to_vec();
    out.extend(version.to_le_bytes());
    out.extend(0u32.to_le_bytes());
    out.extend(0u64.to_le_bytes()); // the length, set below
    out.extend(map.voxel_size_m.to_le_bytes());
    out.extend((text.len() as u32).to_le_bytes());
    out.extend(text.as_bytes());
    put_section(&mut out, &map.occupancy, |_, b, out| {
        b.log_odds.iter().for_each(|v| out.extend(v.to_bits().to_le_bytes()))
    });
    put_section(&mut out, &map.edt, |key, b, out| {
        if version == 1 {
            (0..BLOCK_VOXELS).for_each(|i| out.extend(b.dist_sq(i).to_le_bytes()));
            (0..BLOCK_VOXELS).for_each(|i| b.nearest(key, i).0.iter().for_each(|c| out.extend(c.to_le_bytes())));
        } else {
            b.to_nearest.iter().flatten().for_each(|c| out.extend(c.to_le_bytes()));
        }
    });
    put_section(&mut out, &map.fixed, |_, b, out| b.bits.iter().for_each(|w| out.extend(w.to_le_bytes())));
    let total = out.len() as u64 + 4;
    out[16..24].copy_from_slice(&total.to_le_bytes());
    out.extend(crc32fast::hash(&out).to_le_bytes());
    out
}

/// Recomputes the trailing CRC-32 after a deliberate patch.
fn fix_crc(bytes: &mut [u8]) {
    let n = bytes.len() - 4;
    let crc = crc32fast::hash(&bytes[..n]);
    bytes[n..].copy_from_slice(&crc.to_le_bytes());
}

/// Offset of the occupancy section's block count.
fn sections_at(bytes: &[u8]) -> usize {
    let len = u32::from_le_bytes(bytes[PARAMS_LEN_AT..PARAMS_LEN_AT + 4].try_into().expect("4 bytes"));
    36 + len as usize
}

fn decode_err(bytes: &[u8]) -> MapFileError {
    match decode_map(bytes) {
        Ok(_) => panic!("{} bytes decoded", bytes.len()),
        Err(e) => e,
    }
}

fn map_file_error(path: &Path) -> MapFileError {
    match read_map(path) {
        Err(IoError::MapFile { path: p, error }) => {
            assert_eq!(p, path);
            error
        }
        other => panic!("expected a map file error, got {other:?}"),
    }
}

#[test]
fn round_trip_is_bit_identical_and_deterministic() {
    let map = random_map(7, 300);
    assert!(map.occupancy.len() > 250 && map.edt.len() > 120 && !map.fixed.is_empty());
    let bytes = encode_map(&map).expect("valid map");
    let back = decode_map(&bytes).expect("round trip");
    assert_same(&map, &back);
    assert_eq!(encode_map(&map).expect("valid"), bytes, "encoding twice gives the same bytes");
    assert_eq!(encode_map(&back).expect("valid"), bytes, "a map read back encodes to the same bytes");
    assert_eq!(encode_map(&map.clone()).expect("valid"), bytes, "hash order does not matter");
}

#[test]
fn saved_file_reads_back_and_leaves_no_temporary() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("map.edtmap");
    let first = random_map(1, 40);
    write_map(&path, &first).expect("written");
    assert_same(&first, &read_map(&path).expect("read"));
    assert_eq!(fs::read(&path).expect("bytes"), encode_map(&first).expect("valid"));
    let second = random_map(2, 10);
    write_map(&path, &second).expect("replaced");
    assert_same(&second, &read_map(&path).expect("read"));
    let names: Vec<_> = fs::read_dir(dir.path()).expect("list").map(|e| e.expect("entry").file_name()).collect();
    assert_eq!(names, ["map.edtmap"]);
}

#[test]
fn empty_map_is_the_minimal_file() {
    let map = empty_map();
    let bytes = encode_map(&map).expect("valid");
    let text_len = sections_at(&bytes) - 36;
    assert_eq!(bytes.len(), 36 + text_len + 3 * 8 + 4);
    assert_same(&map, &decode_map(&bytes).expect("round trip"));
    let text = std::str::from_utf8(&bytes[36..36 + text_len]).expect("UTF-8");
    assert!(text.contains("[occupancy]") && text.contains("[global]") && text.contains("prob_hit = 0.65"), "{text}");
}

/// A planar map says so in its parameter text and reads back planar; any
/// other map's text has no `planar` key, so its file is as before.
#[test]
fn planar_maps_say_so_and_others_do_not() {
    let mut map = empty_map();
    let text = |bytes: &[u8]| String::from_utf8(bytes[36..sections_at(bytes)].to_vec()).expect("UTF-8");
    assert!(!text(&encode_map(&map).expect("valid")).contains("planar"));
    map.global_params.planar = true;
    let bytes = encode_map(&map).expect("valid");
    assert!(text(&bytes).contains("planar = true"), "{}", text(&bytes));
    let back = decode_map(&bytes).expect("round trip");
    assert!(back.global_params.planar);
    assert_same(&map, &back);
}

#[test]
fn global_map_converts_both_ways() {
    let params = empty_map().global_params;
    let mut global = GlobalMap::new(VOXEL_SIZE_M, OccupancyParams::default(), params).expect("valid");
    let v = VoxelIndex([3, -4, 5]);
    let max = global.log_odds().max;
    global.occupancy_mut().get_or_insert(v.block()).log_odds.set(v.offset_in_block(), max);
    let fixed_blocks = global.fixed_obstacles().len();
    let bytes = mapfile::encode_map(&global).expect("valid");
    let back = mapfile::decode_map(&bytes).expect("round trip");
    assert_eq!(back.fixed_obstacles().len(), fixed_blocks, "zones are not laid down twice");
    assert_eq!((back.log_odds(), back.cutoff()), (global.log_odds(), global.cutoff()));
    assert!(back.obstacles().contains(v) && back.obstacles().contains(VoxelIndex([-20, -10, 0])));
}

#[test]
fn every_truncation_is_rejected() {
    let mut rng = StdRng::seed_from_u64(3);
    let mut map = empty_map();
    let key = random_key(&mut rng);
    map.occupancy.get_or_insert(key).log_odds.set(5, 0.5);
    map.edt.get_or_insert(key);
    map.fixed.get_or_insert(key).bits[0] = 1;
    let bytes = encode_map(&map).expect("valid");
    let full = bytes.len() as u64;
    for cut in 0..bytes.len() {
        let err = decode_err(&bytes[..cut]);
        let actual = cut as u64;
        match err {
            MapFileError::NotMapFile(_) => assert_eq!(cut, 0),
            MapFileError::TruncatedHeader { actual: a, header: 24 } => assert!(a == actual && cut < 24),
            MapFileError::Truncated { expected, actual: a } => assert!(expected == full && a == actual && cut >= 24),
            other => panic!("cut at {cut}: {other}"),
        }
    }
}

#[test]
fn flipped_bits_are_rejected() {
    let mut rng = StdRng::seed_from_u64(4);
    let mut bytes = encode_map(&random_map(5, 30)).expect("valid");
    let header = sections_at(&bytes) + 8;
    let positions: Vec<usize> = (0..header).chain((0..2000).map(|_| rng.random_range(0..bytes.len()))).collect();
    for at in positions {
        let bit = 1u8 << rng.random_range(0..8);
        bytes[at] ^= bit;
        assert!(decode_map(&bytes).is_err(), "bit {bit:#x} of byte {at}");
        bytes[at] ^= bit;
    }
    decode_map(&bytes).expect("the file is intact again");
}

#[test]
fn wrong_magic_is_not_a_map_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut bytes = encode_map(&random_map(6, 4)).expect("valid");
    bytes[..8].copy_from_slice(b"\x89PNG\r\n\x1a\n");
    let path = dir.path().join("picture.edtmap");
    fs::write(&path, &bytes).expect("write");
    assert!(matches!(map_file_error(&path), MapFileError::NotMapFile(_)));
    let message = read_map(&path).expect_err("not a map").to_string();
    assert!(message.contains("picture.edtmap") && message.contains("not an edtmap map file"), "{message}");
    bytes[..8].copy_from_slice(b"EDTMAP\n\n");
    assert!(matches!(decode_err(&bytes), MapFileError::NotMapFile(_)), "a CR LF turned into LF");
}

#[test]
fn newer_version_is_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut bytes = encode_map(&random_map(8, 4)).expect("valid");
    bytes[8..12].copy_from_slice(&(MAP_FORMAT_VERSION + 1).to_le_bytes());
    fix_crc(&mut bytes);
    let path = dir.path().join("future.edtmap");
    fs::write(&path, &bytes).expect("write");
    assert_eq!(
        map_file_error(&path),
        MapFileError::NewerVersion { found: MAP_FORMAT_VERSION + 1, supported: MAP_FORMAT_VERSION }
    );
    let message = read_map(&path).expect_err("newer").to_string();
    assert!(message.contains("future.edtmap"), "{message}");
    let expected = format!(
        "written by a newer edtmap: format version {}, this build reads up to {MAP_FORMAT_VERSION}",
        MAP_FORMAT_VERSION + 1
    );
    assert!(message.contains(&expected), "{message}");
}

#[test]
fn empty_and_random_files_are_rejected() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("empty.edtmap");
    fs::write(&path, b"").expect("write");
    assert!(matches!(map_file_error(&path), MapFileError::NotMapFile(m) if m.contains("empty")));
    let mut rng = StdRng::seed_from_u64(9);
    for _ in 0..500 {
        let len = rng.random_range(0..4000);
        let bytes: Vec<u8> = (0..len).map(|_| rng.random()).collect();
        decode_err(&bytes);
        // The same garbage behind a valid frame reaches the parser.
        let mut framed = bytes.clone();
        framed.resize(len.max(64), 0);
        framed[..8].copy_from_slice(b"EDTMAP\r\n");
        framed[8..12].copy_from_slice(&rng.random_range(1..=MAP_FORMAT_VERSION).to_le_bytes());
        let total = framed.len() as u64;
        framed[16..24].copy_from_slice(&total.to_le_bytes());
        fix_crc(&mut framed);
        decode_err(&framed);
    }
}

#[test]
fn garbage_inside_a_valid_frame_never_panics() {
    let mut rng = StdRng::seed_from_u64(10);
    let original = encode_map(&random_map(11, 12)).expect("valid");
    for _ in 0..500 {
        let mut bytes = original.clone();
        let start = rng.random_range(24..bytes.len() - 4);
        let end = (start + rng.random_range(1..64)).min(bytes.len() - 4);
        bytes[start..end].iter_mut().for_each(|b| *b = rng.random());
        fix_crc(&mut bytes);
        let _ = decode_map(&bytes);
    }
}

#[test]
fn absurd_counts_are_refused_before_allocating() {
    let original = encode_map(&random_map(12, 8)).expect("valid");
    let occ = sections_at(&original);
    let one_too_many = ((original.len() - 4 - occ - 8) / OCC_RECORD + 1) as u64;
    for value in [u64::MAX, 1 << 40, one_too_many] {
        let mut bytes = original.clone();
        bytes[occ..occ + 8].copy_from_slice(&value.to_le_bytes());
        fix_crc(&mut bytes);
        assert!(
            matches!(decode_err(&bytes), MapFileError::Corrupt(m) if m.contains("occupancy section")),
            "count {value}"
        );
    }
    let mut bytes = original.clone();
    bytes[PARAMS_LEN_AT..PARAMS_LEN_AT + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    fix_crc(&mut bytes);
    assert!(matches!(decode_err(&bytes), MapFileError::Corrupt(m) if m.contains("parameter text")));
}

#[test]
fn duplicate_and_unsorted_keys_are_corrupt() {
    let original = encode_map(&random_map(13, 8)).expect("valid");
    let first = sections_at(&original) + 8;
    let second = first + record_len(&original, first, OCC_LAYER);
    let end = second + record_len(&original, second, OCC_LAYER);
    let mut bytes = original.clone();
    bytes.copy_within(first..first + 12, second);
    fix_crc(&mut bytes);
    assert!(matches!(decode_err(&bytes), MapFileError::Corrupt(m) if m.contains("duplicate block key")));
    let mut bytes = original.clone();
    bytes[first..end].copy_from_slice(&[&original[second..end], &original[first..second]].concat());
    fix_crc(&mut bytes);
    assert!(matches!(decode_err(&bytes), MapFileError::Corrupt(m) if m.contains("out of order")));
}

#[test]
fn version_1_edt_entry_that_disagrees_with_its_obstacle_is_corrupt() {
    let mut map = empty_map();
    let key = BlockKey([1, -2, 3]);
    let block = map.edt.get_or_insert(key);
    let v = key.voxel(0);
    block.set(key, 0, 5, VoxelIndex([v.0[0] + 1, v.0[1] - 2, v.0[2]])).expect("near");
    let original = encode_v1(&map);
    let edt = sections_at(&original) + 8 + 8;
    let dist_at = edt + 12;
    let mut bytes = original.clone();
    bytes[dist_at..dist_at + 4].copy_from_slice(&4u32.to_le_bytes());
    fix_crc(&mut bytes);
    let err = decode_err(&bytes);
    assert!(matches!(&err, MapFileError::Corrupt(m) if m.contains("EDT voxel [8, -16, 24]")), "{err}");
    let mut bytes = original.clone();
    bytes[dist_at..dist_at + 4].copy_from_slice(&FAR_DIST_SQ.to_le_bytes());
    fix_crc(&mut bytes);
    assert!(matches!(decode_err(&bytes), MapFileError::Corrupt(m) if m.contains("beyond the cutoff")));
    assert_eq!(edt + EDT_V1_RECORD + 8 + 4, original.len(), "one EDT block, no fixed block");
    // The map cannot hold the same inconsistency; the writer refuses an
    // entry beyond the cutoff.
    let block = map.edt.get_or_insert(key);
    assert!(block.set(key, 0, 4, VoxelIndex([v.0[0] + 1, v.0[1] - 2, v.0[2]])).is_err());
    let cutoff = map.global_params.cutoff(map.voxel_size_m).expect("valid");
    let beyond = cutoff.reach + 1;
    block.set(key, 0, (beyond * beyond) as u32, VoxelIndex([v.0[0] + beyond, v.0[1], v.0[2]])).expect("in range");
    assert!(matches!(encode_map(&map), Err(MapFileError::Corrupt(m)) if m.contains("beyond the cutoff")));
}

#[test]
fn version_1_edt_entry_whose_obstacle_is_out_of_the_offsets_range_is_corrupt() {
    // The map holds each nearest obstacle as an i16 offset from its voxel;
    // a version 1 file naming one farther away on an axis is refused, not
    // wrapped.
    let mut map = empty_map();
    let key = BlockKey([1, -2, 3]);
    let v = key.voxel(0);
    map.edt.get_or_insert(key).set(key, 0, 1, VoxelIndex([v.0[0] + 1, v.0[1], v.0[2]])).expect("near");
    let original = encode_v1(&map);
    let nearest_at = sections_at(&original) + 8 + 8 + 12 + 4 * BLOCK_VOXELS;
    let mut bytes = original.clone();
    bytes[nearest_at..nearest_at + 4].copy_from_slice(&(v.0[0] + 40_000).to_le_bytes());
    fix_crc(&mut bytes);
    let err = decode_err(&bytes);
    assert!(
        matches!(&err, MapFileError::Corrupt(m) if m.contains("EDT voxel [8, -16, 24]: its nearest obstacle") && m.contains("more than 32767 voxels away")),
        "{err}"
    );
}

/// A map with one EDT block at `key` whose voxel 0 has an obstacle at
/// offset (1, 2, 0) (and voxel 1 the same obstacle), its bytes, and where
/// voxel 0's offset lies in them.
fn one_edt_entry(key: BlockKey) -> (MapContents, Vec<u8>, usize) {
    let mut map = empty_map();
    let v = key.voxel(0);
    let block = map.edt.get_or_insert(key);
    block.set(key, 0, 5, VoxelIndex([v.0[0] + 1, v.0[1] + 2, v.0[2]])).expect("near");
    // Voxel 1 too, so that voxel 0 alone can be made the sentinel.
    block.set(key, 1, 4, VoxelIndex([v.0[0] + 1, v.0[1] + 2, v.0[2]])).expect("near");
    let bytes = encode_map(&map).expect("valid");
    let offset_at = sections_at(&bytes) + 8 + 8 + 13;
    assert_eq!(bytes[offset_at - 1], 1, "one layer stored, the first");
    assert_eq!(bytes[offset_at..offset_at + 6], [1, 0, 2, 0, 0, 0], "three little-endian i16");
    assert_eq!(offset_at - 13 + 13 + EDT_LAYER + 8 + 4, bytes.len(), "one EDT block of one layer, no fixed block");
    (map, bytes, offset_at)
}

/// `bytes` with the offset at `at` replaced by `o`, checksum fixed.
fn with_offset(bytes: &[u8], at: usize, o: [i16; 3]) -> Vec<u8> {
    let mut bytes = bytes.to_vec();
    for (a, c) in o.iter().enumerate() {
        bytes[at + 2 * a..at + 2 * a + 2].copy_from_slice(&c.to_le_bytes());
    }
    fix_crc(&mut bytes);
    bytes
}

#[test]
fn edt_offset_beyond_the_cutoff_is_corrupt() {
    let (map, original, at) = one_edt_entry(BlockKey([1, -2, 3]));
    let reach = map.global_params.cutoff(map.voxel_size_m).expect("valid").reach as i16;
    decode_map(&with_offset(&original, at, [reach, 0, 0])).expect("at the cutoff");
    for o in [[reach + 1, 0, 0], [0, -reach, 1], [i16::MAX; 3], [-i16::MAX; 3]] {
        let err = decode_err(&with_offset(&original, at, o));
        let named = format!("EDT voxel [8, -16, 24] holds offset {o:?}");
        assert!(
            matches!(&err, MapFileError::Corrupt(m) if m.contains(&named) && m.contains("beyond the cutoff")),
            "{err}"
        );
    }
}

#[test]
fn edt_offset_that_is_partly_the_sentinel_is_corrupt() {
    let (_, original, at) = one_edt_entry(BlockKey([1, -2, 3]));
    let back = mapfile::decode_map(&with_offset(&original, at, NO_OFFSET)).expect("the whole sentinel");
    assert_eq!(back.entry(VoxelIndex([8, -16, 24])), (FAR_DIST_SQ, NO_OBSTACLE));
    for o in [[i16::MIN, 3, 4], [3, i16::MIN, 4], [0, 0, i16::MIN], [i16::MIN, i16::MIN, 0]] {
        let err = decode_err(&with_offset(&original, at, o));
        let named = format!("EDT voxel [8, -16, 24] holds offset {o:?}");
        assert!(matches!(&err, MapFileError::Corrupt(m) if m.contains(&named) && m.contains("sentinel")), "{err}");
    }
}

#[test]
fn edt_offset_to_an_obstacle_outside_the_index_range_is_corrupt() {
    // At the lowest key, voxel 0 has index i32::MIN on every axis: one step
    // lower leaves the index range, and from voxel 1 one step lower in x
    // lands on the index that marks no obstacle.
    let edge = -(1 << 28);
    let (_, original, at) = one_edt_entry(BlockKey([edge; 3]));
    for (at, o, voxel) in [(at, [-1, 0, 0], 0), (at, [0, 0, -3], 0), (at + 6, [-1, 0, 0], 1)] {
        let err = decode_err(&with_offset(&original, at, o));
        let named = format!("EDT voxel [{}, {}, {}] holds offset {o:?}", i32::MIN + voxel, i32::MIN, i32::MIN);
        assert!(
            matches!(&err, MapFileError::Corrupt(m) if m.contains(&named) && m.contains("outside the voxel index range")),
            "{err}"
        );
    }
}

#[test]
fn round_trip_keeps_every_distance_and_nearest_obstacle() {
    let map = random_map(15, 120);
    let bytes = encode_map(&map).expect("valid");
    assert_eq!(bytes[8..12], MAP_FORMAT_VERSION.to_le_bytes());
    assert_eq!(MAP_FORMAT_VERSION, 3);
    let back = mapfile::decode_map(&bytes).expect("round trip");
    assert_same_entries(&map.global().expect("valid"), &back);
    assert_same(&map, &MapContents::of(&back));
}

/// A version 1 or 2 file (every layer stored, EDT records of
/// `edt_record` bytes) has the length docs/FORMAT.md gives, loads equal,
/// and saves again as the current version's bytes.
fn old_version_loads_equal(version: u32, edt_record: usize) {
    let map = random_map(15 + u64::from(version), 120);
    let old = encode_old(&map, version);
    let text_len = sections_at(&old) - 36;
    let expected = 36
        + text_len
        + 3 * 8
        + OCC_RECORD * map.occupancy.len()
        + edt_record * map.edt.len()
        + 76 * map.fixed.len()
        + 4;
    assert_eq!(old.len(), expected, "the version {version} length of docs/FORMAT.md");
    let back = mapfile::decode_map(&old).expect("an older version loads");
    assert_same_entries(&map.global().expect("valid"), &back);
    assert_same(&map, &MapContents::of(&back));
    assert_eq!(
        mapfile::encode_map(&back).expect("valid"),
        encode_map(&map).expect("valid"),
        "saved again as the current version"
    );
}

#[test]
fn version_1_file_loads_equal() {
    old_version_loads_equal(1, EDT_V1_RECORD);
}

#[test]
fn version_2_file_loads_equal() {
    old_version_loads_equal(2, EDT_V2_RECORD);
}

/// A floor as a 2D laser maps it: one layer of observed blocks with a wall
/// across it, and the wall's EDT within the cutoff.
fn wall_map() -> MapContents {
    let mut map = empty_map();
    let cutoff = map.global_params.cutoff(VOXEL_SIZE_M).expect("valid");
    let lo = map.occupancy_params.log_odds().expect("valid");
    let (wall_y, wall_x) = (16, 0..32);
    for key in (0..4).flat_map(|x| (0..4).map(move |y| BlockKey([x, y, 0]))) {
        let block = map.occupancy.get_or_insert(key);
        for offset in 0..BLOCK_VOXELS {
            let v = key.voxel(offset).0;
            let l = if v[2] != 0 {
                UNOBSERVED
            } else if v[1] == wall_y {
                lo.max
            } else {
                lo.min
            };
            block.log_odds.set(offset, l);
        }
    }
    let r = cutoff.reach;
    for x in wall_x.start - r..wall_x.end + r {
        for (y, z) in (wall_y - r..=wall_y + r).flat_map(|y| (-r..=r).map(move |z| (y, z))) {
            let nearest = VoxelIndex([x.clamp(wall_x.start, wall_x.end - 1), wall_y, 0]);
            let dist_sq = [x - nearest.0[0], y - wall_y, z].iter().map(|d| (d * d) as u32).sum::<u32>();
            if dist_sq <= cutoff.max_dist_sq {
                let v = VoxelIndex([x, y, z]);
                let key = v.block();
                map.edt.get_or_insert(key).set(key, v.offset_in_block(), dist_sq, nearest).expect("within the cutoff");
            }
        }
    }
    map
}

#[test]
fn version_2_file_is_less_than_half_the_version_1_file() {
    let map = wall_map();
    assert!(map.edt.len() > map.occupancy.len(), "the EDT reaches past the wall's blocks");
    let (v1, v2) = (encode_v1(&map), encode_old(&map, 2));
    assert_same_entries(&mapfile::decode_map(&v1).expect("v1"), &mapfile::decode_map(&v2).expect("v2"));
    let ratio = v1.len() as f64 / v2.len() as f64;
    assert!(ratio >= 2.0, "{} bytes in version 1, {} in version 2: {ratio:.2}", v1.len(), v2.len());
    let edt_bytes = |record: usize| (record * map.edt.len()) as f64;
    assert_eq!(v1.len() - v2.len(), (EDT_V1_RECORD - EDT_V2_RECORD) * map.edt.len(), "only the EDT payload shrinks");
    assert!(edt_bytes(EDT_V1_RECORD) / edt_bytes(EDT_V2_RECORD) > 2.6);
}

/// The layers each block stores in version 3, by brute force over its
/// voxels: those holding something other than a new block holds.
fn stored_layers(map: &MapContents) -> usize {
    let occ = map.occupancy.iter().map(|(_, b)| {
        (0..8)
            .filter(|z| (64 * z..64 * z + 64).map(|o| b.log_odds[o]).any(|l| l.to_bits() != UNOBSERVED.to_bits()))
            .count()
    });
    let edt = map
        .edt
        .iter()
        .map(|(_, b)| (0..8).filter(|z| (64 * z..64 * z + 64).any(|o| b.dist_sq(o) != FAR_DIST_SQ)).count());
    let fixed = map.fixed.iter().map(|(_, b)| (0..8).filter(|&z| b.bits[z] != 0).count());
    OCC_LAYER * occ.sum::<usize>() + EDT_LAYER * edt.sum::<usize>() + 8 * fixed.sum::<usize>()
}

#[test]
fn version_3_stores_only_the_layers_that_hold_something() {
    // A 3D EDT around a wall on a floor: every layer of its blocks within
    // the cutoff; the same wall mapped planar: its layer alone.
    let map3d = wall_map();
    let mut planar = map3d.clone();
    planar.global_params.planar = true;
    let keep: Vec<_> = planar.edt.iter().map(|(k, _)| k).filter(|k| k.0[2] != 0).collect();
    planar.edt.take(&keep);
    let keys: Vec<_> = planar.edt.iter().map(|(k, _)| k).collect();
    for key in keys {
        let block = planar.edt.get_or_insert(key);
        for o in 64..512 {
            block.put(key, o, FAR_DIST_SQ, NO_OBSTACLE);
        }
    }
    for map in [&map3d, &planar] {
        let (v2, v3) = (encode_old(map, 2), encode_map(map).expect("valid"));
        assert_same(map, &decode_map(&v3).expect("v3"));
        assert_same(&decode_map(&v2).expect("v2"), &decode_map(&v3).expect("v3"));
        let blocks = map.occupancy.len() + map.edt.len() + map.fixed.len();
        assert_eq!(
            v3.len() - (v2.len() - OCC_RECORD * map.occupancy.len() - EDT_V2_RECORD * map.edt.len()),
            13 * blocks + stored_layers(map)
        );
    }
    let ratio = |map: &MapContents| encode_old(map, 2).len() as f64 / encode_map(map).expect("valid").len() as f64;
    assert!(ratio(&planar) > 7.5, "a planar map's file: {:.2} times smaller", ratio(&planar));
    assert!(ratio(&map3d) > 1.0, "a 3D map's file: {:.2} times smaller", ratio(&map3d));
}

#[test]
fn a_stored_layer_that_holds_nothing_is_corrupt() {
    let (_, original, at) = one_edt_entry(BlockKey([1, -2, 3]));
    // The mask says layers 0 and 1; layer 1's bytes are the sentinel.
    let mut bytes = original[..at - 1].to_vec();
    bytes.push(0b11);
    bytes.extend_from_slice(&original[at..at + EDT_LAYER]);
    (0..64).for_each(|_| bytes.extend_from_slice(&[0, 0x80, 0, 0x80, 0, 0x80]));
    bytes.extend_from_slice(&original[at + EDT_LAYER..]);
    let len = bytes.len() as u64;
    bytes[16..24].copy_from_slice(&len.to_le_bytes());
    fix_crc(&mut bytes);
    let err = decode_err(&bytes);
    assert!(matches!(&err, MapFileError::Corrupt(m) if m.contains("stores a layer that holds only")), "{err}");
    // A mask naming a layer whose bytes are missing.
    let mut bytes = original.clone();
    bytes[at - 1] = 0b11;
    fix_crc(&mut bytes);
    let err = decode_err(&bytes);
    assert!(matches!(&err, MapFileError::Corrupt(m) if m.contains("a block's layers")), "{err}");
}

#[test]
fn invalid_parameters_are_refused() {
    let original = encode_map(&empty_map()).expect("valid");
    for (voxel_size_m, field) in [(-1.0, "voxel_size_m"), (f64::NAN, "voxel_size_m"), (1.0, "max_distance_m")] {
        let mut bytes = original.clone();
        bytes[24..32].copy_from_slice(&f64::to_le_bytes(voxel_size_m));
        fix_crc(&mut bytes);
        assert!(matches!(decode_err(&bytes), MapFileError::InvalidParams(m) if m.contains(field)), "{voxel_size_m}");
    }
    // Same-length edits of the parameter text.
    for (from, to, field) in [("prob_hit = 0.65", "prob_hit = 0.45", "prob_hit"), ("prob_hit", "prob_hot", "prob_hot")]
    {
        let mut bytes = original.clone();
        let at = original.windows(from.len()).position(|w| w == from.as_bytes()).expect("in the text");
        bytes[at..at + to.len()].copy_from_slice(to.as_bytes());
        fix_crc(&mut bytes);
        assert!(matches!(decode_err(&bytes), MapFileError::InvalidParams(m) if m.contains(field)), "{to}");
    }
}

#[test]
fn writer_refuses_a_map_it_could_not_read_back() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("bad.edtmap");
    // Bad parameters cannot make a map, so such a map is never written
    // (nor can its layers disagree on the voxel size: there is one).
    let mut map = empty_map();
    map.occupancy_params.prob_hit = 0.3;
    assert!(map.global().expect_err("bad prob_hit").to_string().contains("prob_hit"));
    let mut map = empty_map();
    map.occupancy.get_or_insert(BlockKey([0, 0, 0])).log_odds.set(9, f32::NAN);
    assert!(matches!(write_map(&path, &map), Err(IoError::MapFile { error: MapFileError::Corrupt(_), .. })));
    assert_eq!(fs::read_dir(dir.path()).expect("list").count(), 0, "nothing written");
}

#[test]
fn trailing_bytes_are_corrupt() {
    let mut bytes = encode_map(&random_map(14, 4)).expect("valid");
    bytes.push(0);
    assert!(matches!(decode_err(&bytes), MapFileError::Corrupt(m) if m.contains("1 bytes follow")));
}

#[test]
fn missing_directory_is_an_io_error_naming_the_path() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("no/such/dir/map.edtmap");
    match write_map(&path, &empty_map()) {
        Err(e @ IoError::Io { .. }) => {
            assert!(matches!(&e, IoError::Io { path: p, .. } if *p == path));
            assert!(e.to_string().contains("no/such/dir/map.edtmap"), "{e}");
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(read_map(&path), Err(IoError::Io { path: p, .. }) if p == path));
}
