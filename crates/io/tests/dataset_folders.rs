//! Recording folders of every supported layout, built in temporary
//! folders: TUM RGB-D depth folders, 3DMatch folders posed by a
//! trajectory, and point-cloud folders posed by a trajectory, by KITTI
//! poses or by a matrix beside each cloud.

use edtmap_core::sensor::{DepthData, Measurement, RangeLimits};
use edtmap_io::dataset::{Dataset, DatasetOptions};
use edtmap_io::IoError;
use nalgebra::{Isometry3, Vector3};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// TUM depth units: 5000 per metre.
const TUM_SCALE_M: f32 = 0.0002;
const RANGE: RangeLimits = RangeLimits { min_m: 0.1, max_m: 10.0 };

/// The analytic trajectory: straight line at (1, 0.5, 0.1) m/s while
/// turning about z at 0.2 rad/s, from `T0`. Linear interpolation and slerp
/// reproduce it exactly between samples.
const T0: f64 = 1305031100.0;
fn truth(t: f64) -> Isometry3<f64> {
    let s = t - T0;
    Isometry3::new(Vector3::new(s, 0.5 * s, 0.1 * s), Vector3::new(0.0, 0.0, 0.2 * s))
}

/// A TUM trajectory file of `truth` sampled at 100 Hz over `[T0, T0 + 2]`.
fn tum_trajectory() -> String {
    let mut text = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for k in 0..=200 {
        let t = T0 + f64::from(k) * 0.01;
        let p = truth(t);
        let (v, q) = (p.translation.vector, p.rotation);
        writeln!(text, "{t:.6} {} {} {} {} {} {} {}", v.x, v.y, v.z, q.i, q.j, q.k, q.w).expect("format");
    }
    text
}

fn write_depth_png(path: &Path, width: u32, height: u32, values: &[u16]) {
    let file = std::fs::File::create(path).expect("create png");
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().expect("png header");
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    writer.write_image_data(&bytes).expect("png data");
}

fn assert_pose_near(got: &Isometry3<f64>, want: &Isometry3<f64>, what: &str) {
    let d = got.inverse() * want;
    assert!(d.translation.vector.norm() < 1e-6 && d.rotation.angle() < 1e-6, "{what}: {got:?} vs {want:?}");
}

fn options(intrinsics: Option<[f64; 4]>, trajectory: Option<PathBuf>) -> DatasetOptions {
    DatasetOptions { intrinsics, trajectory, ..DatasetOptions::new(TUM_SCALE_M, RANGE) }
}

/// A TUM folder: `depth/<t>.png` images 4 × 3, listed in `depth.txt`
/// (unless `list` is false), with a `groundtruth.txt`. Returns the times.
fn tum_folder(dir: &Path, times: &[f64], list: bool) {
    std::fs::create_dir_all(dir.join("depth")).expect("depth/");
    let mut depth_txt = String::from("# depth maps\n# timestamp filename\n");
    for (k, t) in times.iter().enumerate() {
        let name = format!("depth/{t:.6}.png");
        let v = 5000 + 100 * k as u16;
        write_depth_png(&dir.join(&name), 4, 3, &[v, 0, v, v, v, v, v, v, v, v, v, 1]);
        writeln!(depth_txt, "{t:.6} {name}").expect("format");
    }
    if list {
        std::fs::write(dir.join("depth.txt"), depth_txt).expect("depth.txt");
    }
    std::fs::write(dir.join("groundtruth.txt"), tum_trajectory()).expect("groundtruth.txt");
}

#[test]
fn tum_depth_folder_poses_are_interpolated_at_the_image_times() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let times = [T0 + 0.123, T0 + 0.5175, T0 + 1.25, T0 + 3.0];
    tum_folder(tmp.path(), &times, true);
    let set = Dataset::open_with(tmp.path(), &options(Some([525.0, 525.0, 319.5, 239.5]), None)).expect("opens");
    assert_eq!((set.kind(), set.len()), ("depth camera", 4));
    let Dataset::Depth(folder) = &set else { panic!("a depth folder") };
    assert_eq!((folder.camera.fx, folder.camera.cy, folder.camera.width, folder.camera.height), (525.0, 239.5, 4, 3));
    for (i, &t) in times[..3].iter().enumerate() {
        let frame = set.frame(i).expect("frame");
        assert!((frame.stamp_s - t).abs() < 1e-6, "stamp {} for {t}", frame.stamp_s);
        assert_pose_near(&frame.t_world_sensor, &truth(t), &format!("frame {i}"));
        let Measurement::Depth(image) = &frame.measurement else { panic!("depth") };
        let DepthData::U16 { values, metres_per_unit } = &image.data else { panic!("u16") };
        assert_eq!((values[0], values[1], *metres_per_unit), (5000 + 100 * i as u16, 0, TUM_SCALE_M));
        assert!((image.depth_m(0) - (1.0 + 0.02 * i as f32)).abs() < 1e-6);
    }
    // The last image is after the trajectory: it opens, and its frame says why it has no pose.
    let err = set.frame(3).expect_err("outside the trajectory");
    assert!(matches!(err, IoError::NoPose { .. }), "{err:?}");
    let msg = err.to_string();
    for want in [
        "1305031103.000000.png",
        "1305031103.000000 s",
        "groundtruth.txt",
        "1305031100.000000 s to 1305031102.000000 s",
    ] {
        assert!(msg.contains(want), "{want} not in {msg}");
    }
}

#[test]
fn tum_depth_folder_without_a_list_with_a_given_trajectory() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("rgbd");
    tum_folder(&dir, &[T0 + 1.5, T0 + 0.25], false);
    std::fs::remove_file(dir.join("groundtruth.txt")).expect("rm");
    // No trajectory anywhere.
    let err =
        Dataset::open_with(&dir, &options(Some([500.0, 500.0, 2.0, 1.5]), None)).expect_err("no poses").to_string();
    assert!(err.contains("groundtruth.txt"), "{err}");
    let traj = tmp.path().join("odometry.txt");
    std::fs::write(&traj, tum_trajectory()).expect("write");
    // No intrinsics anywhere.
    let err = Dataset::open_with(&dir, &options(None, Some(traj.clone()))).expect_err("no intrinsics").to_string();
    assert!(err.contains("[sensor] fx, fy, cx, cy"), "{err}");
    let set = Dataset::open_with(&dir, &options(Some([500.0, 500.0, 2.0, 1.5]), Some(traj))).expect("opens");
    // depth/ is read in time order.
    let stamps: Vec<f64> = set.frames().iter().map(|f| f.stamp_s).collect();
    assert_eq!(stamps, vec![T0 + 0.25, T0 + 1.5]);
    assert_pose_near(&set.frame(1).expect("frame").t_world_sensor, &truth(T0 + 1.5), "frame 1");
}

#[test]
fn a_gap_in_the_trajectory_is_not_interpolated_across() {
    let tmp = tempfile::tempdir().expect("temp dir");
    tum_folder(tmp.path(), &[T0 + 0.5, T0 + 1.005], true);
    let gappy: String = tum_trajectory()
        .lines()
        .filter(|l| !l.starts_with("1305031100.") || l.starts_with("1305031100.0"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(tmp.path().join("groundtruth.txt"), gappy).expect("write");
    let mut opts = options(Some([500.0, 500.0, 2.0, 1.5]), None);
    let set = Dataset::open_with(tmp.path(), &opts).expect("opens");
    assert!(set.frame(1).is_ok());
    let err = set.frame(0).expect_err("in the gap").to_string();
    assert!(err.contains("gap") && err.contains("1305031100.500000.png"), "{err}");
    opts.max_pose_gap_s = 1.0;
    let set = Dataset::open_with(tmp.path(), &opts).expect("opens");
    assert!(set.frame(0).is_ok());
}

#[test]
fn threedmatch_folder_posed_by_a_trajectory_at_30_hz() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path();
    std::fs::write(dir.join("camera-intrinsics.txt"), "500 0 2\n0 500 1.5\n0 0 1\n").expect("write");
    for n in [0, 3, 45] {
        write_depth_png(&dir.join(format!("frame-{n:06}.depth.png")), 4, 3, &[1000; 12]);
    }
    // Without a trajectory every frame needs its pose file.
    let err = Dataset::open(dir, 0.001, RANGE).expect_err("no pose files").to_string();
    assert!(err.contains("frame-000000.pose.txt"), "{err}");
    let traj = dir.join("traj.txt");
    let shifted: String = tum_trajectory()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let (t, rest) = l.split_once(' ').expect("stamp");
            format!("{} {rest}\n", t.parse::<f64>().expect("t") - T0)
        })
        .collect();
    std::fs::write(&traj, shifted).expect("write");
    let opts = DatasetOptions { trajectory: Some(traj), ..DatasetOptions::new(0.001, RANGE) };
    let set = Dataset::open_with(dir, &opts).expect("opens");
    let stamps: Vec<f64> = set.frames().iter().map(|f| f.stamp_s).collect();
    assert_eq!(stamps, vec![0.0, 0.1, 1.5]);
    for (i, t) in stamps.into_iter().enumerate() {
        assert_pose_near(&set.frame(i).expect("frame").t_world_sensor, &truth(T0 + t), "3DMatch frame");
    }
}

/// A KITTI `.bin` scan of `points`.
fn bin_scan(points: &[[f32; 3]]) -> Vec<u8> {
    points.iter().flat_map(|p| p.iter().chain([&0.5]).flat_map(|v| v.to_le_bytes())).collect()
}

fn points_of(set: &Dataset, i: usize) -> Vec<[f32; 3]> {
    let Measurement::Points(cloud) = set.frame(i).expect("frame").measurement else { panic!("points") };
    cloud.points
}

#[test]
fn clouds_with_times_and_a_tum_trajectory() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("velodyne");
    std::fs::create_dir(&dir).expect("mkdir");
    for k in 0..3 {
        std::fs::write(dir.join(format!("{k:06}.bin")), bin_scan(&[[k as f32, 1.0, 2.0]])).expect("write");
    }
    let traj = tmp.path().join("traj.txt");
    std::fs::write(&traj, tum_trajectory()).expect("write");
    let opts = DatasetOptions { trajectory: Some(traj.clone()), ..DatasetOptions::new(0.001, RANGE) };
    // KITTI names are frame numbers, not times: times.txt is needed.
    let err = Dataset::open_with(&dir, &opts).expect_err("no times").to_string();
    assert!(err.contains("times.txt"), "{err}");
    let times = [T0 + 0.05, T0 + 0.1501, T0 + 1.99];
    std::fs::write(dir.join("times.txt"), times.iter().map(|t| format!("{t:.6}\n")).collect::<String>())
        .expect("write");
    let set = Dataset::open_with(&dir, &opts).expect("opens");
    assert_eq!((set.kind(), set.len()), ("point cloud", 3));
    for (i, &t) in times.iter().enumerate() {
        let frame = set.frame(i).expect("frame");
        assert!((frame.stamp_s - t).abs() < 1e-6);
        assert_pose_near(&frame.t_world_sensor, &truth(t), "scan");
    }
    assert_eq!(points_of(&set, 2), vec![[2.0, 1.0, 2.0]]);
    // A wrong number of times names times.txt.
    std::fs::write(dir.join("times.txt"), "0\n0.1\n").expect("write");
    let err = Dataset::open_with(&dir, &opts).expect_err("2 times").to_string();
    assert!(err.contains("times.txt") && err.contains("2 times for 3 point clouds"), "{err}");
}

#[test]
fn clouds_named_by_their_time_take_the_trajectory_pose() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path();
    for t in [T0 + 1.25, T0 + 0.75] {
        std::fs::write(
            dir.join(format!("{t:.6}.pcd")),
            "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2 3\n",
        )
        .expect("write");
    }
    let traj = dir.join("groundtruth.tum");
    std::fs::write(&traj, tum_trajectory()).expect("write");
    let set = Dataset::open_with(dir, &DatasetOptions { trajectory: Some(traj), ..DatasetOptions::new(0.001, RANGE) })
        .expect("opens");
    let stamps: Vec<f64> = set.frames().iter().map(|f| f.stamp_s).collect();
    assert_eq!(stamps, vec![T0 + 0.75, T0 + 1.25]);
    assert_pose_near(&set.frame(0).expect("frame").t_world_sensor, &truth(T0 + 0.75), "named cloud");
    assert_eq!(points_of(&set, 1), vec![[1.0, 2.0, 3.0]]);
}

#[test]
fn clouds_with_a_pose_file_each() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path();
    let pcd = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA ascii\n1 0 0\n0 1 0\n";
    std::fs::write(dir.join("a.pcd"), pcd).expect("write");
    std::fs::write(dir.join("b.pcd"), pcd).expect("write");
    // No cloud has a pose: the folder is refused.
    let err = Dataset::open(dir, 0.001, RANGE).expect_err("no poses").to_string();
    assert!(err.contains("a.pcd") && err.contains("a.pose.txt"), "{err}");
    // Only b has none: b alone fails, naming its pose file.
    std::fs::write(dir.join("a.pose.txt"), "1 0 0 1\n0 1 0 2\n0 0 1 3\n0 0 0 1\n").expect("write");
    let set = Dataset::open(dir, 0.001, RANGE).expect("opens");
    let err = set.frame(1).expect_err("b has no pose").to_string();
    assert!(err.contains("b.pcd") && err.contains("b.pose.txt"), "{err}");
    std::fs::write(dir.join("b.pose.txt"), "0 -1 0 0\n1 0 0 0\n0 0 1 x\n0 0 0 1\n").expect("write");
    let set = Dataset::open(dir, 0.001, RANGE).expect("opens");
    assert_eq!(set.frames().iter().map(|f| f.stamp_s).collect::<Vec<_>>(), vec![0.0, 0.1]);
    let first = set.frame(0).expect("frame 0");
    assert_eq!(first.t_world_sensor.translation.vector.as_slice(), &[1.0, 2.0, 3.0]);
    let err = set.frame(1).expect_err("bad matrix").to_string();
    assert!(err.contains("b.pose.txt") && err.contains("line 3") && err.contains("\"x\""), "{err}");
}

#[test]
fn ply_clouds_with_kitti_poses_and_times() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path();
    let ply = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n";
    std::fs::write(dir.join("000000.ply"), ply).expect("write");
    std::fs::write(dir.join("000001.ply"), ply).expect("write");
    std::fs::write(dir.join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 7 0 1 0 0 0 0 1 0\n").expect("write");
    let set = Dataset::open(dir, 0.001, RANGE).expect("opens");
    assert_eq!(set.frames().iter().map(|f| f.stamp_s).collect::<Vec<_>>(), vec![0.0, 0.1]);
    std::fs::write(dir.join("times.txt"), "10.5\n10.6\n").expect("write");
    let set = Dataset::open(dir, 0.001, RANGE).expect("opens");
    let second = set.frame(1).expect("frame 1");
    assert_eq!((second.stamp_s, second.t_world_sensor.translation.x), (10.6, 7.0));
    assert_eq!(points_of(&set, 0), vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    std::fs::write(dir.join("times.txt"), "10.5\nlater\n").expect("write");
    let err = Dataset::open(dir, 0.001, RANGE).expect_err("bad time").to_string();
    assert!(err.contains("times.txt: line 2") && err.contains("\"later\""), "{err}");
}

#[test]
fn folders_of_nothing_known_are_refused() {
    let tmp = tempfile::tempdir().expect("temp dir");
    std::fs::write(tmp.path().join("notes.txt"), "hello").expect("write");
    let err = Dataset::open(tmp.path(), 0.001, RANGE).expect_err("nothing").to_string();
    assert!(err.contains("neither a depth folder"), "{err}");
    let err = Dataset::open(&tmp.path().join("notes.txt"), 0.001, RANGE).expect_err("a file").to_string();
    assert!(err.contains("not a folder"), "{err}");
}
