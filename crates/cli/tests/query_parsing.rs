//! `edtmap query`'s points file is read strictly: a line that is
//! not three finite numbers is an error naming the file, the line, the
//! field and the value, never a silently dropped "header" or a zero; and
//! `edtmap export` writes a JSON sidecar locating the array in the world.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

fn edtmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_edtmap")).args(args).output().expect("edtmap runs")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// One saved map for every test, with its voxel size and cutoff as `info`
/// prints them.
struct Saved {
    _dir: tempfile::TempDir,
    map: PathBuf,
    voxel_size_m: f64,
    cutoff_m: f64,
}

fn saved() -> &'static Saved {
    static SAVED: OnceLock<Saved> = OnceLock::new();
    SAVED.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        let map = dir.path().join("map.edtmap");
        let o = edtmap(&[
            "run",
            "--scene",
            "planar",
            "--frames",
            "4",
            "--out",
            s(&dir.path().join("out")),
            "--save",
            s(&map),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let info = String::from_utf8(edtmap(&["info", s(&map)]).stdout).expect("utf-8");
        // "PATH: voxel 0.1 m, cutoff 2 m, ..."
        let number_after = |key: &str| -> f64 {
            let rest = &info[info.find(key).unwrap_or_else(|| panic!("{key} in {info}")) + key.len()..];
            rest.split_whitespace().next().and_then(|t| t.parse().ok()).unwrap_or_else(|| panic!("{key} in {info}"))
        };
        let (voxel_size_m, cutoff_m) = (number_after("voxel "), number_after("cutoff "));
        Saved { _dir: dir, map, voxel_size_m, cutoff_m }
    })
}

/// Runs `query` on a points file holding `bytes`.
fn query(bytes: &[u8], signed: bool) -> Output {
    let dir = tempfile::tempdir().expect("tempdir");
    let points = dir.path().join("points.csv");
    std::fs::write(&points, bytes).expect("write");
    let map = s(&saved().map);
    let mut args = vec!["query", map, "--points", s(&points)];
    if signed {
        args.push("--signed");
    }
    edtmap(&args)
}

/// Asserts a clean refusal: exit 1 (not a panic's 101), nothing on stdout,
/// one line on stderr naming the file and holding every one of `wanted`.
fn assert_refused(o: &Output, wanted: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(o.stdout.is_empty(), "{}", String::from_utf8_lossy(&o.stdout));
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains("points.csv"), "names the file: {err}");
    for w in wanted {
        assert!(err.contains(w), "{w:?} in {err}");
    }
}

#[test]
fn a_first_line_that_does_not_parse_is_an_error_not_a_header() {
    assert_refused(&query(b"0;0;0\n", false), &["line 1:", "\"0;0;0\"", "1 comma-separated field"]);
    assert_refused(&query(b"0x10,0,0\n", false), &["line 1:", "x = \"0x10\" is not a number"]);
    assert_refused(&query(b"0,0,0 # comment\n", false), &["line 1:", "z = \"0 # comment\" is not a number"]);
    // A header that is not exactly the column names.
    assert_refused(&query(b"x,y,z,w\n1,2,3\n", false), &["line 1:", "4 comma-separated fields"]);
    assert_refused(&query(b"lat,lon,alt\n1,2,3\n", false), &["line 1:", "x = \"lat\" is not a number"]);
    // Whitespace-separated numbers are one field.
    assert_refused(&query(b"1 2 3\n", false), &["line 1:", "\"1 2 3\" has 1 comma-separated field"]);
}

#[test]
fn empty_fields_and_wrong_counts_are_errors_not_zeros() {
    assert_refused(&query(b"0,,0\n", false), &["line 1: y = \"\" is not a number"]);
    assert_refused(&query(b"0,,0,0\n", false), &["line 1:", "4 comma-separated fields"]);
    assert_refused(&query(b",1,2\n", false), &["line 1: x = \"\" is not a number"]);
    assert_refused(&query(b"1,2,\n", false), &["line 1: z = \"\" is not a number"]);
    assert_refused(&query(b"1,2\n", true), &["line 1:", "2 comma-separated fields"]);
}

#[test]
fn non_finite_and_out_of_range_coordinates_are_refused_with_the_limit() {
    assert_refused(&query(b"NaN,0,0\n", false), &["line 1: x = \"NaN\" is not a finite number"]);
    assert_refused(&query(b"0,inf,0\n", true), &["line 1: y = \"inf\" is not a finite number"]);
    assert_refused(&query(b"0,0,-infinity\n", false), &["line 1: z = \"-infinity\" is not a finite number"]);
    assert_refused(&query(b"1e400,0,0\n", false), &["line 1: x = \"1e400\" is not a finite number"]);
    // Voxel indices must stay within 2^30 (inside i32 with room for the
    // query's neighbours): the limit in metres at the map's voxel size.
    let limit = format!("{:.0}", f64::from(1u32 << 30) * saved().voxel_size_m);
    let o = query(b"x,y,z\n1,2,3\n0,-1.07e12,0\n", false);
    assert_refused(&o, &["line 3: y = \"-1.07e12\" is beyond", &limit, "voxel_size_m"]);
}

#[test]
fn errors_name_the_line_after_headers_comments_and_blank_lines() {
    assert_refused(&query(b"x,y,z\n# c\n\n1,2,3\n4,5\n", false), &["line 5:"]);
    // A header only counts as the first line with content.
    assert_refused(&query(b"1,2,3\nx,y,z\n", false), &["line 2: x = \"x\" is not a number"]);
    assert_refused(&query(b"\xef\xbb\xbf1,2,3\n4,5,\xff\n", false), &["UTF-8"]);
}

#[test]
fn a_good_file_with_bom_header_comments_and_blank_lines_gives_every_row() {
    let text = "\u{feff} X , y,Z \r\n# a comment\n\n  1.5, -2,3e-1 \n#0,0,0\n\t\n-1.25e0,+0.5,.5\r\n0,0,0\n";
    let o = query(text.as_bytes(), false);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = String::from_utf8(o.stdout).expect("utf-8");
    let rows: Vec<Vec<f64>> =
        csv.lines().skip(1).map(|l| l.split(',').take(3).map(|f| f.parse().expect("number")).collect()).collect();
    assert_eq!(rows, [vec![1.5, -2.0, 0.3], vec![-1.25, 0.5, 0.5], vec![0.0, 0.0, 0.0]], "{csv}");
    // A BOM before a data line: the line is read, not dropped.
    let o = query("\u{feff}1,2,3\n".as_bytes(), false);
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 2);
}

#[test]
fn a_point_outside_the_mapped_area_reads_the_cutoff_saturated() {
    let saved = saved();
    for signed in [false, true] {
        let o = query(b"1e5,-1e5,3e4\n", signed);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let csv = String::from_utf8(o.stdout).expect("utf-8");
        let row: Vec<&str> = csv.lines().nth(1).expect("a row").split(',').collect();
        let distance: f64 = row[3].parse().expect("distance");
        assert!((distance - saved.cutoff_m).abs() < 1e-6, "{csv}");
        assert_eq!((row[7], row[8], row[9]), ("outside", "false", "true"), "{csv}");
    }
}

#[test]
fn unreadable_points_files_are_refused_by_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    let map = s(&saved().map);
    let o = edtmap(&["query", map, "--points", s(dir.path())]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("directory"));
    if Path::new("/dev/zero").exists() {
        let o = edtmap(&["query", map, "--points", "/dev/zero"]);
        assert_eq!(o.status.code(), Some(1));
        assert!(String::from_utf8_lossy(&o.stderr).contains("/dev/zero"));
    }
}

#[test]
fn export_sidecar_locates_the_array_in_the_world() {
    let saved = saved();
    let vs = saved.voxel_size_m;
    let dir = tempfile::tempdir().expect("tempdir");
    let npy = dir.path().join("box.npy");
    let states = dir.path().join("states.npy");
    let (lo, hi) = ([-1.23, -0.77, 0.85], [0.41, 0.3, 1.52]);
    let spec = format!("{},{},{},{},{},{}", lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
    let o = edtmap(&["export", s(&saved.map), "--box", &spec, s(&npy), "--states", s(&states)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(dir.path().join("box.npy.json")).expect("the sidecar box.npy.json");
    let json: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let num = |v: &serde_json::Value| v.as_f64().expect("a number");
    // Independently: the box's first voxel is floor(min / vs), its last the
    // one holding the point just below max; element [0,0,0] is centred half
    // a voxel above the first voxel's corner.
    let first = lo.map(|m| (m / vs).floor());
    let last = hi.map(|m| (m / vs).ceil() - 1.0);
    for a in 0..3 {
        let origin = num(&json["origin_m"][a]);
        assert!((origin - (first[a] + 0.5) * vs).abs() < 1e-9, "axis {a}: {origin} in {text}");
        assert!((num(&json["origin_corner_m"][a]) - first[a] * vs).abs() < 1e-9, "{text}");
        // The origin is a voxel centre inside the box's first voxel.
        assert!(origin - vs / 2.0 <= lo[a] + 1e-9 && lo[a] < origin + vs / 2.0, "{text}");
    }
    let shape: Vec<u64> = (0..3).rev().map(|a| (last[a] - first[a] + 1.0) as u64).collect();
    let json_shape: Vec<u64> =
        json["shape"].as_array().expect("shape").iter().map(|v| v.as_u64().expect("n")).collect();
    assert_eq!(json_shape, shape, "(nz, ny, nx): {text}");
    assert!(
        (num(&json["voxel_size_m"]) - vs).abs() < 1e-12
            && (num(&json["max_distance_m"]) - saved.cutoff_m).abs() < 1e-12
    );
    assert_eq!(
        (json["dtype"].as_str(), json["states_dtype"].as_str(), json["signed"].as_bool()),
        (Some("float32"), Some("uint8"), Some(false))
    );
    assert_eq!(json["axis_order"], serde_json::json!(["z", "y", "x"]));
    assert_eq!((json["distances"].as_str(), json["states"].as_str()), (Some("box.npy"), Some("states.npy")));
    // The array itself has that shape.
    let bytes = std::fs::read(&npy).expect("npy");
    let array = npyz::NpyFile::new(&bytes[..]).expect("npy header");
    assert_eq!(array.shape(), &shape[..]);
    // The sidecar named as another output is refused before anything is written.
    let other = dir.path().join("other.npy");
    let o = edtmap(&[
        "export",
        s(&saved.map),
        "--box",
        &spec,
        s(&other),
        "--states",
        s(&dir.path().join("other.npy.json")),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!other.exists());
}
