//! The skip rule of folder recordings, at the reader: opening fails only
//! for the recording as a whole; a frame's own problems (its image or
//! cloud unreadable, its pose file missing) fail that frame alone, for
//! every kind of folder; files named like frames but not frames are left
//! out with a warning. And the folder's `camera-intrinsics.txt` with the
//! first image's size gives a 3DMatch folder its camera.

use edtmap_core::sensor::{Measurement, RangeLimits};
use edtmap_io::dataset::{Dataset, DatasetOptions};
use edtmap_io::IoError;
use std::path::Path;

const RANGE: RangeLimits = RangeLimits { min_m: 0.1, max_m: 10.0 };
const IDENTITY: &str = "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";

fn write_depth_png(path: &Path, width: u32, height: u32, value: u16) {
    let file = std::fs::File::create(path).expect("create png");
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().expect("png header");
    let bytes: Vec<u8> = (0..width * height).flat_map(|_| value.to_be_bytes()).collect();
    writer.write_image_data(&bytes).expect("png data");
}

/// A 3DMatch folder of `n` frames of `width` × `height`, each with its
/// pose file, and a `camera-intrinsics.txt`.
fn threedmatch(dir: &Path, n: u32, width: u32, height: u32) {
    std::fs::write(dir.join("camera-intrinsics.txt"), "100 0 60\n0 100 34\n0 0 1\n").expect("intrinsics");
    for k in 0..n {
        write_depth_png(&dir.join(format!("frame-{k:06}.depth.png")), width, height, 2000);
        std::fs::write(dir.join(format!("frame-{k:06}.pose.txt")), IDENTITY).expect("pose");
    }
}

fn depth(set: &Dataset) -> &edtmap_io::dataset::DepthFolder {
    let Dataset::Depth(folder) = set else { panic!("a depth folder") };
    folder
}

#[test]
fn the_folders_intrinsics_and_first_image_give_the_camera() {
    let tmp = tempfile::tempdir().expect("temp dir");
    threedmatch(tmp.path(), 2, 120, 68);
    // The options' intrinsics are another camera's: the folder's file wins.
    let opts =
        DatasetOptions { intrinsics: Some([570.342, 570.342, 320.0, 240.0]), ..DatasetOptions::new(0.001, RANGE) };
    let set = Dataset::open_with(tmp.path(), &opts).expect("opens");
    let c = &depth(&set).camera;
    assert_eq!((c.fx, c.fy, c.cx, c.cy, c.width, c.height), (100.0, 100.0, 60.0, 34.0, 120, 68));
    assert_eq!(depth(&set).intrinsics_file.as_deref(), Some(tmp.path().join("camera-intrinsics.txt").as_path()));
    let Measurement::Depth(image) = set.frame(1).expect("frame 1").measurement else { panic!("depth") };
    assert_eq!((image.width, image.height), (120, 68));
    // Told not to read the folder's file, the options give the intrinsics.
    let set =
        Dataset::open_with(tmp.path(), &DatasetOptions { folder_intrinsics: false, ..opts.clone() }).expect("opens");
    let c = &depth(&set).camera;
    assert_eq!((c.fx, c.cx, c.cy, c.width, c.height), (570.342, 320.0, 240.0, 120, 68));
    assert_eq!(depth(&set).intrinsics_file, None);
    // A bad intrinsics file is the recording's problem: refused at open, naming it.
    std::fs::write(tmp.path().join("camera-intrinsics.txt"), "100 0 60\n0 100 34\n").expect("write");
    let err = Dataset::open_with(tmp.path(), &opts).expect_err("6 numbers").to_string();
    assert!(err.contains("camera-intrinsics.txt") && err.contains("found 6"), "{err}");
}

#[test]
fn a_3dmatch_frames_own_problems_fail_that_frame_alone() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path();
    threedmatch(dir, 4, 120, 68);
    // Frame 0's image is not a PNG, frame 2 has no pose file, and a stray
    // image is named like a frame.
    std::fs::write(dir.join("frame-000000.depth.png"), b"\x89PNG\r\n\x1a\n garbage").expect("write");
    std::fs::remove_file(dir.join("frame-000002.pose.txt")).expect("rm");
    write_depth_png(&dir.join("frame-abc.depth.png"), 120, 68, 1000);
    std::fs::write(dir.join("frame-abc.pose.txt"), IDENTITY).expect("pose");
    let set = Dataset::open(dir, 0.001, RANGE).expect("opens");
    assert_eq!(set.len(), 4, "{:?}", set.frames());
    assert_eq!(set.frames().iter().map(|f| f.stamp_s * 30.0).collect::<Vec<_>>(), vec![0.0, 1.0, 2.0, 3.0]);
    let warnings = set.warnings().join("\n");
    assert!(
        set.warnings().len() == 1
            && warnings.contains("frame-abc.depth.png")
            && warnings.contains("frame-XXXXXX.depth.png"),
        "{warnings}"
    );
    // The size comes from the first image whose header reads.
    assert_eq!((depth(&set).camera.width, depth(&set).camera.height), (120, 68));
    let err = set.frame(0).expect_err("corrupt").to_string();
    assert!(err.contains("frame-000000.depth.png") && err.contains("PNG"), "{err}");
    assert!(set.frame(1).is_ok());
    let err = set.frame(2).expect_err("no pose file");
    assert!(matches!(err, IoError::NoPose { .. }), "{err:?}");
    let err = err.to_string();
    assert!(err.contains("frame-000002.depth.png") && err.contains("frame-000002.pose.txt is missing"), "{err}");
    assert!(set.frame(3).is_ok());
}

#[test]
fn a_3dmatch_folder_refused_as_a_whole_says_why() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path();
    threedmatch(dir, 2, 8, 6);
    // No frame has a pose: that is the recording's problem.
    for k in 0..2 {
        std::fs::remove_file(dir.join(format!("frame-{k:06}.pose.txt"))).expect("rm");
    }
    let err = Dataset::open(dir, 0.001, RANGE).expect_err("no poses").to_string();
    assert!(
        err.contains("no poses") && err.contains("frame-000000.pose.txt") && err.contains("[dataset] trajectory"),
        "{err}"
    );
    // No image can be read at all: nothing gives the camera's size.
    for k in 0..2 {
        std::fs::write(dir.join(format!("frame-{k:06}.pose.txt")), IDENTITY).expect("pose");
        std::fs::write(dir.join(format!("frame-{k:06}.depth.png")), b"not a png").expect("write");
    }
    let err = Dataset::open(dir, 0.001, RANGE).expect_err("no readable image").to_string();
    assert!(err.contains("none of the 2 depth images can be read") && err.contains("frame-000000.depth.png"), "{err}");
    // Only stray names: no frames, and the message lists what was left out.
    let tmp = tempfile::tempdir().expect("temp dir");
    std::fs::write(tmp.path().join("camera-intrinsics.txt"), "100 0 60\n0 100 34\n0 0 1\n").expect("intrinsics");
    write_depth_png(&tmp.path().join("depth-1.depth.png"), 8, 6, 1000);
    let err = Dataset::open(tmp.path(), 0.001, RANGE).expect_err("no frames").to_string();
    assert!(err.contains("no depth images named frame-XXXXXX.depth.png") && err.contains("depth-1.depth.png"), "{err}");
}

#[test]
fn a_tum_image_named_otherwise_is_left_out_and_a_corrupt_one_fails_alone() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path();
    std::fs::create_dir(dir.join("depth")).expect("depth/");
    std::fs::write(dir.join("depth/10.000000.png"), b"garbage").expect("write");
    write_depth_png(&dir.join("depth/10.100000.png"), 4, 3, 5000);
    write_depth_png(&dir.join("depth/notes.png"), 4, 3, 5000);
    std::fs::write(dir.join("groundtruth.txt"), "9.95 0 0 0 0 0 0 1\n10.05 0 0 0 0 0 0 1\n10.15 0 0 0 0 0 0 1\n")
        .expect("gt");
    let opts = DatasetOptions { intrinsics: Some([500.0, 500.0, 2.0, 1.5]), ..DatasetOptions::new(0.0002, RANGE) };
    let set = Dataset::open_with(dir, &opts).expect("opens");
    assert_eq!(set.frames().iter().map(|f| f.stamp_s).collect::<Vec<_>>(), vec![10.0, 10.1]);
    assert!(set.warnings().len() == 1 && set.warnings()[0].contains("notes.png"), "{:?}", set.warnings());
    let err = set.frame(0).expect_err("corrupt").to_string();
    assert!(err.contains("10.000000.png"), "{err}");
    assert!(set.frame(1).is_ok());
    // The config's intrinsics for TUM: no file in the folder.
    assert_eq!((depth(&set).camera.fx, depth(&set).intrinsics_file.clone()), (500.0, None));
    // A depth.txt that lists a missing image: that frame alone fails, naming it.
    std::fs::write(dir.join("depth.txt"), "10.0 depth/10.000000.png\n10.05 depth/gone.png\n10.1 depth/10.100000.png\n")
        .expect("depth.txt");
    let set = Dataset::open_with(dir, &opts).expect("opens");
    assert_eq!(set.len(), 3);
    let err = set.frame(1).expect_err("missing").to_string();
    assert!(err.contains("gone.png"), "{err}");
    assert!(set.frame(2).is_ok());
}

const PCD: &str =
    "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n";
const PLY: &str = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";

#[test]
fn a_corrupt_first_cloud_or_a_missing_pose_file_fails_that_frame_alone_for_every_cloud_kind() {
    let bin: Vec<u8> = [1.0f32, 2.0, 3.0, 0.5].iter().flat_map(|v| v.to_le_bytes()).collect();
    for (ext, good) in [("pcd", PCD.as_bytes().to_vec()), ("ply", PLY.as_bytes().to_vec()), ("bin", bin)] {
        let tmp = tempfile::tempdir().expect("temp dir");
        let dir = tmp.path();
        std::fs::write(dir.join(format!("000000.{ext}")), b"garbage!garbage!garbage").expect("write");
        for k in 1..3 {
            std::fs::write(dir.join(format!("00000{k}.{ext}")), &good).expect("write");
        }
        // Posed by a file each; 000002's is missing.
        for k in 0..2 {
            std::fs::write(dir.join(format!("00000{k}.pose.txt")), IDENTITY).expect("pose");
        }
        let set = Dataset::open(dir, 0.001, RANGE).unwrap_or_else(|e| panic!("{ext}: opens: {e}"));
        assert_eq!(set.len(), 3, "{ext}");
        let err = set.frame(0).expect_err("corrupt").to_string();
        assert!(err.contains(&format!("000000.{ext}")), "{ext}: {err}");
        let Measurement::Points(cloud) = set.frame(1).unwrap_or_else(|e| panic!("{ext}: frame 1: {e}")).measurement
        else {
            panic!("points")
        };
        assert_eq!(cloud.points, vec![[1.0, 2.0, 3.0]], "{ext}");
        let err = set.frame(2).expect_err("no pose file");
        assert!(matches!(err, IoError::NoPose { .. }), "{ext}: {err:?}");
        assert!(err.to_string().contains("000002.pose.txt is missing"), "{ext}: {err}");
    }
}
