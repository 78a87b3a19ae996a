//! `edtmap edt` end to end: npy round trips for every accepted dtype,
//! checked against a brute-force oracle, and one test per kind of bad input.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use npyz::{AutoSerialize, Order, WriterBuilder};

fn edtmap(args: &[&Path]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_edtmap")).arg("edt").args(args).output().expect("edtmap runs")
}

fn write_npy<T: AutoSerialize + Clone>(path: &Path, shape: &[u64], order: Order, data: &[T]) {
    let file = fs::File::create(path).expect("create npy");
    let mut w = npyz::WriteOptions::<T>::new()
        .default_dtype()
        .shape(shape)
        .order(order)
        .writer(std::io::BufWriter::new(file))
        .begin_nd()
        .expect("npy header");
    w.extend(data.iter().cloned()).expect("npy data");
    w.finish().expect("npy finish");
}

fn read_npy<T: npyz::Deserialize>(path: &Path) -> (Vec<u64>, Order, Vec<T>) {
    let bytes = fs::read(path).expect("read npy");
    let npy = npyz::NpyFile::new(&bytes[..]).expect("valid npy");
    let (shape, order) = (npy.shape().to_vec(), npy.order());
    (shape, order, npy.into_vec().expect("npy data"))
}

/// A small deterministic pattern of obstacles (about 1 in 7 voxels).
fn pattern(n: usize) -> Vec<bool> {
    (0..n).map(|i| (i * 2_654_435_761usize) % 7 == 3).collect()
}

/// C-order multi-index of linear index `i` in `shape`.
fn unravel(mut i: usize, shape: &[usize]) -> Vec<usize> {
    let mut idx = vec![0; shape.len()];
    for k in (0..shape.len()).rev() {
        idx[k] = i % shape[k];
        i /= shape[k];
    }
    idx
}

fn dist_sq(a: &[usize], b: &[usize]) -> usize {
    a.iter().zip(b).map(|(&p, &q)| p.abs_diff(q).pow(2)).sum()
}

/// Checks OUT and IDX (C order) against exhaustive search.
fn check_against_oracle(shape: &[usize], obstacles: &[bool], out: &Path, idx: &Path) {
    let (dshape, _, dist) = read_npy::<f32>(out);
    let (ishape, _, nearest) = read_npy::<i32>(idx);
    let shape64: Vec<u64> = shape.iter().map(|&n| n as u64).collect();
    assert_eq!(dshape, shape64);
    assert_eq!(ishape, [shape64.clone(), vec![shape.len() as u64]].concat());
    let sites: Vec<Vec<usize>> = (0..obstacles.len()).filter(|&i| obstacles[i]).map(|i| unravel(i, shape)).collect();
    for i in 0..obstacles.len() {
        let p = unravel(i, shape);
        let best = sites.iter().map(|s| dist_sq(&p, s)).min();
        let got_site: Vec<usize> =
            nearest[i * shape.len()..(i + 1) * shape.len()].iter().map(|&v| v as usize).collect();
        match best {
            Some(d2) => {
                assert_eq!(dist[i], (d2 as f64).sqrt() as f32, "distance at {p:?}");
                assert!(sites.contains(&got_site), "nearest of {p:?} is not an obstacle");
                assert_eq!(dist_sq(&p, &got_site), d2, "nearest of {p:?} is not the closest");
            }
            None => {
                assert_eq!(dist[i], f32::INFINITY);
                assert!(got_site.iter().all(|&v| v == usize::MAX || v as i32 == -1));
            }
        }
    }
}

struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new() -> Self {
        Case { dir: tempfile::tempdir().expect("tempdir") }
    }
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
}

fn round_trip<T: AutoSerialize + Clone>(shape: &[usize], to_value: impl Fn(bool, usize) -> T) {
    let case = Case::new();
    let (input, out, idx) = (case.path("in.npy"), case.path("out.npy"), case.path("idx.npy"));
    let n: usize = shape.iter().product();
    let obstacles = pattern(n);
    let data: Vec<T> = obstacles.iter().enumerate().map(|(i, &o)| to_value(o, i)).collect();
    let shape64: Vec<u64> = shape.iter().map(|&n| n as u64).collect();
    write_npy(&input, &shape64, Order::C, &data);
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .arg("edt")
        .args([&input, &out])
        .arg("--nearest")
        .arg(&idx)
        .output()
        .expect("edtmap runs");
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    check_against_oracle(shape, &obstacles, &out, &idx);
}

#[test]
fn round_trip_every_dtype_3d() {
    let shape = [5, 6, 7];
    // Obstacles take varied nonzero values, including ones whose low byte is 0.
    round_trip::<bool>(&shape, |o, _| o);
    round_trip::<u8>(&shape, |o, i| if o { 1 + (i % 255) as u8 } else { 0 });
    round_trip::<i8>(&shape, |o, _| if o { -1 } else { 0 });
    round_trip::<u16>(&shape, |o, _| if o { 256 } else { 0 });
    round_trip::<i16>(&shape, |o, _| if o { -32768 } else { 0 });
    round_trip::<u32>(&shape, |o, _| if o { 1 << 24 } else { 0 });
    round_trip::<i32>(&shape, |o, _| if o { 7 } else { 0 });
    round_trip::<u64>(&shape, |o, _| if o { 1 << 40 } else { 0 });
    round_trip::<i64>(&shape, |o, _| if o { -3 } else { 0 });
}

#[test]
fn round_trip_2d_and_thin_shapes() {
    round_trip::<u8>(&[9, 13], |o, _| o as u8);
    round_trip::<u8>(&[1, 17], |o, _| o as u8);
    round_trip::<u8>(&[11, 1, 3], |o, _| o as u8);
}

#[test]
fn big_endian_integers_are_read() {
    let case = Case::new();
    let (input, out, idx) = (case.path("in.npy"), case.path("out.npy"), case.path("idx.npy"));
    let obstacles = pattern(4 * 5 * 6);
    // '>i4' written by hand: header then big-endian data.
    let values: Vec<u8> = obstacles.iter().flat_map(|&o| (if o { 0x0100_0000i32 } else { 0 }).to_be_bytes()).collect();
    write_raw_npy(&input, "'>i4'", "(4, 5, 6)", false, &values);
    let o = edtmap(&[&input, &out, Path::new("--nearest"), &idx]);
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    check_against_oracle(&[4, 5, 6], &obstacles, &out, &idx);
}

#[test]
fn fortran_order_is_supported_and_kept() {
    let case = Case::new();
    let (input, out, idx) = (case.path("in.npy"), case.path("out.npy"), case.path("idx.npy"));
    let shape = [4usize, 6, 5];
    // The same obstacles as a C-order grid, stored in Fortran order.
    let obstacles = pattern(shape.iter().product());
    let c_index = |a: usize, b: usize, c: usize| (a * shape[1] + b) * shape[2] + c;
    let mut fortran = Vec::new();
    for c in 0..shape[2] {
        for b in 0..shape[1] {
            for a in 0..shape[0] {
                fortran.push(obstacles[c_index(a, b, c)] as u8);
            }
        }
    }
    write_npy(&input, &[4, 6, 5], Order::Fortran, &fortran);
    let o = edtmap(&[&input, &out, Path::new("--nearest"), &idx]);
    assert!(o.status.success(), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let (_, order, dist_f) = read_npy::<f32>(&out);
    let (_, iorder, idx_f) = read_npy::<i32>(&idx);
    assert_eq!((order, iorder), (Order::Fortran, Order::Fortran));
    // Re-express both in C order and compare with the oracle.
    let case_c = Case::new();
    let (out_c, idx_c) = (case_c.path("out.npy"), case_c.path("idx.npy"));
    let n = obstacles.len();
    let mut dist_c = vec![0f32; n];
    let mut idx_cv = vec![0i32; n * 3];
    let mut f = 0;
    for c in 0..shape[2] {
        for b in 0..shape[1] {
            for a in 0..shape[0] {
                let i = c_index(a, b, c);
                dist_c[i] = dist_f[f];
                for k in 0..3 {
                    idx_cv[i * 3 + k] = idx_f[k * n + f];
                }
                f += 1;
            }
        }
    }
    write_npy(&out_c, &[4, 6, 5], Order::C, &dist_c);
    write_npy(&idx_c, &[4, 6, 5, 3], Order::C, &idx_cv);
    check_against_oracle(&shape, &obstacles, &out_c, &idx_c);
}

#[test]
fn grid_without_obstacles_gives_inf_and_minus_one() {
    let case = Case::new();
    let (input, out, idx) = (case.path("in.npy"), case.path("out.npy"), case.path("idx.npy"));
    write_npy(&input, &[3, 4], Order::C, &[0u8; 12]);
    let o = edtmap(&[&input, &out, Path::new("--nearest"), &idx]);
    assert!(o.status.success());
    assert!(read_npy::<f32>(&out).2.iter().all(|d| *d == f32::INFINITY));
    assert!(read_npy::<i32>(&idx).2.iter().all(|&i| i == -1));
}

#[test]
fn repeat_prints_one_json_line() {
    let case = Case::new();
    let (input, out) = (case.path("in.npy"), case.path("out.npy"));
    write_npy(&input, &[8, 8, 8], Order::C, &pattern(512).iter().map(|&o| o as u8).collect::<Vec<_>>());
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(["edt".as_ref(), input.as_os_str(), out.as_os_str(), "--repeat".as_ref(), "3".as_ref()])
        .output()
        .expect("edtmap runs");
    assert!(o.status.success());
    let stdout = String::from_utf8(o.stdout).expect("utf-8");
    assert_eq!(stdout.lines().count(), 1, "{stdout}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).expect("JSON");
    assert_eq!(v["runs"], 3);
    assert_eq!(v["voxels"], 512);
    let (min, median) = (v["min_ms"].as_f64().expect("min"), v["median_ms"].as_f64().expect("median"));
    assert!(min >= 0.0 && median >= min);
}

/// Writes an npy version 1.0 file by hand.
fn write_raw_npy(path: &Path, descr: &str, shape: &str, fortran: bool, data: &[u8]) {
    let dict = format!(
        "{{'descr': {descr}, 'fortran_order': {}, 'shape': {shape}, }}",
        if fortran { "True" } else { "False" }
    );
    let mut header = dict.into_bytes();
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(b' ');
    }
    header.push(b'\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header);
    bytes.extend(data);
    fs::write(path, bytes).expect("write npy");
}

/// Runs `edt` on `input` and returns its one-line error message.
fn expect_error(input: &Path) -> String {
    let out = input.with_file_name("out.npy");
    let o = edtmap(&[input, &out]);
    let stderr = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(!o.status.success(), "should fail: {stderr}");
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "one line: {stderr}");
    assert!(stderr.contains(&input.display().to_string()), "names the file: {stderr}");
    assert!(!out.exists(), "no output written on error");
    stderr
}

#[test]
fn missing_file_is_reported() {
    let case = Case::new();
    let err = expect_error(&case.path("nope.npy"));
    assert!(err.contains("No such file"), "{err}");
}

#[test]
fn non_npy_file_is_reported() {
    let case = Case::new();
    let input = case.path("text.npy");
    fs::write(&input, "x,y,z\n1,2,3\n").expect("write");
    assert!(expect_error(&input).contains("not an npy file"));
}

#[test]
fn truncated_data_is_reported() {
    let case = Case::new();
    let input = case.path("cut.npy");
    write_raw_npy(&input, "'|u1'", "(4, 4, 4)", false, &[1u8; 40]);
    let err = expect_error(&input);
    assert!(err.contains("truncated") && err.contains("64") && err.contains("40"), "{err}");
}

#[test]
fn float_and_other_dtypes_are_refused() {
    let case = Case::new();
    for (k, descr) in ["'<f4'", "'<f8'", "'<c8'", "'|S3'", "'<U2'"].into_iter().enumerate() {
        let input = case.path(&format!("bad{k}.npy"));
        write_raw_npy(&input, descr, "(2, 2)", false, &[0u8; 64]);
        let err = expect_error(&input);
        assert!(err.contains("unsupported dtype"), "{descr}: {err}");
    }
}

#[test]
fn wrong_number_of_axes_is_refused() {
    let case = Case::new();
    for (k, shape) in ["(5,)", "(2, 2, 2, 2)", "()"].into_iter().enumerate() {
        let input = case.path(&format!("ndim{k}.npy"));
        write_raw_npy(&input, "'|u1'", shape, false, &[0u8; 16]);
        let err = expect_error(&input);
        assert!(err.contains("expected 2 or 3"), "{shape}: {err}");
    }
}

#[test]
fn empty_axis_is_refused() {
    let case = Case::new();
    let input = case.path("empty.npy");
    write_raw_npy(&input, "'|u1'", "(3, 0, 2)", false, &[]);
    assert!(expect_error(&input).contains("axis 1 has length 0"));
}

/// A `|u1` npy file of `shape` whose data is a sparse hole of `data_bytes`,
/// so that the header's size check passes without using disk.
fn sparse_npy(case: &Case, name: &str, shape: &str, data_bytes: u64) -> PathBuf {
    let input = case.path(name);
    write_raw_npy(&input, "'|u1'", shape, false, &[]);
    let f = fs::OpenOptions::new().write(true).open(&input).expect("open");
    f.set_len(128 + data_bytes).expect("sparse file");
    input
}

#[test]
fn grid_beyond_index_limits_is_refused() {
    let case = Case::new();
    let input = sparse_npy(&case, "huge.npy", "(3000, 3000, 3000)", 27_000_000_000);
    assert!(expect_error(&input).contains("too large"));
}

#[test]
fn grid_beyond_memory_is_refused() {
    let case = Case::new();
    // 4.1 G voxels need about 53 GiB of working memory.
    let input = sparse_npy(&case, "big.npy", "(1600, 1600, 1600)", 4_096_000_000);
    let err = expect_error(&input);
    assert!(err.contains("GiB") && err.contains("--max-memory"), "{err}");
}
