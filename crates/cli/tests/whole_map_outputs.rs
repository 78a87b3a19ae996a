//! Outputs of a whole saved map: `export` without `--box`, map_server
//! maps, top-view pictures and the frontiers of a one-voxel-thick map.

use std::path::{Path, PathBuf};
use std::process::Command;

fn edtmap(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap")).args(args).output().expect("edtmap runs");
    (o.status.success(), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// Maps `scene` for a few frames and saves the map in `dir`.
fn saved_map(dir: &Path, scene: &str) -> PathBuf {
    let map = dir.join(format!("{scene}.edtmap"));
    let out = dir.join(format!("{scene}-run"));
    let (ok, stdout, err) = edtmap(&["run", "--scene", scene, "--frames", "6", "--out", s(&out), "--save", s(&map)]);
    assert!(ok, "{stdout}\n{err}");
    map
}

/// The numbers after `prefix` on the line of `text` that starts with it.
fn numbers_after(text: &str, prefix: &str) -> Vec<f64> {
    let line = text.lines().find_map(|l| l.strip_prefix(prefix)).unwrap_or_else(|| panic!("no {prefix:?} in {text}"));
    line.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-')).filter(|t| !t.is_empty()).map(|t| t.parse().expect("number")).collect()
}

#[test]
fn export_without_a_box_covers_the_mapped_box() {
    let dir = tempfile::tempdir().expect("tempdir");
    let map = saved_map(dir.path(), "planar");
    let (ok, info, err) = edtmap(&["info", s(&map)]);
    assert!(ok, "{err}");
    let mapped = numbers_after(&info, "mapped box (m): ");
    let counts = numbers_after(&info, "voxels: ");
    let (free, occupied) = (counts[0] as usize, counts[1] as usize);
    assert!(free > 0 && occupied > 0, "{info}");

    let npy = dir.path().join("all.npy");
    let states = dir.path().join("all_states.npy");
    let (ok, out, err) = edtmap(&["export", s(&map), s(&npy), "--states", s(&states)]);
    assert!(ok, "{out}\n{err}");
    let sidecar: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("all.npy.json")).expect("sidecar")).expect("json");
    let corner = |k: &str| -> Vec<f64> { sidecar["box_m"][k].as_array().expect("box").iter().map(|v| v.as_f64().expect("number")).collect() };
    let (lo, hi) = (corner("min"), corner("max"));
    for a in 0..3 {
        assert!((lo[a] - mapped[a]).abs() < 0.006 && (hi[a] - mapped[a + 3]).abs() < 0.006, "box {lo:?}..{hi:?}, info {mapped:?}");
    }
    // The whole map is in the box: every free and occupied voxel that
    // `info` counts is there, with its state.
    let bytes = std::fs::read(&states).expect("states");
    let array = npyz::NpyFile::new(&bytes[..]).expect("npy");
    let shape = array.shape().to_vec();
    let values: Vec<u8> = array.into_vec().expect("u8 states");
    let vs = sidecar["voxel_size_m"].as_f64().expect("voxel size");
    let expected: Vec<u64> = [2, 1, 0].map(|a| ((mapped[a + 3] - mapped[a]) / vs).round() as u64).to_vec();
    assert_eq!(shape, expected);
    assert_eq!(values.iter().filter(|&&v| v == 2).count(), free);
    assert_eq!(values.iter().filter(|&&v| v == 3).count(), occupied);

    // A box of the wrong length still names the option.
    let (ok, _, err) = edtmap(&["export", s(&map), "--box", "0,0,0", s(&npy)]);
    assert!(!ok && err.contains("--box takes six numbers"), "{err}");
}

#[test]
fn frontiers_of_a_planar_map_stay_in_its_plane() {
    let dir = tempfile::tempdir().expect("tempdir");
    let map = saved_map(dir.path(), "planar");
    let frontiers = dir.path().join("frontiers.csv");
    let (ok, info, err) = edtmap(&["info", s(&map), "--frontiers", s(&frontiers)]);
    assert!(ok, "{err}");
    let reported = numbers_after(&info, "voxels: ")[2] as usize;

    // Brute force over the states of the whole mapped box: free voxels
    // with an unknown (or unmapped) neighbour among the four in the plane.
    let states = dir.path().join("states.npy");
    let (ok, out, err) = edtmap(&["export", s(&map), s(&dir.path().join("d.npy")), "--states", s(&states)]);
    assert!(ok, "{out}\n{err}");
    let bytes = std::fs::read(&states).expect("states");
    let array = npyz::NpyFile::new(&bytes[..]).expect("npy");
    let [nz, ny, nx] = <[u64; 3]>::try_from(array.shape()).expect("3D").map(|n| n as i64);
    let values: Vec<u8> = array.into_vec().expect("u8 states");
    let at = |x: i64, y: i64, z: i64| if (0..nx).contains(&x) && (0..ny).contains(&y) { values[((z * ny + y) * nx + x) as usize] } else { 0 };
    let layers: Vec<i64> = (0..nz).filter(|&z| (0..ny).any(|y| (0..nx).any(|x| at(x, y, z) >= 2))).collect();
    assert_eq!(layers.len(), 1, "the planar scene observes one layer");
    let z = layers[0];
    let mut brute = 0;
    for y in 0..ny {
        for x in 0..nx {
            let unknown_beside = [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|(dx, dy)| at(x + dx, y + dy, z) <= 1);
            brute += usize::from(at(x, y, z) == 2 && unknown_beside);
        }
    }
    let free = numbers_after(&info, "voxels: ")[0] as usize;
    assert!(brute > 0 && brute < free, "in-plane frontiers are the rim of the free area: {brute} of {free}");
    assert_eq!(reported, brute, "{info}");
    let listed: Vec<String> = std::fs::read_to_string(&frontiers).expect("csv").lines().skip(1).map(String::from).collect();
    assert_eq!(listed.len(), brute);
    let heights: std::collections::BTreeSet<&str> = listed.iter().map(|l| l.rsplit(',').next().expect("z")).collect();
    assert_eq!(heights.len(), 1, "every frontier lies in the scan plane");
}
