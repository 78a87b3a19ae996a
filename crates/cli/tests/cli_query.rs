//! `edtmap run --save`, then `query`, `export` and `info` on the saved map.

use std::path::Path;
use std::process::Command;

fn edtmap(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap")).args(args).output().expect("edtmap runs");
    (o.status.success(), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

#[test]
fn saved_map_answers_queries_and_exports() {
    let dir = tempfile::tempdir().expect("tempdir");
    let map = dir.path().join("map.edtmap");
    let (ok, out, err) =
        edtmap(&["run", "--scene", "planar", "--frames", "6", "--out", s(dir.path()), "--save", s(&map)]);
    assert!(ok, "{out}\n{err}");
    let frontiers = dir.path().join("frontiers.csv");
    let (ok, info, err) = edtmap(&["info", s(&map), "--frontiers", s(&frontiers)]);
    assert!(ok && info.contains("voxel 0.") && info.contains("blocks:"), "{info}\n{err}");
    let listed = std::fs::read_to_string(&frontiers).expect("frontiers").lines().count() - 1;
    assert!(listed > 0 && info.contains(&format!("{listed} exploration frontiers")), "{info}");

    let points = dir.path().join("points.csv");
    std::fs::write(&points, "x,y,z\n# a comment\n0.5,0.5,1.0\n1e5,0,0\n").expect("write");
    let (ok, csv, err) = edtmap(&["query", s(&map), "--points", s(&points)]);
    assert!(ok, "{err}");
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], "x,y,z,distance_m,grad_x,grad_y,grad_z,state,observed,saturated");
    assert_eq!(lines.len(), 3, "{csv}");
    let far: Vec<&str> = lines[2].split(',').collect();
    assert_eq!(
        (far[7], far[9]),
        ("outside", "true"),
        "a point far outside the mapped area reads the cutoff, saturated"
    );

    let npy = dir.path().join("box.npy");
    let states = dir.path().join("states.npy");
    let (ok, out, err) = edtmap(&["export", s(&map), "--box", "-1,-1,0.5,1,1,1.5", s(&npy), "--states", s(&states)]);
    assert!(ok, "{out}\n{err}");
    let bytes = std::fs::read(&npy).expect("npy");
    assert!(bytes.starts_with(b"\x93NUMPY") && std::fs::read(&states).expect("states").starts_with(b"\x93NUMPY"));

    // Bad input: a malformed points file and a truncated map name the file.
    std::fs::write(&points, "1,2\n").expect("write");
    let (ok, _, err) = edtmap(&["query", s(&map), "--points", s(&points)]);
    assert!(!ok && err.contains("points.csv: line 1"), "{err}");
    let cut = dir.path().join("cut.edtmap");
    std::fs::write(&cut, &std::fs::read(&map).expect("map")[..200]).expect("write");
    let (ok, _, err) = edtmap(&["info", s(&cut)]);
    assert!(!ok && err.contains("cut.edtmap") && err.contains("truncated"), "{err}");
    let (ok, _, err) = edtmap(&["export", s(&map), "--box", "1,1,1,0,0,0", s(&npy)]);
    assert!(!ok && err.contains("box"), "{err}");
}
