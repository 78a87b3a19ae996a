//! `edtmap run --dataset`: the real recordings replayed with the shipped
//! configs, and the mistakes a user can make. The Velodyne pair ships in the
//! repository (`data/`); the depth recordings are read from `../shared/data`
//! beside the checkout where it exists, and their cases are skipped (with a
//! note) where it does not.

use std::path::PathBuf;
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A recording of the repository's own `data/` folder.
fn repo_data(name: &str) -> PathBuf {
    root().join("data").join(name)
}

/// A recording of `../shared/data`, or `None` (with a note) where it is absent.
fn data(name: &str) -> Option<PathBuf> {
    let dir = root().join("../shared/data").join(name);
    if dir.exists() {
        Some(dir)
    } else {
        eprintln!("skipping: {} is absent", dir.display());
        None
    }
}

fn run(config: &str, dataset: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(["run", "--config"])
        .arg(root().join("configs").join(config))
        .arg("--dataset")
        .arg(dataset)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .expect("edtmap runs")
}

fn report(out: &std::path::Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("report.json")).expect("report")).expect("json")
}

/// The vertex count of a binary PLY, checking the body holds exactly that
/// many 15-byte vertices.
fn ply_vertices(path: &std::path::Path) -> usize {
    let bytes = std::fs::read(path).expect("ply");
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).expect("header") + end.len();
    let header = std::str::from_utf8(&bytes[..at]).expect("ascii header");
    let n: usize =
        header.lines().find_map(|l| l.strip_prefix("element vertex ")).expect("vertex count").parse().expect("number");
    assert_eq!(bytes.len() - at, 15 * n, "{}", path.display());
    n
}

#[test]
fn replays_the_3dmatch_frames_and_the_velodyne_pair() {
    let tmp = tempfile::tempdir().expect("temp dir");
    for (config, name, frames, sensor) in
        [("velodyne.toml", "velodyne-pair", 2, "point cloud"), ("3dmatch.toml", "3dmatch-seq01", 5, "depth camera")]
    {
        let dir = if name == "velodyne-pair" {
            repo_data(name)
        } else if let Some(dir) = data(name) {
            dir
        } else {
            continue;
        };
        let out = tmp.path().join(name);
        let o =
            run(config, &dir, &out, &["--eval", "--ply", "--save", out.join("map.edtmap").to_str().expect("utf-8")]);
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        let r = report(&out);
        assert_eq!(r["frames"].as_array().map(Vec::len), Some(frames), "{name}");
        assert_eq!(r["sensor"], sensor);
        assert!(r["map_blocks"].as_u64().is_some_and(|b| b > 100), "{name}: {}", r["map_blocks"]);
        for picture in ["occupancy_slice.png", "edt_slice.png", "timing.png", "map.edtmap"] {
            assert!(out.join(picture).metadata().is_ok_and(|m| m.len() > 0), "{name}: {picture}");
        }
        // occupied.ply holds exactly the saved map's occupied voxels.
        let map = edtmap::load_map(&out.join("map.edtmap")).expect("saved map");
        let occupied = map
            .occupancy()
            .iter()
            .flat_map(|(_, b)| b.log_odds.iter())
            .filter(|&v| map.log_odds().state(v) == edtmap::VoxelState::Occupied)
            .count();
        assert_eq!(ply_vertices(&out.join("occupied.ply")), occupied, "{name}");
        assert!(ply_vertices(&out.join("edt.ply")) > 1000, "{name}");
        // Every field of the report is in its schema, docs/REPORT.md.
        let schema = std::fs::read_to_string(root().join("docs/REPORT.md")).expect("docs/REPORT.md");
        let keys = [&r, &r["frames"][0], &r["summary"]]
            .into_iter()
            .flat_map(|o| o.as_object().expect("object").keys().cloned().collect::<Vec<_>>());
        for key in keys {
            assert!(schema.contains(&format!("`{key}`")), "report field {key} is not in docs/REPORT.md");
        }
        // The global EDT against an exact EDT of the map's own obstacles.
        let last = &r["frames"][frames - 1];
        assert_eq!(last["global_max_m"].as_f64(), Some(0.0), "{name}: {last}");
    }
}

#[test]
fn dataset_mistakes_are_refused_with_the_reason() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let clouds = repo_data("velodyne-pair");
    let mut cases: Vec<(&str, PathBuf, &[&str], &str)> = vec![
        ("3dmatch.toml", clouds.clone(), &[], "holds point cloud frames"),
        ("velodyne.toml", clouds, &["--frames", "9"], "has 2 frames"),
        ("3dmatch.toml", tmp.path().to_path_buf(), &[], "neither a depth folder"),
    ];
    if let Some(depth) = data("3dmatch-seq01") {
        cases.push(("velodyne.toml", depth, &[], "holds depth camera frames"));
    }
    for (config, dir, extra, want) in cases {
        let o = run(config, &dir, &tmp.path().join("out"), extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(want), "{config} {}: {err}", dir.display());
    }
}

/// An ascii PCD of a small wall at x = 3 m.
fn wall_pcd(data_line: &str) -> String {
    let points: Vec<String> = (0..40)
        .flat_map(|i| (0..10).map(move |k| format!("3 {} {}", -1.0 + 0.05 * i as f64, 0.1 * k as f64)))
        .collect();
    format!("VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\n{data_line}\n{}\n", points.join("\n"), n = points.len())
}

#[test]
fn a_bad_cloud_is_skipped_or_stops_the_run_keeping_the_others() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("clouds");
    std::fs::create_dir(&dir).expect("dir");
    for (name, data) in
        [("000000.pcd", "DATA ascii"), ("000001.pcd", "DATA binary_compressed"), ("000002.pcd", "DATA ascii")]
    {
        std::fs::write(dir.join(name), wall_pcd(data)).expect("pcd");
    }
    std::fs::write(dir.join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n".repeat(3)).expect("poses");
    let out = tmp.path().join("out");
    let o = run("velodyne.toml", &dir, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("000001.pcd") && err.contains("binary_compressed"), "{err}");
    let r = report(&out);
    assert_eq!(
        r["frames"].as_array().map(|f| f.iter().map(|x| x["index"].as_u64()).collect::<Vec<_>>()),
        Some(vec![Some(0), Some(2)])
    );
    assert!(r["skipped"][0]["reason"].as_str().is_some_and(|s| s.contains("000001.pcd")), "{}", r["skipped"]);
    // With on_error = "stop": the first frame is kept and written, the run fails naming the file.
    let config = std::fs::read_to_string(root().join("configs/velodyne.toml")).expect("config")
        + "\n[dataset]\non_error = \"stop\"\n";
    let stop = tmp.path().join("stop.toml");
    std::fs::write(&stop, config).expect("config");
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(["run", "--config"])
        .arg(&stop)
        .arg("--dataset")
        .arg(&dir)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("000001.pcd") && err.contains("the 1 frame before it is integrated"),
        "{err}"
    );
    assert_eq!(report(&out)["frames"].as_array().map(Vec::len), Some(1));
}

/// A row-major 3 × 4 pose (KITTI's `poses.txt` line): a rotation of `angle`
/// about z whose entries are off by `noise` (as published ground truth
/// is), at `x` along the x axis.
fn kitti_line(angle: f64, noise: f64, x: f64) -> String {
    let (s, c) = angle.sin_cos();
    let r = [[c + noise, -s, 0.0], [s, c - noise, noise], [0.0, 0.0, 1.0 + noise]];
    format!(
        "{} {} {} {x} {} {} {} 0 {} {} {} 0\n",
        r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]
    )
}

#[test]
fn published_poses_are_projected_with_one_warning_and_bad_ones_refused() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("clouds");
    std::fs::create_dir(&dir).expect("dir");
    for k in 0..3 {
        std::fs::write(dir.join(format!("00000{k}.pcd")), wall_pcd("DATA ascii")).expect("pcd");
    }
    // Orthonormal to 3e-4, as 7-Scenes' ground truth: every frame maps, and
    // one warning names the worst deviation.
    let poses = (0..3).map(|k| kitti_line(0.1 * k as f64, 1.5e-4, 0.1 * k as f64)).collect::<String>();
    std::fs::write(dir.join("poses.txt"), poses).expect("poses");
    let out = tmp.path().join("out");
    let o = run("velodyne.toml", &dir, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("had rotations orthonormal only to").count(), 1, "{err}");
    assert!(err.contains("3 poses") && err.contains("e-4 (worst"), "{err}");
    assert_eq!(report(&out)["frames"].as_array().map(Vec::len), Some(3));
    // Beyond the tolerance (2 %): refused, naming the file, line and the fix.
    let poses = kitti_line(0.0, 0.0, 0.0) + &kitti_line(0.1, 2e-2, 0.1) + &kitti_line(0.2, 0.0, 0.2);
    std::fs::write(dir.join("poses.txt"), poses).expect("poses");
    let o = run("velodyne.toml", &dir, &tmp.path().join("refused"), &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("poses.txt")
            && err.contains("line 2")
            && err.contains("not orthonormal")
            && err.contains("accepted up to 1e-2"),
        "{err}"
    );
}

#[test]
fn the_seven_scenes_frames_map_as_published() {
    let Some(dir) = data("7scenes-kitchen-100") else { return };
    let tmp = tempfile::tempdir().expect("temp dir");
    let out = tmp.path().join("out");
    let o = run("3dmatch.toml", &dir, &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("had rotations orthonormal only to").count(), 1, "{err}");
    assert_eq!(report(&out)["frames"].as_array().map(Vec::len), Some(100));
}
