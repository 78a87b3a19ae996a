//! Decompression bombs and lying headers: a small
//! file whose header claims a huge image or cloud must be refused from the
//! header, at once, naming the file, the header's value and the expected
//! one or the limit, without allocating what the header claims.
//!
//! A watching allocator records the largest single request; requests over
//! 1 GiB are refused outright (the test then fails on the allocation
//! error instead of taking the machine).

mod support;

use edtmap_core::sensor::RangeLimits;
use edtmap_io::dataset::Dataset;
use edtmap_io::depth_folder::{read_depth_png, ExpectedSize, MAX_DEPTH_IMAGE_BYTES};
use edtmap_io::npy::ObstacleNpy;
use edtmap_io::pcd::parse_pcd;
use edtmap_io::ply::parse_ply;
use edtmap_io::{read_pcd, IoError};
use std::path::Path;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use support::LARGEST;

/// The most any refusal here may allocate at once: the files are tiny.
const ALLOCATION_LIMIT: usize = 16 << 20;
/// The most any refusal here may take.
const TIME_LIMIT: Duration = Duration::from_millis(500);

#[global_allocator]
static GLOBAL: support::Watch = support::Watch;

/// Runs `refuse`, which must fail, and checks it was quick and small;
/// returns the error's message.
fn refused<T: std::fmt::Debug>(what: &str, refuse: impl FnOnce() -> Result<T, IoError>) -> String {
    let start = Instant::now();
    let err = refuse().expect_err(what).to_string();
    let took = start.elapsed();
    assert!(took < TIME_LIMIT, "{what}: refused after {took:?}: {err}");
    let largest = LARGEST.load(Ordering::Relaxed);
    assert!(largest <= ALLOCATION_LIMIT, "{what}: an allocation of {largest} bytes: {err}");
    err
}

/// A 16-bit greyscale PNG of `width` × `height` pixels, all `value`.
fn depth_png(width: u32, height: u32, value: u16) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().expect("png header");
    let data: Vec<u8> = (0..width * height).flat_map(|_| value.to_be_bytes()).collect();
    writer.write_image_data(&data).expect("png data");
    writer.finish().expect("png end");
    bytes
}

/// `png` with its IHDR patched to claim `width` × `height` pixels, the
/// chunk's CRC made valid again: a bomb with a small real IDAT behind it.
fn claim_size(mut png: Vec<u8>, width: u32, height: u32) -> Vec<u8> {
    // Signature (8), IHDR length (4), "IHDR" (4), width (4), height (4), ...
    assert_eq!(&png[12..16], b"IHDR");
    png[16..20].copy_from_slice(&width.to_be_bytes());
    png[20..24].copy_from_slice(&height.to_be_bytes());
    let crc = crc32fast::hash(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    png
}

#[test]
fn a_png_claiming_50000_squared_is_refused_from_its_header() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("frame-000001.depth.png");
    std::fs::write(&path, claim_size(depth_png(4, 3, 1000), 50_000, 50_000)).expect("write");
    let err = refused("no expected size", || read_depth_png(&path, None));
    assert!(err.contains("frame-000001.depth.png") && err.contains("50000 x 50000"), "{err}");
    assert!(
        err.contains(&MAX_DEPTH_IMAGE_BYTES.to_string()) && err.contains("before decoding"),
        "names the limit: {err}"
    );

    let expected = ExpectedSize { width: 640, height: 480, source: "[sensor] width, height" };
    let err = refused("expected 640 x 480", || read_depth_png(&path, Some(expected)));
    assert!(
        err.contains("50000 x 50000") && err.contains("640 x 480") && err.contains("[sensor] width, height"),
        "{err}"
    );
}

#[test]
fn a_png_claiming_30000_squared_is_refused_before_decoding() {
    // 1.8 GB decoded: under the old reader it was decoded and then skipped.
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("big.png");
    std::fs::write(&path, claim_size(depth_png(4, 3, 1000), 30_000, 30_000)).expect("write");
    let err = refused("30000 squared", || read_depth_png(&path, None));
    assert!(err.contains("30000 x 30000") && err.contains("1800000000 bytes"), "{err}");
}

#[test]
fn a_png_of_the_wrong_kind_is_refused_from_its_header() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("rgb.png");
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, 2, 2);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header().expect("header").write_image_data(&[7; 12]).expect("data");
    std::fs::write(&path, claim_size(bytes, 40_000, 40_000)).expect("write");
    let err = refused("rgb", || read_depth_png(&path, None));
    assert!(err.contains("16-bit greyscale") && err.contains("Rgb") && err.contains("Eight"), "{err}");
}

#[test]
fn a_true_png_of_the_expected_size_still_decodes() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("ok.png");
    std::fs::write(&path, depth_png(4, 3, 1234)).expect("write");
    let expected = ExpectedSize { width: 4, height: 3, source: "the test" };
    let (w, h, values) = read_depth_png(&path, Some(expected)).expect("decodes");
    assert_eq!((w, h), (4, 3));
    assert_eq!(values, vec![1234; 12]);
}

/// A 3DMatch folder of `frames` depth PNGs, each with an identity pose.
fn threedmatch_folder(dir: &Path, frames: &[Vec<u8>]) {
    std::fs::write(dir.join("camera-intrinsics.txt"), "5 0 2\n0 5 1.5\n0 0 1\n").expect("intrinsics");
    for (k, png) in frames.iter().enumerate() {
        std::fs::write(dir.join(format!("frame-{k:06}.depth.png")), png).expect("png");
        std::fs::write(dir.join(format!("frame-{k:06}.pose.txt")), "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
            .expect("pose");
    }
}

const RANGE: RangeLimits = RangeLimits { min_m: 0.1, max_m: 10.0 };

#[test]
fn a_bomb_in_a_depth_folder_fails_its_frame_only() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let good = depth_png(4, 3, 1000);
    threedmatch_folder(tmp.path(), &[good.clone(), claim_size(good, 50_000, 50_000)]);
    let set = Dataset::open(tmp.path(), 0.001, RANGE).expect("the first frame is fine");
    set.frame(0).expect("frame 0 reads");
    let err = refused("frame 1", || set.frame(1));
    assert!(err.contains("frame-000001.depth.png") && err.contains("50000 x 50000") && err.contains("4 x 3"), "{err}");
    assert!(err.contains("the folder's first image"), "says where 4 x 3 comes from: {err}");
}

#[test]
fn a_bomb_as_the_first_frame_is_refused_when_the_folder_opens() {
    let tmp = tempfile::tempdir().expect("temp dir");
    threedmatch_folder(tmp.path(), &[claim_size(depth_png(4, 3, 1000), 50_000, 50_000)]);
    let err = refused("frame 0", || Dataset::open(tmp.path(), 0.001, RANGE));
    assert!(err.contains("frame-000000.depth.png") && err.contains("50000 x 50000"), "{err}");
}

#[test]
fn a_pcd_claiming_1e12_points_is_refused_from_its_header() {
    let head = |data: &str| {
        format!("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1000000000000\nHEIGHT 1\nPOINTS 1000000000000\nDATA {data}\n")
    };
    let mut binary = head("binary").into_bytes();
    binary.extend([0u8; 24]);
    let err = refused("binary", || parse_pcd(Path::new("bomb.pcd"), &binary));
    assert!(err.contains("bomb.pcd") && err.contains("12000000000000") && err.contains("24"), "{err}");
    let ascii = format!("{}1 2 3\n4 5 6\n", head("ascii"));
    let err = refused("ascii", || parse_pcd(Path::new("bomb.pcd"), ascii.as_bytes()));
    assert!(
        err.contains("bomb.pcd") && err.contains("promises 1000000000000 points") && err.contains("has 2"),
        "{err}"
    );

    // And through the file reader.
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("bomb.pcd");
    std::fs::write(&path, &binary).expect("write");
    let err = refused("file", || read_pcd(&path));
    assert!(err.contains("bomb.pcd"), "{err}");
}

#[test]
fn a_ply_claiming_1e12_vertices_is_refused_from_its_header() {
    for format in ["binary_little_endian", "binary_big_endian", "ascii"] {
        let mut file = format!("ply\nformat {format} 1.0\nelement vertex 1000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n").into_bytes();
        file.extend(b"1 2 3\n4 5 6\n");
        let err = refused(format, || parse_ply(Path::new("bomb.ply"), &file));
        // Binary: the bytes the count needs; ascii: the count, where the data ends.
        assert!(
            err.contains("bomb.ply") && (err.contains("12000000000000") || err.contains("1000000000000 records")),
            "{format}: {err}"
        );
    }
}

/// An npy version 2 header whose length field claims 4 GiB of header:
/// refused before the header is allocated.
#[test]
fn an_npy_header_length_of_4_gib_is_refused_before_allocating() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("bomb.npy");
    let mut bytes = b"\x93NUMPY\x02\x00".to_vec();
    bytes.extend(u32::MAX.to_le_bytes());
    bytes.extend(b"{'descr': '|u1', 'fortran_order': False, 'shape': (2, 2), }\n");
    std::fs::write(&path, bytes).expect("write");
    let err = refused("4 GiB header", || ObstacleNpy::open(&path).map(|f| f.item_size()));
    assert!(err.contains("bomb.npy") && err.contains("4294967295"), "{err}");
}

#[test]
fn an_npy_shape_beyond_the_file_is_refused_before_allocating() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("big.npy");
    let dict = "{'descr': '|u1', 'fortran_order': False, 'shape': (1000, 1000, 1000), }";
    std::fs::write(&path, support::raw_npy(dict, &[1u8; 64])).expect("write");
    let err = refused("1e9 elements", || ObstacleNpy::open(&path).map(|f| f.item_size()));
    assert!(err.contains("big.npy") && err.contains("1000000000") && err.contains("64"), "{err}");
}
