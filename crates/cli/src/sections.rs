//! The sections of a configuration file the CLI reads beside the mapper's
//! (which the library's `Config` reads): `[scene]` for `edtmap run
//! --scene`, `[output]` for its pictures and `[dataset]` for `--dataset`
//! (`edtmap node` reads `[ros]` with `edtmap_node::config`).

use anyhow::{anyhow, Result};
use edtmap::config::{sections, Config, WORLD_M};
use edtmap::MapError;
use edtmap_ros::config::DatasetSection;
use edtmap_sim::SceneSection;
use serde::Deserialize;
use std::path::Path;

/// `[output]`: pictures.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct OutputSection {
    /// Height of the pictured horizontal slices, metres (default: the
    /// layer of the last local volume with the most observed voxels).
    #[serde(default)]
    pub(crate) slice_height_m: Option<f64>,
}

/// The CLI's sections of one configuration file.
#[derive(Debug, Clone, Default, Deserialize)]
pub(crate) struct Sections {
    /// The built-in scene to replay.
    #[serde(default)]
    pub(crate) scene: Option<SceneSection>,
    /// Pictures.
    #[serde(default)]
    pub(crate) output: OutputSection,
    /// Recordings replayed with `edtmap run --dataset`.
    #[serde(default)]
    pub(crate) dataset: DatasetSection,
}

impl Sections {
    /// The CLI's sections of `text`, each number checked as the library
    /// checks the mapper's.
    pub(crate) fn parse(text: &str, origin: &str) -> Result<Sections> {
        let s: Sections = sections(text, origin)?;
        let in_section = |section| move |source| MapError::Config { section, source };
        if let Some(scene) = &s.scene {
            scene.options().map_err(|e| anyhow!("config [scene] {e}"))?;
        }
        WORLD_M.opt("slice_height_m", s.output.slice_height_m).map_err(in_section("output"))?;
        s.dataset.validate().map_err(in_section("dataset"))?;
        Ok(s)
    }
}

/// The mapper's configuration and the CLI's sections of `text`.
pub(crate) fn parse(text: &str, origin: &str) -> Result<(Config, Sections)> {
    Ok((Config::parse(text, origin)?, Sections::parse(text, origin)?))
}

/// The mapper's configuration and the CLI's sections of the file `path`.
pub(crate) fn load(path: &Path) -> Result<(Config, Sections)> {
    let text = edtmap::config::read(path)?;
    parse(&text, &path.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use edtmap_conformance::config_text::{assert_names_the_value, configs_dir, set, shipped as config_text};

    #[test]
    fn every_shipped_config_has_valid_sections() {
        let mut scenes = 0;
        for entry in std::fs::read_dir(configs_dir()).expect("configs/") {
            let path = entry.expect("entry").path();
            let (_, s) = load(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
            let stem = path.file_stem().and_then(|s| s.to_str()).expect("utf-8 name");
            match &s.scene {
                // A scene's own config is named after it; a variant
                // (another sensor set) after it and what it varies.
                Some(scene) if stem == scene.name => scenes += 1,
                Some(scene) => {
                    assert!(stem.starts_with(&format!("{}_", scene.name)), "{stem}.toml runs {}", scene.name)
                }
                // Configs for recordings (`--dataset`) name no scene.
                None => assert!(
                    matches!(
                        stem,
                        "3dmatch" | "velodyne" | "tum" | "ros_lidar" | "ros_depth" | "ros2_lidar" | "ros2_depth"
                    ),
                    "{stem}.toml names no scene"
                ),
            }
            let text = std::fs::read_to_string(&path).expect("read");
            edtmap_node::config::RosSection::parse(&text, "t.toml")
                .unwrap_or_else(|e| panic!("{}: [ros] {e}", path.display()));
        }
        assert!(scenes >= 4, "expected a config per built-in scene");
    }

    /// The CLI's sections refuse NaN, infinities and meaningless values
    /// with one message naming the section, the field (once), the value
    /// and the accepted range, as the mapper's sections do.
    #[test]
    fn out_of_range_numbers_name_section_field_value_and_range_once() {
        let cases: &[(&str, &str, &str, &str, &str)] = &[
            ("uav_pillars.toml", "scene", "range_noise_m", "-0.1", "-0.1"),
            ("uav_pillars.toml", "scene", "range_noise_m", "nan", "NaN"),
            ("uav_pillars.toml", "scene", "range_noise_m", "2.0", "2"),
            ("uav_pillars.toml", "scene", "dropout", "1.5", "1.5"),
            ("uav_pillars.toml", "output", "slice_height_m", "nan", "NaN"),
            ("uav_pillars.toml", "output", "slice_height_m", "-inf", "-inf"),
            ("3dmatch.toml", "dataset", "depth_scale_m", "1e30", "1e30"),
            ("3dmatch.toml", "dataset", "depth_scale_m", "0.0", "0.0"),
            ("3dmatch.toml", "dataset", "depth_scale_m", "nan", "NaN"),
            ("3dmatch.toml", "dataset", "max_pose_gap_s", "0.0", "0.0"),
            ("3dmatch.toml", "dataset", "max_pose_gap_s", "1e9", "1000000000"),
            ("3dmatch.toml", "dataset", "sensor_in_body", "[1e9, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]", "1000000000"),
            ("3dmatch.toml", "dataset", "sensor_in_body", "[0.0, 0.0, 0.0, nan, 0.0, 0.0, 1.0]", "NaN"),
        ];
        for &(file, section, field, value, shown) in cases {
            let text = set(&config_text(file), section, field, value);
            let err = parse(&text, file).expect_err(&format!("{file}: [{section}] {field} = {value} accepted"));
            assert_names_the_value(&format!("{err:#}"), section, field, value, shown);
        }
    }

    #[test]
    fn values_at_the_ends_of_their_ranges_are_accepted() {
        let cases = [
            ("3dmatch.toml", "dataset", "depth_scale_m", "1000.0"),
            ("uav_pillars.toml", "output", "slice_height_m", "-0.4"),
            ("uav_pillars.toml", "scene", "dropout", "1.0"),
            ("uav_pillars.toml", "scene", "range_noise_m", "1.0"),
        ];
        for (file, section, field, value) in cases {
            if let Err(e) = parse(&set(&config_text(file), section, field, value), file) {
                panic!("[{section}] {field} = {value} refused: {e:#}");
            }
        }
    }

    #[test]
    fn an_unknown_section_or_field_is_named() {
        let text = config_text("uav_pillars.toml");
        let e = format!("{:#}", parse(&format!("{text}\n[outptu]\nx = 1\n"), "t.toml").expect_err("typo"));
        assert!(e.contains("outptu"), "{e}");
        let e = format!("{:#}", parse(&set(&text, "dataset", "on_eror", "\"skip\""), "t.toml").expect_err("typo"));
        assert!(e.contains("on_eror"), "{e}");
        let e = format!("{:#}", parse(&set(&text, "scene", "sead", "3"), "t.toml").expect_err("typo"));
        assert!(e.contains("sead"), "{e}");
    }
}
