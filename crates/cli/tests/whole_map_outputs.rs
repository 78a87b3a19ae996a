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
    line.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
        .filter(|t| !t.is_empty())
        .map(|t| t.parse().expect("number"))
        .collect()
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
    let sidecar: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("all.npy.json")).expect("sidecar")).expect("json");
    let corner = |k: &str| -> Vec<f64> {
        sidecar["box_m"][k].as_array().expect("box").iter().map(|v| v.as_f64().expect("number")).collect()
    };
    let (lo, hi) = (corner("min"), corner("max"));
    for a in 0..3 {
        assert!(
            (lo[a] - mapped[a]).abs() < 0.006 && (hi[a] - mapped[a + 3]).abs() < 0.006,
            "box {lo:?}..{hi:?}, info {mapped:?}"
        );
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
    let at = |x: i64, y: i64, z: i64| {
        if (0..nx).contains(&x) && (0..ny).contains(&y) {
            values[((z * ny + y) * nx + x) as usize]
        } else {
            0
        }
    };
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
    let listed: Vec<String> =
        std::fs::read_to_string(&frontiers).expect("csv").lines().skip(1).map(String::from).collect();
    assert_eq!(listed.len(), brute);
    let heights: std::collections::BTreeSet<&str> = listed.iter().map(|l| l.rsplit(',').next().expect("z")).collect();
    assert_eq!(heights.len(), 1, "every frontier lies in the scan plane");
}

/// A map_server map read back by a minimal loader of its own: the YAML's
/// keys, and the PGM's cells as map_server classifies them.
struct LoadedMap {
    resolution: f64,
    origin: [f64; 3],
    width: usize,
    height: usize,
    /// "occupied", "free" or "unknown" per pixel, row 0 at the top.
    cells: Vec<&'static str>,
}

fn load_map_server(yaml: &Path) -> LoadedMap {
    let text = std::fs::read_to_string(yaml).expect("yaml");
    let value = |key: &str| -> String {
        let line = text
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{key}:")))
            .unwrap_or_else(|| panic!("no {key} in {text}"));
        line.trim().to_string()
    };
    let number = |key: &str| value(key).parse::<f64>().unwrap_or_else(|e| panic!("{key}: {e}"));
    assert_eq!(value("mode"), "trinary");
    assert_eq!(value("negate"), "0");
    let (occupied_thresh, free_thresh) = (number("occupied_thresh"), number("free_thresh"));
    let origin: Vec<f64> =
        value("origin").trim_matches(['[', ']']).split(',').map(|t| t.trim().parse().expect("origin number")).collect();
    let image = yaml.parent().expect("folder").join(value("image").trim_matches('"'));
    let bytes = std::fs::read(image).expect("pgm");
    // P5, then width, height and maxval as whitespace-separated tokens
    // with `#` comments, then one whitespace byte and the pixels.
    let mut pos = 0;
    let mut tokens = Vec::new();
    while tokens.len() < 4 {
        while bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if bytes[pos] == b'#' {
            while bytes[pos] != b'\n' {
                pos += 1;
            }
            continue;
        }
        let start = pos;
        while !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        tokens.push(String::from_utf8(bytes[start..pos].to_vec()).expect("ascii"));
    }
    assert_eq!((tokens[0].as_str(), tokens[3].as_str()), ("P5", "255"));
    let (width, height): (usize, usize) = (tokens[1].parse().expect("width"), tokens[2].parse().expect("height"));
    let pixels = &bytes[pos + 1..];
    assert_eq!(pixels.len(), width * height);
    let cells = pixels
        .iter()
        .map(|&v| {
            let p = (255.0 - f64::from(v)) / 255.0;
            if p > occupied_thresh {
                "occupied"
            } else if p < free_thresh {
                "free"
            } else {
                "unknown"
            }
        })
        .collect();
    LoadedMap { resolution: number("resolution"), origin: [origin[0], origin[1], origin[2]], width, height, cells }
}

/// The states `edtmap query` answers at the centre of every cell of
/// `loaded` at height `z`, in the image's order (row 0 at the top).
fn queried_states(dir: &Path, map: &Path, loaded: &LoadedMap, z: f64) -> Vec<String> {
    let mut csv = String::from("x,y,z\n");
    for row in 0..loaded.height {
        for col in 0..loaded.width {
            let x = loaded.origin[0] + (col as f64 + 0.5) * loaded.resolution;
            let y = loaded.origin[1] + ((loaded.height - 1 - row) as f64 + 0.5) * loaded.resolution;
            csv.push_str(&format!("{x},{y},{z}\n"));
        }
    }
    let points = dir.join("cells.csv");
    std::fs::write(&points, csv).expect("points");
    let (ok, out, err) = edtmap(&["query", s(map), "--points", s(&points)]);
    assert!(ok, "{err}");
    out.lines().skip(1).map(|l| l.split(',').nth(7).expect("state").replace("outside", "unknown")).collect()
}

#[test]
fn map_server_map_of_a_planar_map_matches_its_voxels() {
    let dir = tempfile::tempdir().expect("tempdir");
    let map = saved_map(dir.path(), "planar");
    let yaml = dir.path().join("floor.yaml");
    let (ok, out, err) = edtmap(&["export", s(&map), s(&yaml)]);
    assert!(ok, "{out}\n{err}");
    let loaded = load_map_server(&yaml);
    let (ok, info, _) = edtmap(&["info", s(&map)]);
    assert!(ok);
    let mapped = numbers_after(&info, "mapped box (m): ");
    assert_eq!(loaded.resolution, 0.1);
    assert_eq!(loaded.origin, [mapped[0], mapped[1], 0.0]);
    assert_eq!(
        (loaded.width, loaded.height),
        (((mapped[3] - mapped[0]) / 0.1).round() as usize, ((mapped[4] - mapped[1]) / 0.1).round() as usize)
    );

    // The planar scene's scan plane: the one observed layer.
    let frontiers = dir.path().join("f.csv");
    assert!(edtmap(&["info", s(&map), "--frontiers", s(&frontiers)]).0);
    let z: f64 = std::fs::read_to_string(&frontiers)
        .expect("csv")
        .lines()
        .nth(1)
        .expect("a frontier")
        .rsplit(',')
        .next()
        .expect("z")
        .parse()
        .expect("z");
    let truth = queried_states(dir.path(), &map, &loaded, z);
    let mismatches = loaded.cells.iter().zip(&truth).filter(|(a, b)| **a != b.as_str()).count();
    assert_eq!(mismatches, 0, "every cell reads as the voxel at its centre");
    let count = |state: &str| loaded.cells.iter().filter(|c| **c == state).count();
    let counts = numbers_after(&info, "voxels: ");
    assert_eq!(
        (count("free"), count("occupied")),
        (counts[0] as usize, counts[1] as usize),
        "the map holds every observed voxel"
    );

    // Orientation: an occupied voxel, found by query, is black at its
    // row (counted from the top, the largest y) and column.
    let first = truth.iter().position(|t| t == "occupied").expect("an obstacle");
    let (row, col) = (first / loaded.width, first % loaded.width);
    let bytes = std::fs::read(dir.path().join("floor.pgm")).expect("pgm");
    assert_eq!(bytes[bytes.len() - loaded.width * loaded.height + row * loaded.width + col], 0);
}

#[test]
fn map_server_map_of_a_3d_map_is_a_layer_at_the_height_asked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let map = saved_map(dir.path(), "uav_pillars");
    let yaml = dir.path().join("layer.yaml");
    let (ok, _, err) = edtmap(&["export", s(&map), s(&yaml)]);
    assert!(!ok && err.contains("--height") && !yaml.exists(), "a 3D map needs --height: {err}");
    let (ok, out, err) = edtmap(&["export", s(&map), s(&yaml), "--height", "1.1"]);
    assert!(ok, "{out}\n{err}");
    let loaded = load_map_server(&yaml);
    let truth = queried_states(dir.path(), &map, &loaded, 1.1);
    assert!(truth.iter().any(|t| t == "occupied") && truth.iter().any(|t| t == "free"));
    let mismatches = loaded.cells.iter().zip(&truth).filter(|(a, b)| **a != b.as_str()).count();
    assert_eq!(mismatches, 0);
    let (ok, _, err) = edtmap(&["export", s(&map), s(&yaml), "--states", s(&dir.path().join("st.npy"))]);
    assert!(!ok && err.contains("--states"), "{err}");
}

/// The RGB pixels of a PNG, with its size.
fn png_pixels(path: &Path) -> (u32, u32, Vec<[u8; 3]>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    ));
    let mut reader = decoder.read_info().expect("png header");
    let mut buf = vec![0; reader.output_buffer_size().expect("size")];
    let info = reader.next_frame(&mut buf).expect("png data");
    assert_eq!(info.color_type, png::ColorType::Rgb);
    (info.width, info.height, buf[..info.buffer_size()].chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

const TOP_VIEWS: [&str; 4] =
    ["map_top_occupancy.png", "map_top_distance.png", "map_top_projection.png", "map_top_clearance.png"];

#[test]
fn run_and_picture_draw_top_views_of_the_whole_map() {
    let dir = tempfile::tempdir().expect("tempdir");
    for scene in ["planar", "uav_pillars"] {
        let map = saved_map(dir.path(), scene);
        for name in TOP_VIEWS {
            let (w, h, _) = png_pixels(&dir.path().join(format!("{scene}-run")).join(name));
            assert!(w > 100 && h > 100, "{scene}: {name} is {w} x {h}");
        }
        let out = dir.path().join(format!("{scene}-pictures"));
        let (ok, stdout, err) = edtmap(&["picture", s(&map), "--out", s(&out)]);
        assert!(ok, "{stdout}\n{err}");
        assert_eq!(stdout.lines().count(), 4, "{stdout}");
        // The map has unknown, free and occupied voxels; the occupancy view
        // shows each in its colour (grey, off-white, near black).
        let (_, _, pixels) = png_pixels(&out.join(TOP_VIEWS[0]));
        for colour in [[150, 150, 150], [245, 245, 235], [20, 20, 20]] {
            assert!(pixels.iter().filter(|p| **p == colour).count() > 100, "{scene}: {colour:?}");
        }
    }
    let map = dir.path().join("planar.edtmap");
    let (ok, _, err) = edtmap(&["picture", s(&map), "--out", s(dir.path()), "--band", "2,1"]);
    assert!(!ok && err.contains("--band"), "{err}");
    let (ok, _, err) = edtmap(&["picture", s(&map), "--out", s(dir.path()), "--height", "nan"]);
    assert!(!ok && err.contains("height"), "{err}");
}
