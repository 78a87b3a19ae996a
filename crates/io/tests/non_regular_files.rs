//! Inputs that are not regular files: a FIFO named
//! like a frame, a cloud, a pose file or a recording, and devices such as
//! `/dev/zero`, are refused by every reader with an error saying what they
//! are, instead of blocking on the FIFO or reading the device forever.
//!
//! Each read runs on its own thread under a timeout, so that a regression
//! fails the test instead of hanging it.
#![cfg(unix)]

use edtmap_core::sensor::RangeLimits;
use edtmap_io::dataset::{read_kitti_bin, read_matrix_file, Dataset};
use edtmap_io::depth_folder::read_depth_png;
use edtmap_io::npy::ObstacleNpy;
use edtmap_io::ply::read_ply;
use edtmap_io::{read_map, read_pcd, IoError, Trajectory};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

const RANGE: RangeLimits = RangeLimits { min_m: 0.1, max_m: 10.0 };

/// Makes a FIFO at `path` with the system's `mkfifo`.
fn mkfifo(path: &Path) {
    let status = std::process::Command::new("mkfifo").arg(path).status().expect("run mkfifo");
    assert!(status.success(), "mkfifo {}", path.display());
}

/// The error `read` gives, which must come within 10 s: a reader that
/// blocks on a FIFO or reads a device forever fails here.
fn refusal<T: Send + 'static>(what: &str, read: impl FnOnce() -> Result<T, IoError> + Send + 'static) -> String {
    let (send, recv) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(read().err().map(|e| e.to_string()));
    });
    match recv.recv_timeout(Duration::from_secs(10)) {
        Ok(Some(err)) => err,
        Ok(None) => panic!("{what}: accepted"),
        Err(_) => panic!("{what}: still reading after 10 s (blocked on a FIFO or reading a device?)"),
    }
}

/// A 4 × 3 16-bit greyscale PNG.
fn depth_png(path: &Path) {
    let file = std::fs::File::create(path).expect("create png");
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), 4, 3);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    encoder.write_header().expect("header").write_image_data(&[0x13; 24]).expect("data");
}

const IDENTITY: &str = "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";

/// A 3DMatch folder of two frames, posed, with intrinsics.
fn threedmatch_folder(dir: &Path) {
    std::fs::write(dir.join("camera-intrinsics.txt"), "5 0 2\n0 5 1.5\n0 0 1\n").expect("intrinsics");
    for k in 0..2 {
        std::fs::write(dir.join(format!("frame-{k:06}.pose.txt")), IDENTITY).expect("pose");
    }
}

#[test]
fn a_fifo_frame_in_a_3dmatch_folder_fails_its_frame() {
    let tmp = tempfile::tempdir().expect("temp dir");
    threedmatch_folder(tmp.path());
    depth_png(&tmp.path().join("frame-000000.depth.png"));
    mkfifo(&tmp.path().join("frame-000001.depth.png"));
    let dir = tmp.path().to_path_buf();
    let err = refusal("frame 1", move || {
        let set = Dataset::open(&dir, 0.001, RANGE)?;
        set.frame(0)?;
        set.frame(1)
    });
    assert!(err.contains("frame-000001.depth.png") && err.contains("FIFO"), "{err}");
}

/// A FIFO as the first frame: refused, when the folder opens or with its
/// frame, but never read.
#[test]
fn a_fifo_first_frame_is_refused() {
    let tmp = tempfile::tempdir().expect("temp dir");
    threedmatch_folder(tmp.path());
    mkfifo(&tmp.path().join("frame-000000.depth.png"));
    depth_png(&tmp.path().join("frame-000001.depth.png"));
    let dir = tmp.path().to_path_buf();
    let err = refusal("frame 0", move || Dataset::open(&dir, 0.001, RANGE)?.frame(0));
    assert!(err.contains("frame-000000.depth.png") && err.contains("FIFO"), "{err}");
}

#[test]
fn fifo_side_files_of_a_depth_folder_are_refused() {
    for side in ["camera-intrinsics.txt", "frame-000000.pose.txt"] {
        let tmp = tempfile::tempdir().expect("temp dir");
        threedmatch_folder(tmp.path());
        depth_png(&tmp.path().join("frame-000000.depth.png"));
        depth_png(&tmp.path().join("frame-000001.depth.png"));
        std::fs::remove_file(tmp.path().join(side)).expect("remove");
        mkfifo(&tmp.path().join(side));
        let dir = tmp.path().to_path_buf();
        let err = refusal(side, move || Dataset::open(&dir, 0.001, RANGE)?.frame(0));
        assert!(err.contains(side) && err.contains("FIFO"), "{side}: {err}");
    }
}

#[test]
fn a_fifo_cloud_in_a_cloud_folder_fails_its_frame() {
    for ext in ["pcd", "ply", "bin"] {
        let tmp = tempfile::tempdir().expect("temp dir");
        let dir = tmp.path().to_path_buf();
        std::fs::write(dir.join(format!("a.{ext}")), b"not read").expect("write");
        mkfifo(&dir.join(format!("x.{ext}")));
        std::fs::write(dir.join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0\n").expect("poses");
        let err = refusal(ext, move || Dataset::open(&dir, 0.001, RANGE)?.frame(1));
        assert!(err.contains(&format!("x.{ext}")) && err.contains("FIFO"), "{ext}: {err}");
    }
}

#[test]
fn a_fifo_poses_or_times_file_is_refused() {
    for side in ["poses.txt", "times.txt"] {
        let tmp = tempfile::tempdir().expect("temp dir");
        let dir = tmp.path().to_path_buf();
        std::fs::write(dir.join("000000.bin"), [0u8; 16]).expect("write");
        mkfifo(&dir.join(side));
        let err = refusal(side, move || Dataset::open(&dir, 0.001, RANGE));
        assert!(err.contains(side) && err.contains("FIFO"), "{side}: {err}");
    }
}

/// Every file reader (the ROS ones are tested in `edtmap-ros`), on a FIFO of the kind's name and on `/dev/zero`.
#[test]
fn every_reader_refuses_fifos_and_devices() {
    type Reader = fn(&Path) -> Result<(), IoError>;
    let readers: [(&str, Reader); 8] = [
        ("x.depth.png", |p| read_depth_png(p, None).map(drop)),
        ("x.pcd", |p| read_pcd(p).map(drop)),
        ("x.ply", |p| read_ply(p).map(drop)),
        ("x.bin", |p| read_kitti_bin(p).map(drop)),
        ("x.npy", |p| ObstacleNpy::open(p).map(drop)),
        ("x.edtmap", |p| read_map(p).map(drop)),
        ("groundtruth.txt", |p| Trajectory::read_tum(p).map(drop)),
        ("x.pose.txt", |p| read_matrix_file(p).map(drop)),
    ];
    let tmp = tempfile::tempdir().expect("temp dir");
    for (name, read) in readers {
        let fifo = tmp.path().join(name);
        mkfifo(&fifo);
        let shown = fifo.display().to_string();
        let err = refusal(name, move || read(&fifo));
        assert!(err.contains(&shown) && err.contains("FIFO"), "{name}: {err}");
        let err = refusal(name, move || read(Path::new("/dev/zero")));
        assert!(err.contains("/dev/zero") && err.contains("character device"), "{name}: {err}");
        let dir: PathBuf = tmp.path().to_path_buf();
        let err = refusal(name, move || read(&dir));
        assert!(err.contains("directory"), "{name}: {err}");
    }
}
