//! Robustness of the recording readers: valid files mutated at random
//! (flipped bytes, truncation, inserted garbage, repeated header lines,
//! huge counts) must give `Ok` or `Err`, never a panic, and never ask for
//! an absurd amount of memory. Seeded, so a failure repeats.

mod support;

use edtmap_io::dataset::{parse_kitti_bin, parse_kitti_poses, parse_matrix, parse_times};
use edtmap_io::depth_folder::parse_intrinsics;
use edtmap_io::pcd::parse_pcd;
use edtmap_io::ply::{parse_ply, write_ply, ColouredPoint};
use edtmap_io::Trajectory;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::sync::atomic::Ordering;
use support::LARGEST;

/// Mutated files per reader.
const CASES: usize = 500;
/// The largest single allocation any reader may ask for on these inputs
/// (each under a few kilobytes).
const ALLOCATION_LIMIT: usize = 64 << 20;

#[global_allocator]
static GLOBAL: support::Watch = support::Watch;

/// Numbers that break counts: past u32, past u64, negative, not integers.
const HUGE: [&str; 8] =
    ["4000000000", "18446744073709551615", "18446744073709551616", "4294967296", "-1", "0", "1e9", "nan"];

/// One random change to `bytes`. `counts` are header texts whose number
/// (their last token) is worth replacing with a huge one.
fn mutate(rng: &mut StdRng, bytes: &mut Vec<u8>, counts: &[&str]) {
    let len = bytes.len();
    match rng.random_range(0..7) {
        0 if len > 0 => {
            for _ in 0..rng.random_range(1..4) {
                let at = rng.random_range(0..len);
                bytes[at] = rng.random();
            }
        }
        1 => bytes.truncate(rng.random_range(0..=len)),
        2 => {
            let at = rng.random_range(0..=len);
            let garbage: Vec<u8> = match rng.random_range(0..3) {
                0 => (0..rng.random_range(1..16)).map(|_| rng.random()).collect(),
                1 => (0..rng.random_range(1..16)).map(|_| b"0123456789 .-e\n"[rng.random_range(0..15)]).collect(),
                _ => format!(" {} ", HUGE[rng.random_range(0..HUGE.len())]).into_bytes(),
            };
            bytes.splice(at..at, garbage);
        }
        3 => {
            // Repeat one of the first lines (the header's).
            let starts: Vec<usize> = std::iter::once(0)
                .chain(bytes.iter().enumerate().filter(|(_, &b)| b == b'\n').map(|(k, _)| k + 1))
                .take(12)
                .collect();
            let k = rng.random_range(0..starts.len());
            let end = starts.get(k + 1).copied().unwrap_or(len);
            let line = bytes[starts[k]..end].to_vec();
            let at = starts[rng.random_range(0..starts.len())];
            bytes.splice(at..at, line);
        }
        4 if !counts.is_empty() => {
            let site = counts[rng.random_range(0..counts.len())];
            let (keep, _) = site.rsplit_once(' ').unwrap_or((site, ""));
            let with = format!("{keep} {}", HUGE[rng.random_range(0..HUGE.len())]);
            if let Some(at) = bytes.windows(site.len()).position(|w| w == site.as_bytes()) {
                bytes.splice(at..at + site.len(), with.into_bytes());
            }
        }
        5 if len > 0 => {
            let a = rng.random_range(0..len);
            let b = rng.random_range(a..=len.min(a + 64));
            bytes.drain(a..b);
        }
        _ if len > 0 => {
            // Overwrite four bytes with a huge little- or big-endian count.
            let at = rng.random_range(0..len);
            let v: [u8; 4] = if rng.random() { 0xEE6B_2800u32.to_le_bytes() } else { u32::MAX.to_be_bytes() };
            for (k, b) in v.into_iter().enumerate() {
                if let Some(slot) = bytes.get_mut(at + k) {
                    *slot = b;
                }
            }
        }
        _ => bytes.push(b'\n'),
    }
}

/// Runs `read` on `CASES` mutations of `valid`, checking it neither panics
/// nor asks for absurd memory; returns how many were accepted.
fn fuzz(name: &str, seed: u64, valid: &[u8], counts: &[&str], read: impl Fn(&[u8]) -> bool) -> usize {
    assert!(read(valid), "{name}: the unmutated file must be valid");
    let mut rng = StdRng::seed_from_u64(seed);
    let mut accepted = 0;
    for case in 0..CASES {
        let mut bytes = valid.to_vec();
        for _ in 0..rng.random_range(1..4) {
            mutate(&mut rng, &mut bytes, counts);
        }
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read(&bytes)));
        let shown = String::from_utf8_lossy(&bytes[..bytes.len().min(400)]).into_owned();
        let ok = outcome.unwrap_or_else(|_| panic!("{name} case {case} (seed {seed}) panicked on {shown:?}"));
        accepted += usize::from(ok);
        let largest = LARGEST.load(Ordering::Relaxed);
        assert!(
            largest <= ALLOCATION_LIMIT,
            "{name} case {case} (seed {seed}): an allocation of {largest} bytes on {shown:?}"
        );
    }
    eprintln!("{name}: {accepted} of {CASES} accepted");
    accepted
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

const PCD_HEADER: &str = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb normal\nSIZE 4 4 4 4 8\nTYPE F F F U F\nCOUNT 1 1 1 1 2\nWIDTH 4\nHEIGHT 1\nVIEWPOINT 1 2 3 0.7071068 0 0 0.7071068\nPOINTS 4\n";
const PCD_COUNTS: [&str; 5] = ["POINTS 4", "WIDTH 4", "HEIGHT 1", "COUNT 1 1 1 1 2", "SIZE 4 4 4 4 8"];

#[test]
fn pcd_ascii_survives_mutations() {
    let mut file = format!("{PCD_HEADER}DATA ascii\n");
    for k in 0..4 {
        file.push_str(&format!("{k}.5 -{k} 1e-3 4278190080 0.25 -0.5\n"));
    }
    let n = fuzz("pcd ascii", 1, file.as_bytes(), &PCD_COUNTS, |b| parse_pcd(Path::new("a.pcd"), b).is_ok());
    assert!(n < CASES, "some mutations must be refused");
}

#[test]
fn pcd_binary_survives_mutations() {
    let mut file = format!("{PCD_HEADER}DATA binary\n").into_bytes();
    for k in 0..4 {
        for v in [k as f32, 1.0, -2.0] {
            file.extend_from_slice(&v.to_le_bytes());
        }
        file.extend_from_slice(&7u32.to_le_bytes());
        file.extend_from_slice(&0.5f64.to_le_bytes());
        file.extend_from_slice(&1.5f64.to_le_bytes());
    }
    fuzz("pcd binary", 2, &file, &PCD_COUNTS, |b| parse_pcd(Path::new("b.pcd"), b).is_ok());
}

const PLY_COUNTS: [&str; 4] = ["element vertex 4", "element face 2", "element camera 1", "element edge 3"];

#[test]
fn ply_ascii_survives_mutations() {
    let file = "ply\nformat ascii 1.0\ncomment fuzz\nelement camera 1\nproperty list uchar float k\nelement vertex 4\nproperty float x\nproperty double y\n\
                property uchar red\nproperty list uint8 int16 tags\nproperty int z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
                3 1 2 3\n1 2 3 2 7 8 4\n0 0 9 0 1\n-1 -2 0 1 5 3\n1e3 2.5 255 0 -7\n3 0 1 2\n3 1 2 3\n";
    fuzz("ply ascii", 3, file.as_bytes(), &PLY_COUNTS, |b| parse_ply(Path::new("a.ply"), b).is_ok());
}

#[test]
fn ply_binary_survives_mutations() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("w.ply");
    let points: Vec<ColouredPoint> =
        (0..4).map(|k| ColouredPoint { xyz: [k as f32, 1.0, 2.0], rgb: [1, 2, 3] }).collect();
    write_ply(&path, &points, "fuzz").expect("written");
    let little = std::fs::read(&path).expect("read");
    fuzz("ply little-endian", 4, &little, &PLY_COUNTS, |b| parse_ply(Path::new("w.ply"), b).is_ok());

    let mut big = b"ply\nformat binary_big_endian 1.0\nelement edge 3\nproperty list uchar int v\nproperty short w\nelement vertex 4\nproperty double x\nproperty list ushort uchar n\nproperty float y\nproperty uint z\nend_header\n".to_vec();
    for k in 0..3u8 {
        big.push(k);
        big.extend((0..k).flat_map(|j| i32::from(j).to_be_bytes()));
        big.extend_from_slice(&(-3i16).to_be_bytes());
    }
    for k in 0..4u16 {
        big.extend_from_slice(&f64::from(k).to_be_bytes());
        big.extend_from_slice(&k.to_be_bytes());
        big.extend((0..k).map(|j| j as u8));
        big.extend_from_slice(&1.5f32.to_be_bytes());
        big.extend_from_slice(&9u32.to_be_bytes());
    }
    fuzz("ply big-endian", 5, &big, &PLY_COUNTS, |b| parse_ply(Path::new("b.ply"), b).is_ok());
}

#[test]
fn kitti_bin_survives_mutations() {
    let scan: Vec<u8> = (0..32).flat_map(|k| [k as f32, 1.0, 2.0, 0.5]).flat_map(f32::to_le_bytes).collect();
    fuzz("kitti bin", 6, &scan, &[], |b| parse_kitti_bin(Path::new("0.bin"), b).is_ok());
}

#[test]
fn text_trajectories_survive_mutations() {
    let tum =
        "# timestamp tx ty tz qx qy qz qw\n1.0 1 2 3 0 0 0 1\n1.1,1.5,2,3,0,0,0.7071068,0.7071068\n1.2 2 2 3 0 0 1 0\n";
    fuzz("tum", 7, tum.as_bytes(), &[], |b| Trajectory::parse_tum(&text(b)).is_ok());
    let kitti = "1 0 0 0 0 1 0 0 0 0 1 0\n0 -1 0 10 1 0 0 20 0 0 1 0.5\n1 0 0 1e3 0 1 0 -2 0 0 1 3\n";
    fuzz("kitti poses", 8, kitti.as_bytes(), &[], |b| parse_kitti_poses(Path::new("poses.txt"), &text(b)).is_ok());
    fuzz("times", 9, b"0.0\n0.1\n1e2\n", &[], |b| parse_times(Path::new("times.txt"), &text(b)).is_ok());
    let matrix = "0 -1 0 1\n1 0 0 2\n0 0 1 3\n0 0 0 1\n";
    fuzz("pose matrix", 10, matrix.as_bytes(), &[], |b| parse_matrix(Path::new("a.pose.txt"), &text(b)).is_ok());
    let k = "570.342 0 320\n0 570.342 240\n0 0 1\n";
    fuzz("intrinsics", 11, k.as_bytes(), &[], |b| {
        parse_intrinsics(Path::new("camera-intrinsics.txt"), &text(b)).is_ok()
    });
}

/// The huge counts on their own, one at a time, in every header keyword
/// that sizes the data.
#[test]
fn huge_header_counts_are_refused_without_allocating() {
    for huge in HUGE {
        for site in PCD_COUNTS {
            for data in ["ascii", "binary"] {
                let (keep, _) = site.rsplit_once(' ').expect("count");
                let file = format!("{PCD_HEADER}DATA {data}\n1 2 3 4 5 6\n").replace(site, &format!("{keep} {huge}"));
                let _ = parse_pcd(Path::new("h.pcd"), file.as_bytes());
            }
        }
        for format in ["ascii", "binary_little_endian", "binary_big_endian"] {
            let file = format!("ply\nformat {format} 1.0\nelement face {huge}\nproperty list uchar int i\nelement vertex {huge}\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3 4 5 6 7 8\n");
            let _ = parse_ply(Path::new("h.ply"), file.as_bytes());
        }
        let largest = LARGEST.load(Ordering::Relaxed);
        assert!(largest <= ALLOCATION_LIMIT, "{huge}: an allocation of {largest} bytes");
    }
}

/// A PCD whose `POINTS` is smaller than its data is refused, not cut to
/// `POINTS` points: ascii with extra lines, binary with extra bytes.
#[test]
fn pcd_data_past_points_is_refused() {
    let head = |points: usize, data: &str| {
        format!("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {points}\nHEIGHT 1\nPOINTS {points}\nDATA {data}\n")
    };
    let ascii = format!("{}1 2 3\n4 5 6\n7 8 9\n\n", head(2, "ascii"));
    let err = parse_pcd(Path::new("more.pcd"), ascii.as_bytes()).expect_err("3 lines for POINTS 2").to_string();
    assert!(
        err.contains("more.pcd") && err.contains("line 12") && err.contains("POINTS is 2") && err.contains("3 lines"),
        "{err}"
    );
    // Blank lines after the points are not points.
    let ascii = format!("{}1 2 3\n4 5 6\n\n  \n", head(2, "ascii"));
    assert_eq!(parse_pcd(Path::new("ok.pcd"), ascii.as_bytes()).expect("2 points").points.len(), 2);

    let mut binary = head(2, "binary").into_bytes();
    binary.extend((0..9).flat_map(|k| (k as f32).to_le_bytes()));
    let err = parse_pcd(Path::new("more.pcd"), &binary).expect_err("36 bytes for POINTS 2").to_string();
    assert!(
        err.contains("more.pcd")
            && err.contains("POINTS 2")
            && err.contains("24 bytes")
            && err.contains("36")
            && err.contains("12 bytes past"),
        "{err}"
    );
    binary.truncate(binary.len() - 12);
    assert_eq!(
        parse_pcd(Path::new("ok.pcd"), &binary).expect("2 points").points,
        vec![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]
    );
}

/// The error (or `Ok`) of opening and reading `bytes` as an obstacle npy.
fn read_npy(name: &str, bytes: &[u8]) -> Result<usize, String> {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join(name);
    std::fs::write(&path, bytes).expect("write");
    let grid = edtmap_io::npy::ObstacleNpy::open(&path).and_then(|f| f.read()).map_err(|e| e.to_string())?;
    Ok(grid.as_slice().iter().filter(|&&o| o).count())
}

#[test]
fn npy_trailing_bytes_duplicate_keys_and_bad_bools_are_refused() {
    let dict = "{'descr': '|b1', 'fortran_order': False, 'shape': (2, 3), }";
    assert_eq!(read_npy("ok.npy", &support::raw_npy(dict, &[0, 1, 1, 0, 0, 1])), Ok(3));

    let err = read_npy("tail.npy", &support::raw_npy(dict, &[0, 1, 1, 0, 0, 1, 9, 9])).expect_err("trailing");
    assert!(
        err.contains("tail.npy")
            && err.contains("2 bytes after the data")
            && err.contains("[2, 3]")
            && err.contains("gives 6 bytes")
            && err.contains("has 8"),
        "{err}"
    );

    let twice = "{'descr': '|b1', 'fortran_order': False, 'shape': (2, 3), 'shape': (3, 2), }";
    let err = read_npy("twice.npy", &support::raw_npy(twice, &[0; 6])).expect_err("duplicate key");
    assert!(err.contains("twice.npy") && err.contains("\"shape\" twice"), "{err}");

    let err = read_npy("seven.npy", &support::raw_npy(dict, &[0, 1, 1, 7, 0, 1])).expect_err("bool 7");
    assert!(err.contains("seven.npy") && err.contains("element 3") && err.contains("value 7"), "{err}");
    // Integer dtypes keep "nonzero is an obstacle".
    let bytes = "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3), }";
    assert_eq!(read_npy("u8.npy", &support::raw_npy(bytes, &[0, 1, 1, 7, 0, 1])), Ok(4));
}
