//! The TOML configuration: shipped files parse, bad values name their field.

use edtmap::config::Config;
use edtmap::sensor::Sensor;
use std::path::PathBuf;

fn configs_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs")
}

fn shipped() -> String {
    std::fs::read_to_string(configs_dir().join("uav_pillars.toml")).expect("configs/uav_pillars.toml")
}

#[test]
fn every_shipped_config_parses() {
    let mut n = 0;
    for entry in std::fs::read_dir(configs_dir()).expect("configs/") {
        let path = entry.expect("entry").path();
        let config = Config::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let (sensor, params) = config.mapper_params().expect("valid");
        assert!(params.voxel_size_m > 0.0);
        let stem = path.file_stem().and_then(|s| s.to_str()).expect("utf-8 name");
        // Configs for recordings (`--dataset`) name no scene.
        if let Some(scene) = config.scene {
            assert_eq!(stem, scene.name.as_str());
            n += 1;
        } else {
            assert!(matches!(stem, "3dmatch" | "velodyne" | "tum" | "ros_lidar" | "ros_depth"), "{stem}.toml names no scene");
        }
        if stem == "room" || stem == "3dmatch" {
            assert!(matches!(sensor, Sensor::Depth(_)));
        }
    }
    assert!(n >= 4, "expected a config per built-in scene");
}

fn error_of(text: &str) -> String {
    Config::parse(text, "test.toml").expect_err("invalid config").to_string()
}

#[test]
fn bad_values_name_the_field() {
    let base = shipped();
    let cases = [
        ("prob_hit = 0.7", "prob_hit = 1.5", "prob_hit"),
        ("voxel_size_m = 0.2", "voxel_size_m = -0.2", "voxel_size_m"),
        ("azimuth_bins = 900", "azimuth_bins = 0", "azimuth_bins"),
        ("max_range_m = 20.0", "max_range_m = 0.1", "range"),
        ("local_size_m = [10.0, 10.0, 3.0]", "local_size_m = [10.0, 0.0, 3.0]", "size_m"),
        ("kind = \"lidar\"", "kind = \"sonar\"", "sonar"),
        ("rings = 32", "ringz = 32", "ringz"),
        ("prob_miss = 0.4", "prob_mis = 0.4", "prob_mis"),
        ("construction = \"auto\"", "construction = \"sideways\"", "sideways"),
        ("voxel_size_m = 0.2", "voxel_size_m = \"small\"", "voxel_size_m"),
    ];
    for (from, to, expect) in cases {
        assert!(base.contains(from), "{from}");
        let msg = error_of(&base.replace(from, to));
        assert!(msg.contains(expect), "{to}: error does not name {expect}: {msg}");
        assert!(msg.contains("test.toml") || msg.contains('['), "{to}: {msg}");
    }
}

#[test]
fn depth_sensor_needs_intrinsics() {
    let text = shipped().replace("kind = \"lidar\"", "kind = \"depth\"");
    let msg = error_of(&text);
    assert!(msg.contains("[sensor]") && msg.contains("fx"), "{msg}");
}

#[test]
fn projection_of_plain_points_is_refused() {
    let text = shipped().replace("kind = \"lidar\"", "kind = \"points\"").replace("construction = \"auto\"", "construction = \"projection\"");
    assert!(error_of(&text).contains("construction"));
}

