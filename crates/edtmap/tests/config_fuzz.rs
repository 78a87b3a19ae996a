//! Seeded fuzzing of every shipped config: one value replaced by an odd
//! one (zero, negative, huge, tiny, NaN, infinite, the wrong type), a line
//! dropped or a section repeated; then the mapper is made and runs three
//! simulated frames under a small memory budget. Every case must end in a
//! clean error or a finished run: no panic, no abort (an abort would kill
//! this test), no allocation past the budget.

use edtmap::config::Config;
use edtmap::Mapper;
use edtmap_sim::{Scene, SceneName, SceneOptions};
use std::path::PathBuf;

/// Mutated cases per shipped config.
const CASES_PER_CONFIG: usize = 30;
/// The memory budget every case runs under.
const BUDGET_BYTES: u64 = 320 << 20;

/// Values that break naive parsers and unchecked allocations.
const ODD_VALUES: [&str; 18] = [
    "0",
    "-1",
    "1e30",
    "-1e30",
    "nan",
    "inf",
    "-inf",
    "1e-30",
    "18446744073709551615",
    "4294967296",
    "0.000001",
    "\"\"",
    "\"x\"",
    "true",
    "[]",
    "[1e9, 1e9, 1e9]",
    "[0.0, 0.0, 0.0]",
    "-0.0",
];

/// A small deterministic generator (64-bit LCG, high bits).
struct Lcg(u64);

impl Lcg {
    fn below(&mut self, n: usize) -> usize {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 33) as usize) % n.max(1)
    }
}

/// `text` with one mutation.
fn mutate(text: &str, rng: &mut Lcg) -> String {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    // Lines holding a whole `key = value` (not the start of a multi-line array).
    let whole = |l: &str| {
        l.contains('=') && !l.trim_start().starts_with('#') && l.matches('[').count() == l.matches(']').count()
    };
    let values: Vec<usize> = (0..lines.len()).filter(|&i| whole(&lines[i])).collect();
    match rng.below(10) {
        0 if !lines.is_empty() => {
            let i = rng.below(lines.len());
            lines.remove(i);
        }
        1 => {
            let sections: Vec<usize> = (0..lines.len()).filter(|&i| lines[i].starts_with('[')).collect();
            if let Some(&i) = sections.get(rng.below(sections.len())) {
                let header = lines[i].clone();
                lines.push(header);
            }
        }
        _ if !values.is_empty() => {
            let i = values[rng.below(values.len())];
            let key = lines[i].split('=').next().unwrap_or("").trim().to_string();
            lines[i] = format!("{key} = {}", ODD_VALUES[rng.below(ODD_VALUES.len())]);
        }
        _ => {}
    }
    lines.join("\n")
}

/// `[scene]`, which the CLI reads.
#[derive(serde::Deserialize)]
struct SceneFile {
    scene: Option<edtmap_sim::SceneSection>,
}

/// A scene to simulate frames from: the config's own, else one whose
/// sensor kind fits.
fn scene_for(config: &Config, text: &str) -> SceneName {
    let named = edtmap::config::sections::<SceneFile>(text, "fuzz.toml").ok().and_then(|f| f.scene);
    if let Some(s) = named.and_then(|s| s.name.parse().ok()) {
        return s;
    }
    match config.sensor.kind {
        edtmap::config::SensorKind::Depth => SceneName::Room,
        _ => SceneName::UavPillars,
    }
}

/// Parses `text`, makes the mapper under the budget and runs three frames;
/// errors are fine, panics are not.
fn run_case(text: &str, scenes: &mut std::collections::HashMap<SceneName, Scene>) -> Result<usize, String> {
    let config = Config::parse(text, "fuzz.toml").map_err(|e| e.to_string())?;
    let (sensor, mut params) = config.mapper_params().map_err(|e| e.to_string())?;
    params.max_memory_bytes = Some(BUDGET_BYTES);
    let mut mapper = Mapper::new(sensor.clone(), params).map_err(|e| e.to_string())?;
    let name = scene_for(&config, text);
    let scene = scenes.entry(name).or_insert_with(|| Scene::new(name, &SceneOptions::default()).expect("scene"));
    let mut done = 0;
    for i in 0..3 {
        let Ok(frame) = scene.frame(&sensor, i) else { continue };
        if mapper.integrate_frame(&frame).is_ok() {
            done += 1;
        }
    }
    Ok(done)
}

#[test]
fn mutated_configs_never_panic() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs");
    let mut paths: Vec<PathBuf> =
        std::fs::read_dir(&dir).expect("configs/").map(|e| e.expect("entry").path()).collect();
    paths.sort();
    let mut rng = Lcg(0x5eed_cafe);
    let mut scenes = std::collections::HashMap::new();
    let (mut refused, mut ran) = (0, 0);
    for path in &paths {
        let text = std::fs::read_to_string(path).expect("config");
        for case in 0..CASES_PER_CONFIG {
            let mutated = mutate(&text, &mut rng);
            let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_case(&mutated, &mut scenes)));
            match outcome {
                Ok(Ok(_)) => ran += 1,
                Ok(Err(e)) => {
                    assert!(!e.is_empty(), "an empty error message");
                    if refused < 400 && std::env::var("FUZZ_DEBUG").is_ok() {
                        eprintln!("{}: {e}", path.display());
                    }
                    refused += 1;
                }
                Err(_) => panic!("{} case {case} panicked on:\n{mutated}", path.display()),
            }
        }
    }
    eprintln!("{refused} mutated configs refused, {ran} ran their frames");
    assert!(refused > 0 && ran > 0, "the mutations both break and keep configs ({refused} refused, {ran} ran)");
}
