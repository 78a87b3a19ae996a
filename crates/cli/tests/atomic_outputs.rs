//! Every output is written whole or not at all: a kill mid-write or a full
//! disk leaves the previous file as it was, and no partial file or stale
//! temporary behind.

mod common;

use common::{assert_refused, bin, run_in, SHORT};
use std::path::Path;
use std::time::Duration;

/// The files a run leaves in `dir`, hidden temporaries included.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("list")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn temporaries(dir: &Path) -> Vec<String> {
    names(dir).into_iter().filter(|n| n.ends_with(".tmp")).collect()
}

/// The outputs that must be whole: each is either the previous run's bytes
/// or a complete new file of its kind.
fn check_whole(out: &Path, before: &[(String, Vec<u8>)]) {
    for (name, old) in before {
        let now = std::fs::read(out.join(name)).unwrap_or_default();
        if &now == old {
            continue;
        }
        match name.rsplit('.').next() {
            Some("json") => {
                serde_json::from_slice::<serde_json::Value>(&now)
                    .unwrap_or_else(|e| panic!("{name} is not whole JSON: {e}"));
            }
            Some("png") => {
                assert!(now.starts_with(b"\x89PNG") && now.ends_with(b"IEND\xaeB`\x82"), "{name} is not a whole PNG")
            }
            Some("edtmap") => assert!(now.len() >= old.len() / 2 && now.starts_with(b"EDTMAP"), "{name} is cut"),
            _ => {}
        }
    }
}

#[test]
fn a_run_killed_at_any_moment_leaves_whole_outputs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let args = ["run", "--scene", "room", "--frames", "3", "--ply", "--out", "out", "--save", "out/map.edtmap"];
    let first = run_in(dir.path(), &args, SHORT);
    assert_eq!(first.code(), Some(0), "{}", first.stderr);
    let before: Vec<(String, Vec<u8>)> =
        names(&out).into_iter().map(|n| (n.clone(), std::fs::read(out.join(&n)).expect("read"))).collect();
    assert!(before.len() >= 6, "{before:?}");
    // Kill points spread over the run, the writing at its end included
    // (seeded: the same delays every time).
    let mut state = 0x2545_f491_u64;
    for _ in 0..12 {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let delay = Duration::from_millis(200 + (state >> 33) % 4000);
        let mut child = bin()
            .args(args)
            .current_dir(dir.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("start");
        std::thread::sleep(delay);
        let _ = child.kill();
        let _ = child.wait();
        check_whole(&out, &before);
    }
    // The next run removes the killed runs' temporaries.
    let last = run_in(dir.path(), &args, SHORT);
    assert_eq!(last.code(), Some(0), "{}", last.stderr);
    assert_eq!(temporaries(&out), Vec::<String>::new());
    check_whole(&out, &before);
}

/// A tmpfs of `kib` KiB mounted at a new folder, unmounted on drop;
/// `None` where mounting is not allowed (not root, no tmpfs).
struct Tmpfs(tempfile::TempDir);

impl Tmpfs {
    fn mount(kib: u32) -> Option<Tmpfs> {
        let dir = tempfile::tempdir().ok()?;
        let ok = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
            .arg(dir.path())
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        ok.then_some(Tmpfs(dir))
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(self.0.path()).status();
    }
}

#[test]
fn a_full_disk_keeps_the_previous_outputs() {
    let Some(fs) = Tmpfs::mount(1024) else {
        eprintln!("skipped: cannot mount a tmpfs here");
        return;
    };
    let dir = fs.0.path();
    let small = run_in(dir, &["run", "--scene", "planar", "--frames", "2", "--out", "out"], SHORT);
    assert_eq!(small.code(), Some(0), "{}", small.stderr);
    let report = std::fs::read(dir.join("out/report.json")).expect("report");
    // The room's map and PLY files do not fit in what is left.
    let big = run_in(
        dir,
        &["run", "--scene", "room", "--frames", "3", "--ply", "--out", "out", "--save", "map.edtmap"],
        SHORT,
    );
    assert_eq!(big.code(), Some(1), "{}", big.stderr);
    assert!(big.stderr.contains("No space left"), "{}", big.stderr);
    let now = std::fs::read(dir.join("out/report.json")).expect("report");
    serde_json::from_slice::<serde_json::Value>(&now).expect("the report is whole JSON");
    assert!(now == report || now.len() > 100);
    assert!(
        !dir.join("map.edtmap").exists()
            || std::fs::read(dir.join("map.edtmap")).is_ok_and(|b| b.starts_with(b"EDTMAP"))
    );
    assert_eq!(temporaries(dir), Vec::<String>::new());
    assert_eq!(temporaries(&dir.join("out")), Vec::<String>::new());
    // edt and export outputs: the same rule.
    let grid = dir.join("g.npy");
    let mut data = vec![0u8; 64 * 64 * 64];
    data[0] = 1;
    let npy = common::npy_u8("(64, 64, 64)", &data);
    if std::fs::write(&grid, &npy).is_ok() {
        let run = run_in(dir, &["edt", "g.npy", "dist.npy", "--nearest", "idx.npy"], SHORT);
        assert_refused(&run, &["No space left"]);
        assert!(
            !dir.join("idx.npy").exists() && !dir.join("dist.npy").exists()
                || std::fs::metadata(dir.join("dist.npy")).is_ok_and(|m| m.len() == 128 + 4 * 64 * 64 * 64)
        );
        assert_eq!(temporaries(dir), Vec::<String>::new());
    }
}
