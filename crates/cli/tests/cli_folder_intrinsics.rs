//! A 3DMatch-layout folder from another camera: its
//! `camera-intrinsics.txt` and its images' size give the camera, over the
//! shipped config's 640 × 480 `[sensor]`, with a warning naming both;
//! `[dataset] intrinsics = "config"` makes `[sensor]` win. The mapped wall
//! is where the intrinsics put it, worked out by hand.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

const WIDTH: u32 = 120;
const HEIGHT: u32 = 68;
/// Depth of every pixel, millimetres.
const DEPTH_MM: u16 = 2000;
/// `T_world_camera`: the optical axis (z) along world x, image right (x)
/// along world -y, image down (y) along world -z, 1 m up.
const POSE: &str = "0 0 1 0\n-1 0 0 0\n0 -1 0 1\n0 0 0 1\n";

fn write_depth_png(path: &Path) {
    let file = std::fs::File::create(path).expect("create png");
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), WIDTH, HEIGHT);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().expect("png header");
    let bytes: Vec<u8> = (0..WIDTH * HEIGHT).flat_map(|_| DEPTH_MM.to_be_bytes()).collect();
    writer.write_image_data(&bytes).expect("png data");
}

/// A 3DMatch folder of three frames whose `camera-intrinsics.txt` says
/// focal length `f`, principal point at the image centre.
fn folder(dir: &Path, f: f64) {
    std::fs::create_dir_all(dir).expect("dir");
    let (cx, cy) = (f64::from(WIDTH) / 2.0, f64::from(HEIGHT) / 2.0);
    std::fs::write(dir.join("camera-intrinsics.txt"), format!("{f} 0 {cx}\n0 {f} {cy}\n0 0 1\n")).expect("intrinsics");
    for k in 0..3 {
        write_depth_png(&dir.join(format!("frame-{k:06}.depth.png")));
        std::fs::write(dir.join(format!("frame-{k:06}.pose.txt")), POSE).expect("pose");
    }
}

fn run(config: &Path, data: &Path, out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(["run", "--config"])
        .arg(config)
        .arg("--dataset")
        .arg(data)
        .arg("--out")
        .arg(out)
        .arg("--ply")
        .arg("--save")
        .arg(out.join("map.edtmap"))
        .output()
        .expect("edtmap runs")
}

/// Every frame integrated, none skipped.
fn assert_all_frames(out: &Path, o: &Output, what: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{what}: {err}");
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).expect("report")).expect("json");
    assert_eq!(r["frames"].as_array().map(Vec::len), Some(3), "{what}: {err}");
    assert!(r["skipped"].as_array().is_some_and(Vec::is_empty), "{what}: {}", r["skipped"]);
}

/// The occupied voxel centres' extent: x range, largest |y|, z range.
fn wall_extent(out: &Path) -> ([f32; 2], f32, [f32; 2]) {
    let cloud = edtmap_io::ply::read_ply(&out.join("occupied.ply")).expect("occupied.ply");
    assert!(cloud.points.len() > 100, "{} occupied voxels", cloud.points.len());
    let mut x = [f32::MAX, f32::MIN];
    let mut z = [f32::MAX, f32::MIN];
    let mut y = 0.0f32;
    for p in &cloud.points {
        x = [x[0].min(p[0]), x[1].max(p[0])];
        z = [z[0].min(p[2]), z[1].max(p[2])];
        y = y.max(p[1].abs());
    }
    (x, y, z)
}

/// The wall the camera sees at 2 m with focal length `f`: half its width
/// is `(WIDTH / 2) / f · 2 m`, half its height `(HEIGHT / 2) / f · 2 m`
/// about the camera's 1 m; the voxels are 0.05 m.
fn assert_wall(out: &Path, f: f32, what: &str) {
    let (x, y, z) = wall_extent(out);
    let depth = f32::from(DEPTH_MM) / 1000.0;
    let half_w = (WIDTH as f32 / 2.0) / f * depth;
    let half_h = (HEIGHT as f32 / 2.0) / f * depth;
    let tol = 0.08;
    assert!(x[0] > depth - tol && x[1] < depth + tol, "{what}: wall x in {x:?}, want {depth}");
    assert!((y - half_w).abs() < tol, "{what}: wall half width {y}, want {half_w}");
    assert!(
        (z[0] - (1.0 - half_h)).abs() < tol && (z[1] - (1.0 + half_h)).abs() < tol,
        "{what}: wall z in {z:?}, want 1 ± {half_h}"
    );
}

#[test]
fn a_folders_own_intrinsics_and_image_size_map_it_over_the_configs() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let shipped = root().join("configs/3dmatch.toml");
    // The folder's camera: f = 100 px. The shipped config says 640 × 480, f = 570.342.
    let right = tmp.path().join("right");
    folder(&right, 100.0);
    let out_right = tmp.path().join("out-right");
    let o = run(&shipped, &right, &out_right);
    assert_all_frames(&out_right, &o, "the folder's intrinsics");
    let err = String::from_utf8_lossy(&o.stderr);
    for want in [
        "camera-intrinsics.txt",
        "120 x 68",
        "640 x 480",
        "570.342",
        "using the recording's",
        "intrinsics = \"config\"",
    ] {
        assert!(err.contains(want), "{want:?} not in the warning: {err}");
    }
    assert_wall(&out_right, 100.0, "f = 100");

    // The same images with an intrinsics file that is wrong (f = 200):
    // another map, the wall half as wide.
    let wrong = tmp.path().join("wrong");
    folder(&wrong, 200.0);
    let out_wrong = tmp.path().join("out-wrong");
    let o = run(&shipped, &wrong, &out_wrong);
    assert_all_frames(&out_wrong, &o, "a wrong intrinsics file");
    assert_wall(&out_wrong, 200.0, "f = 200");
    let map = |out: &Path| std::fs::read(out.join("map.edtmap")).expect("map");
    assert_ne!(map(&out_right), map(&out_wrong), "the intrinsics file must change the map");

    // [dataset] intrinsics = "config": [sensor] wins over the folder's file.
    let text = std::fs::read_to_string(&shipped).expect("config");
    let mut text = text.replace("fx = 570.342", "fx = 200.0").replace("fy = 570.342", "fy = 200.0");
    text = text
        .replace("cx = 320.0", "cx = 60.0")
        .replace("cy = 240.0", "cy = 34.0")
        .replace("width = 640", "width = 120")
        .replace("height = 480", "height = 68");
    let text = text.replace("[dataset]\n", "[dataset]\nintrinsics = \"config\"\n");
    assert!(
        text.contains("fx = 200.0") && text.contains("height = 68") && text.contains("intrinsics = \"config\""),
        "{text}"
    );
    let config = tmp.path().join("config.toml");
    std::fs::write(&config, text).expect("config");
    let out_config = tmp.path().join("out-config");
    let o = run(&config, &right, &out_config);
    assert_all_frames(&out_config, &o, "intrinsics = \"config\"");
    assert_eq!(map(&out_config), map(&out_wrong), "[sensor]'s f = 200 over the folder's f = 100");
}
