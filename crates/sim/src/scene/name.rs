//! Scene names and options.

use crate::SimError;
use serde::Deserialize;
use std::fmt;
use std::str::FromStr;

/// The built-in scenes (the paper's datasets, synthesized).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SceneName {
    /// A drone at ~2 m/s among pillars in a 40 × 40 m field, 32-ring LiDAR
    /// (paper §V-A, UAV-Pillar).
    UavPillars,
    /// A ground robot at 1 m/s in a loop of 2.6 m wide corridors with four
    /// walking pedestrians, 16-ring LiDAR (UGV-Corridor).
    UgvCorridor,
    /// A 6 × 5 × 2.7 m furnished room circled by a hand-held depth camera
    /// (Cow-and-Lady-like).
    Room,
    /// A drone at 1 m height on a cluttered 20 × 20 m floor, planar LiDAR
    /// (paper §VI).
    Planar,
}

impl SceneName {
    /// Every built-in scene.
    pub const ALL: [SceneName; 4] = [SceneName::UavPillars, SceneName::UgvCorridor, SceneName::Room, SceneName::Planar];

    /// The scene's name as written in configs: `uav_pillars`, `ugv_corridor`,
    /// `room` or `planar`.
    pub fn as_str(self) -> &'static str {
        match self {
            SceneName::UavPillars => "uav_pillars",
            SceneName::UgvCorridor => "ugv_corridor",
            SceneName::Room => "room",
            SceneName::Planar => "planar",
        }
    }
}

impl fmt::Display for SceneName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for SceneName {
    type Err = SimError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        SceneName::ALL
            .into_iter()
            .find(|n| n.as_str() == s)
            .ok_or_else(|| SimError::UnknownScene { name: s.to_owned() })
    }
}

/// Seed and sensor noise of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneOptions {
    /// Seed of the layout and of the noise.
    pub seed: u64,
    /// Standard deviation of the Gaussian noise added to each return,
    /// metres (on the range for LiDARs, on the depth for cameras).
    pub range_noise_m: f64,
    /// Probability that a return is lost (reported as no return).
    pub dropout: f64,
}

impl Default for SceneOptions {
    /// Seed 7, no noise, no dropout.
    fn default() -> Self {
        SceneOptions { seed: 7, range_noise_m: 0.0, dropout: 0.0 }
    }
}

impl SceneOptions {
    /// Checks that the noise is between 0 and 1 m and the dropout a
    /// probability.
    pub fn validate(&self) -> Result<(), SimError> {
        if !(0.0..=1.0).contains(&self.range_noise_m) {
            return Err(SimError::InvalidOption {
                field: "range_noise_m",
                value: self.range_noise_m.to_string(),
                reason: "must be finite, in [0, 1] metres",
            });
        }
        if !(0.0..=1.0).contains(&self.dropout) {
            return Err(SimError::InvalidOption {
                field: "dropout",
                value: self.dropout.to_string(),
                reason: "must be a probability in [0, 1]",
            });
        }
        Ok(())
    }
}

/// `[scene]` of a configuration file: which built-in scene to replay and
/// how to simulate it (`edtmap run --scene`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSection {
    /// Scene name (`uav_pillars`, `ugv_corridor`, `room`, `planar`).
    pub name: String,
    /// Frames to replay; the scene's own length when absent.
    #[serde(default)]
    pub frames: Option<usize>,
    /// Seed of the layout and the noise.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Standard deviation of Gaussian range noise, metres.
    #[serde(default)]
    pub range_noise_m: f64,
    /// Probability that a return is dropped.
    #[serde(default)]
    pub dropout: f64,
}

fn default_seed() -> u64 {
    SceneOptions::default().seed
}

impl SceneSection {
    /// The scene `name` with the default options.
    pub fn named(name: &str) -> SceneSection {
        let o = SceneOptions::default();
        SceneSection {
            name: name.into(),
            frames: None,
            seed: o.seed,
            range_noise_m: o.range_noise_m,
            dropout: o.dropout,
        }
    }

    /// The seed and noise, checked.
    pub fn options(&self) -> Result<SceneOptions, SimError> {
        let options = SceneOptions { seed: self.seed, range_noise_m: self.range_noise_m, dropout: self.dropout };
        options.validate()?;
        Ok(options)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for n in SceneName::ALL {
            assert_eq!(n.to_string().parse::<SceneName>(), Ok(n));
        }
        let e = "forest".parse::<SceneName>().expect_err("unknown");
        assert!(e.to_string().contains("forest"), "{e}");
    }

    #[test]
    fn bad_options_name_the_field() {
        let bad = |o: SceneOptions| o.validate().expect_err("invalid").to_string();
        assert!(bad(SceneOptions { range_noise_m: -0.1, ..Default::default() }).contains("range_noise_m"));
        assert!(bad(SceneOptions { range_noise_m: f64::NAN, ..Default::default() }).contains("range_noise_m"));
        assert!(bad(SceneOptions { dropout: 1.5, ..Default::default() }).contains("dropout"));
        assert!(bad(SceneOptions { dropout: f64::NAN, ..Default::default() }).contains("dropout"));
        assert!(SceneOptions { dropout: 1.0, range_noise_m: 0.05, seed: 1 }.validate().is_ok());
    }
}
