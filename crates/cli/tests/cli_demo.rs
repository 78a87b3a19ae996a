//! `edtmap demo` end to end on a small scene.

use std::process::Command;

#[test]
fn demo_writes_a_png_slice_and_reports_timing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("pictures");
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(["demo", "--dims", "48", "40", "24", "--voxel-size-m", "0.2", "--out"])
        .arg(&out)
        .output()
        .expect("edtmap runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("batch EDT") && stdout.contains("median"), "{stdout}");
    let png = std::fs::read(out.join("edt_slice.png")).expect("picture written");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
}

#[test]
fn demo_refuses_a_bad_voxel_size() {
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(["demo", "--voxel-size-m=-1"])
        .output()
        .expect("edtmap runs");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--voxel-size-m"));
}

#[test]
fn demo_refuses_an_empty_axis() {
    let o = Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(["demo", "--dims", "8", "0", "8"])
        .output()
        .expect("edtmap runs");
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("length 0") && !stderr.contains("panicked"), "{stderr}");
}
