//! The TOML configuration: shipped files parse, bad values name their field.

use edtmap::config::Config;
use edtmap::sensor::Sensor;
use edtmap_conformance::config_text::{assert_names_the_value, configs_dir, set, shipped as config_text};

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
        // The sensor names its kind as the file spells it (the Python
        // package and the command line report that name).
        let table = std::fs::read_to_string(&path).expect("config").parse::<toml::Table>().expect("toml");
        let first = match table.get("sensors") {
            Some(entries) => &entries[0],
            None => &table["sensor"],
        };
        assert_eq!(sensor.name(), first["kind"].as_str().expect("kind"), "{stem}");
        n += 1;
        if stem == "room" || stem == "3dmatch" {
            assert!(matches!(sensor, Sensor::Depth(_)));
        }
    }
    assert!(n >= 12, "expected the shipped configs, found {n}");
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
    let text = shipped()
        .replace("kind = \"lidar\"", "kind = \"points\"")
        .replace("construction = \"auto\"", "construction = \"projection\"");
    assert!(error_of(&text).contains("construction"));
}

/// The error and its sources joined as anyhow's `{:#}` prints them.
fn chain(e: &dyn std::error::Error) -> String {
    let mut out = e.to_string();
    let mut next = e.source();
    while let Some(s) = next {
        out = format!("{out}: {s}");
        next = s.source();
    }
    out
}

/// Every float field refuses NaN, infinities and physically meaningless
/// values, with one message naming the section, the field (once), the
/// value and the accepted range.
#[test]
fn out_of_range_numbers_name_section_field_value_and_range_once() {
    let cases: &[(&str, &str, &str, &str, &str)] = &[
        // (config, section, field, TOML value, value as printed)
        ("uav_pillars.toml", "sensor", "min_range_m", "-1.0", "-1.0"),
        ("uav_pillars.toml", "sensor", "max_range_m", "inf", "inf"),
        ("uav_pillars.toml", "sensor", "max_range_m", "1e9", "1000000000"),
        ("uav_pillars.toml", "sensor", "free_margin_m", "-0.1", "-0.1"),
        ("uav_pillars.toml", "sensor", "planar_half_thickness_m", "100.0", "100.0"),
        ("uav_pillars.toml", "sensor", "elevation_min_deg", "nan", "NaN"),
        ("uav_pillars.toml", "sensor", "elevation_max_deg", "95.0", "95.0"),
        ("uav_pillars.toml", "sensor", "ring_elevations_deg", "[0.0, nan]", "[0.0, NaN]"),
        ("uav_pillars.toml", "occupancy", "voxel_size_m", "0", "0.0"),
        ("uav_pillars.toml", "occupancy", "voxel_size_m", "nan", "NaN"),
        ("uav_pillars.toml", "occupancy", "voxel_size_m", "1e-30", "1e-30"),
        ("uav_pillars.toml", "occupancy", "local_size_m", "[10.0, nan, 3.0]", "[10.0, NaN, 3.0]"),
        ("uav_pillars.toml", "occupancy", "local_size_m", "[1e9, 10.0, 3.0]", "1000000000"),
        ("uav_pillars.toml", "occupancy", "fixed_height_m", "1e30", "1e30"),
        ("uav_pillars.toml", "occupancy", "prob_hit", "nan", "NaN"),
        ("uav_pillars.toml", "occupancy", "clamp_max", "1.0", "1"),
        ("uav_pillars.toml", "occupancy", "occupied_threshold", "inf", "inf"),
        ("uav_pillars.toml", "global", "max_distance_m", "nan", "NaN"),
        ("uav_pillars.toml", "global", "max_distance_m", "1e30", "1e30"),
        ("uav_pillars.toml", "global", "forbidden", "[{ min_m = [0.0, 0.0, 0.0], max_m = [1e30, 1.0, 1.0] }]", "1e30"),
        ("3dmatch.toml", "sensor", "fx", "1e-30", "1e-30"),
        ("3dmatch.toml", "sensor", "fx", "0.5", "0.5"),
        ("3dmatch.toml", "sensor", "fy", "1e9", "1000000000"),
        ("3dmatch.toml", "sensor", "cx", "1e30", "1e30"),
        ("3dmatch.toml", "sensor", "cx", "-1000.0", "-1000.0"),
        ("3dmatch.toml", "sensor", "cy", "nan", "NaN"),
    ];
    for &(file, section, field, value, shown) in cases {
        let text = set(&config_text(file), section, field, value);
        let err = Config::parse(&text, file).expect_err(&format!("{file}: [{section}] {field} = {value} accepted"));
        assert_names_the_value(&chain(&err), section, field, value, shown);
    }
}

#[test]
fn values_at_the_ends_of_their_ranges_are_accepted() {
    let cases = [
        ("3dmatch.toml", "sensor", "fx", "1.0"),
        ("3dmatch.toml", "sensor", "fy", "1e6"),
        ("3dmatch.toml", "sensor", "cx", "-640.0"),
        ("3dmatch.toml", "sensor", "cy", "960.0"),
    ];
    for (file, section, field, value) in cases {
        let text = set(&config_text(file), section, field, value);
        if let Err(e) = Config::parse(&text, file) {
            panic!("[{section}] {field} = {value} refused: {}", chain(&e));
        }
    }
}

/// Regression: the message of a wrapped config error was printed twice
/// (`invalid fx = missing: …: invalid fx = missing: …`).
#[test]
fn config_errors_print_their_cause_once() {
    let text = shipped().replace("kind = \"lidar\"", "kind = \"depth\"");
    let msg = chain(&Config::parse(&text, "test.toml").expect_err("no intrinsics"));
    assert_eq!(msg, "config [sensor] invalid fx = missing: required for kind = \"depth\"");
    let msg = chain(
        &Config::parse(&set(&shipped(), "occupancy", "voxel_size_m", "0"), "test.toml").expect_err("zero voxels"),
    );
    assert_eq!(msg.matches("voxel_size_m").count(), 1, "{msg}");
}

/// The applications' sections (`[scene]`, `[output]`, `[dataset]`, `[ros]`)
/// are theirs to read and check; the library accepts them unread and
/// refuses any other section by name.
#[test]
fn application_sections_are_left_to_the_applications() {
    let base = shipped();
    let apps = format!("{base}\n[dataset]\ndepth_scale_m = -1.0\n[ros]\nnamespace = \"x y\"\n");
    Config::parse(&apps, "test.toml").expect("the library reads none of the applications' fields");
    let msg = error_of(&format!("{base}\n[sceen]\nname = \"room\"\n"));
    assert!(msg.contains("sceen") && msg.contains("test.toml"), "{msg}");
}

/// A robot's LiDAR and a camera as `[[sensors]]` entries.
const TWO_SENSORS: &str = r#"
[[sensors]]
name = "lidar_top"
kind = "lidar"
min_range_m = 0.2
max_range_m = 20.0
rings = 16
elevation_min_deg = -15.0
elevation_max_deg = 15.0
azimuth_bins = 900

[[sensors]]
name = "front_camera"
kind = "depth"
min_range_m = 0.2
max_range_m = 5.0
fx = 100.0
fy = 100.0
cx = 79.5
cy = 59.5
width = 160
height = 120
sensor_in_body = [0.25, 0.0, -0.3, 0.0, 0.2164396, 0.0, 0.9762960]

[occupancy]
voxel_size_m = 0.1
"#;

#[test]
fn several_sensors_are_sensors_entries_each_named_and_mounted() {
    let config = Config::parse(TWO_SENSORS, "two.toml").expect("two sensors");
    assert_eq!(config.other_sensors.len(), 1);
    assert_eq!(config.sensor.name(), "lidar_top", "the first entry is the first sensor");
    let sensors = config.mapper_sensors().expect("valid sensors");
    let names: Vec<&str> = sensors.iter().map(|(s, _)| s.name.as_str()).collect();
    assert_eq!(names, ["lidar_top", "front_camera"]);
    assert!(matches!(sensors[1].0.sensor, Sensor::Depth(_)));
    assert_eq!(sensors[0].1, nalgebra::Isometry3::identity());
    // 25° about y: the camera's x axis turns down.
    let x = sensors[1].1 * nalgebra::Vector3::x();
    assert!((x.z + 25f64.to_radians().sin()).abs() < 1e-6, "{x:?}");
    assert!((sensors[1].1.translation.vector - nalgebra::Vector3::new(0.25, 0.0, -0.3)).norm() < 1e-12);
}

#[test]
fn sensor_entries_are_refused_by_name() {
    let both = format!("{}\n{}", shipped().split("[occupancy]").next().expect("text"), TWO_SENSORS);
    assert!(error_of(&both).contains("both [sensor] and [[sensors]]"), "{}", error_of(&both));
    let twice = TWO_SENSORS.replace("\"front_camera\"", "\"lidar_top\"");
    assert!(error_of(&twice).contains("two sensors are named \"lidar_top\""), "{}", error_of(&twice));
    let bad = TWO_SENSORS.replace("fx = 100.0\n", "");
    let msg = error_of(&bad);
    assert!(msg.contains("[[sensors]] \"front_camera\"") && msg.contains("fx = missing"), "{msg}");
    let bad_mount = TWO_SENSORS.replace("0.2164396, 0.0, 0.9762960", "0.5, 0.0, 0.5");
    let msg = error_of(&bad_mount);
    assert!(msg.contains("front_camera") && msg.contains("unit quaternion"), "{msg}");
    let mount_in_sensor =
        shipped().replace("kind = \"lidar\"", "kind = \"lidar\"\nsensor_in_body = [0, 0, 0, 0, 0, 0, 1]");
    assert!(error_of(&mount_in_sensor).contains("[sensor] takes no sensor_in_body"), "{}", error_of(&mount_in_sensor));
    let none = shipped().split("[occupancy]").nth(1).map(|rest| format!("[occupancy]{rest}")).expect("text");
    assert!(error_of(&none).contains("missing [sensor]"), "{}", error_of(&none));
}
