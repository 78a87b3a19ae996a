//! `read_ply`: what `write_ply` writes, hand-written ascii and big-endian
//! files with extra properties and elements, every scalar type name, and
//! the errors for broken files.

use edtmap_io::ply::{parse_ply, read_ply, write_ply, ColouredPoint};
use edtmap_io::IoError;
use std::path::Path;

fn parse(bytes: &[u8]) -> Result<Vec<[f32; 3]>, IoError> {
    parse_ply(Path::new("cloud.ply"), bytes).map(|c| c.points)
}

#[test]
fn reads_what_write_ply_writes() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let path = tmp.path().join("occupied.ply");
    let points: Vec<ColouredPoint> = (0..50)
        .map(|k| ColouredPoint { xyz: [k as f32 * 0.5, -(k as f32), 1e-3 * k as f32], rgb: [k as u8, 2, 3] })
        .collect();
    write_ply(&path, &points, "round trip").expect("written");
    let cloud = read_ply(&path).expect("read back");
    assert_eq!(cloud.points, points.iter().map(|p| p.xyz).collect::<Vec<_>>());
    let err = read_ply(&tmp.path().join("missing.ply")).expect_err("no file").to_string();
    assert!(err.contains("missing.ply"), "{err}");
}

#[test]
fn ascii_with_extra_properties_and_a_face_element() {
    let text = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info nothing\r\n\
                element camera 1\r\nproperty list uchar float params\r\nproperty int id\r\n\
                element vertex 3\r\nproperty uchar red\r\nproperty double z\r\nproperty list int int8 tags\r\n\
                property float x\r\nproperty float32 y\r\nproperty float nx\r\n\
                element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n\
                3 0.1 0.2 0.3 7\r\n\
                255 3.5 2 1 2 1.5 2.5 0\r\n\
                0 -1 0 0 -2 1\r\n\
                9 1e2 3 5 6 7 10 20 0.5\r\n\
                3 0 1 2\r\n";
    assert_eq!(parse(text.as_bytes()).expect("valid"), vec![[1.5, 2.5, 3.5], [0.0, -2.0, -1.0], [10.0, 20.0, 100.0]]);
}

/// A big-endian file: a `face` element of lists before the vertices,
/// vertices of `short x`, `double y`, `uint z` among other properties, and
/// an element after them that the file does not even hold.
fn big_endian() -> Vec<u8> {
    let mut b = b"ply\nformat binary_big_endian 1.0\nelement face 2\nproperty list uchar int vertex_indices\nproperty ushort flags\n\
                  element vertex 2\nproperty short x\nproperty uchar confidence\nproperty double y\nproperty list ushort float normals\nproperty uint z\n\
                  element edge 1000\nproperty int vertex1\nend_header\n"
        .to_vec();
    for n in [3u8, 1] {
        b.push(n);
        for k in 0..n {
            b.extend_from_slice(&i32::from(k).to_be_bytes());
        }
        b.extend_from_slice(&7u16.to_be_bytes());
    }
    for (x, y, z, normals) in [(-3i16, 0.25f64, 7u32, 2u16), (1000, -1e3, 4_000_000_000, 0)] {
        b.extend_from_slice(&x.to_be_bytes());
        b.push(200);
        b.extend_from_slice(&y.to_be_bytes());
        b.extend_from_slice(&normals.to_be_bytes());
        for _ in 0..normals {
            b.extend_from_slice(&1.5f32.to_be_bytes());
        }
        b.extend_from_slice(&z.to_be_bytes());
    }
    b
}

#[test]
fn big_endian_of_mixed_types_with_lists_before_and_elements_after() {
    assert_eq!(parse(&big_endian()).expect("valid"), vec![[-3.0, 0.25, 7.0], [1000.0, -1000.0, 4e9]]);
}

#[test]
fn every_scalar_type_name() {
    for (names, bytes) in [
        (["char", "int8"], vec![0xFFu8]),
        (["uchar", "uint8"], vec![0xFF]),
        (["short", "int16"], (-2i16).to_le_bytes().to_vec()),
        (["ushort", "uint16"], 65535u16.to_le_bytes().to_vec()),
        (["int", "int32"], (-5i32).to_le_bytes().to_vec()),
        (["uint", "uint32"], 5u32.to_le_bytes().to_vec()),
        (["float", "float32"], 0.5f32.to_le_bytes().to_vec()),
        (["double", "float64"], 0.25f64.to_le_bytes().to_vec()),
    ] {
        let want = match names[0] {
            "char" => -1.0,
            "uchar" => 255.0,
            "short" => -2.0,
            "ushort" => 65535.0,
            "int" => -5.0,
            "uint" => 5.0,
            "float" => 0.5,
            _ => 0.25,
        };
        for name in names {
            let mut file = format!("ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty {name} x\nproperty {name} y\nproperty {name} z\nend_header\n").into_bytes();
            for _ in 0..3 {
                file.extend_from_slice(&bytes);
            }
            assert_eq!(parse(&file).expect(name), vec![[want; 3]], "{name}");
        }
    }
}

#[test]
fn broken_files_name_the_problem() {
    let head =
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"PLY\n".to_vec(), "not a PLY file"),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n".to_vec(), "no end_header"),
        (b"ply\nelement vertex 0\nproperty float x\nend_header\n".to_vec(), "no format line"),
        (b"ply\nformat ascii 1.0\nformat ascii 1.0\nend_header\n".to_vec(), "header line 3: format given twice"),
        (b"ply\nformat ascii 2.0\nend_header\n".to_vec(), "version \"2.0\""),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty half z\nend_header\n".to_vec(), "header line 6: unknown type \"half\""),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n".to_vec(), "no property z"),
        (b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int i\nend_header\n".to_vec(), "no vertex element"),
        (b"ply\nformat ascii 1.0\nproperty float x\nend_header\n".to_vec(), "property before any element"),
        (b"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n".to_vec(), "count \"-1\""),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float float x\nend_header\n".to_vec(), "length type"),
        (format!("{head}1 2 3\n4 five 6\n").into_bytes(), "line 9: bad number \"five\" for y"),
        (format!("{head}1 2 3\n4 5\n").into_bytes(), "line 9: the data ends in record 1 of element vertex"),
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0".to_vec(), "truncated data"),
        (b"ply\nformat binary_big_endian 1.0\nelement face 3\nproperty list uchar int i\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x01\0\0\0\0\x05".to_vec(), "record 1 of element face"),
    ];
    for (bytes, want) in cases {
        let err = parse(&bytes).expect_err(want).to_string();
        assert!(err.contains("cloud.ply") && err.contains(want), "want {want:?} in {err:?}");
    }
}
