//! `docs/configuration.md` against the code: for every section of the
//! configuration file, the keys of the page's table are exactly the keys
//! the section's parser accepts.
//!
//! The accepted keys come from the parsers themselves: each section is
//! parsed with an unknown key as its first key, and serde's error lists
//! the keys the section takes (``unknown field `zz_not_a_key`, expected one
//! of `a`, `b`, ...``). `[output]` is parsed inside the `edtmap` binary, so
//! its error is read from the binary's stderr.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use edtmap::config::{sections, Config};
use edtmap_node::config::RosSection;
use edtmap_ros::config::DatasetSection;
use edtmap_sim::SceneSection;

/// The key no section accepts.
const PROBE: &str = "zz_not_a_key";

/// A lone sensor's keys, and `[occupancy]`'s, of a minimal valid config.
const SENSOR: &str = "kind = \"points\"\nmin_range_m = 0.5\nmax_range_m = 40.0\n";
const OCCUPANCY: &str = "voxel_size_m = 0.2\n";

/// The columns of every table of the page.
const COLUMNS: [&str; 5] = ["key", "type", "default", "range", "meaning"];

type Keys = BTreeSet<String>;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The page: each heading's text (without the `#`s), its level and the
/// keys of the first table under it (none where it has no table).
struct Page {
    text: String,
    headings: Vec<(usize, String, Option<Vec<String>>)>,
}

impl Page {
    fn read() -> Page {
        let path = repo().join("docs/configuration.md");
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut headings: Vec<(usize, String, Option<Vec<String>>)> = Vec::new();
        let (mut fence, mut in_table, mut table_done) = (false, false, false);
        for (n, line) in text.lines().enumerate() {
            let at = format!("docs/configuration.md:{}", n + 1);
            if line.trim_start().starts_with("```") {
                fence = !fence;
                continue;
            }
            if fence {
                continue;
            }
            let level = line.chars().take_while(|&c| c == '#').count();
            if level > 0 && line[level..].starts_with(' ') {
                headings.push((level, line[level..].trim().to_string(), None));
                (in_table, table_done) = (false, false);
                continue;
            }
            let row = line.trim();
            if !row.starts_with('|') {
                if in_table {
                    (in_table, table_done) = (false, true);
                }
                continue;
            }
            let Some((_, heading, keys)) = headings.last_mut() else { panic!("{at}: a table before any heading") };
            if table_done {
                continue;
            }
            let cells: Vec<&str> = row.trim_matches('|').split('|').map(str::trim).collect();
            if !in_table {
                assert_eq!(cells, COLUMNS, "{at}: the columns of the table under {heading:?}");
                (in_table, *keys) = (true, Some(Vec::new()));
                continue;
            }
            if cells.iter().all(|c| !c.is_empty() && c.chars().all(|ch| matches!(ch, '-' | ':'))) {
                continue;
            }
            assert_eq!(cells.len(), COLUMNS.len(), "{at}: a row of {} cells (a `|` inside a cell?)", cells.len());
            let key = cells[0].strip_prefix('`').and_then(|k| k.strip_suffix('`'));
            let key = key.unwrap_or_else(|| panic!("{at}: the first cell is not a `key`: {:?}", cells[0]));
            assert!(!cells[1].is_empty() && !cells[2].is_empty() && !cells[4].is_empty(), "{at}: {key} lacks a cell");
            keys.get_or_insert_with(Vec::new).push(key.to_string());
        }
        assert!(!fence, "docs/configuration.md: a code fence is not closed");
        Page { text, headings }
    }

    /// The keys of the table under the heading `heading`, each once.
    fn table(&self, heading: &str) -> Keys {
        let found: Vec<_> = self.headings.iter().filter(|(_, h, _)| h == heading).collect();
        assert_eq!(found.len(), 1, "docs/configuration.md: {} headings {heading:?}", found.len());
        let keys = found[0].2.as_ref().unwrap_or_else(|| panic!("no table under {heading:?}"));
        let set: Keys = keys.iter().cloned().collect();
        assert_eq!(set.len(), keys.len(), "a key listed twice under {heading:?}: {keys:?}");
        set
    }

    /// The sections the level-2 headings `## [name]` (or `## [a] and
    /// [[b]]`) describe, each with its heading.
    fn sections(&self) -> BTreeMap<String, String> {
        let mut out = BTreeMap::new();
        for (_, heading, _) in self.headings.iter().filter(|(level, h, _)| *level == 2 && h.starts_with('[')) {
            for word in heading.split_whitespace().filter(|w| w.starts_with('[')) {
                let name = word.trim_start_matches('[').trim_end_matches(']');
                let before = out.insert(name.to_string(), heading.clone());
                assert!(before.is_none(), "section [{name}] under two headings");
            }
        }
        out
    }

    /// The first TOML example of the page.
    fn example(&self) -> String {
        let start = self.text.find("```toml\n").expect("a ```toml example") + "```toml\n".len();
        let end = self.text[start..].find("```").expect("the example's end");
        self.text[start..start + end].to_string()
    }
}

/// The keys serde lists after ``unknown field `zz_not_a_key` `` in
/// `message` (`expected one of `a`, `b``, `expected `a` or `b``, `expected `a``).
fn expected_keys(message: &str) -> Keys {
    let unknown = format!("unknown field `{PROBE}`");
    let at = message.find(&unknown).unwrap_or_else(|| panic!("the error does not name {PROBE}: {message}"));
    let rest = message[at + unknown.len()..].lines().next().unwrap_or_default();
    assert!(rest.starts_with(", expected "), "the error lists no keys: {message}");
    rest.split('`').skip(1).step_by(2).map(str::to_string).collect()
}

fn probe_line() -> String {
    format!("{PROBE} = 1\n")
}

/// The mapper's error for `text`, which it must refuse.
fn config_error(text: &str) -> String {
    match Config::parse(text, "probe.toml") {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// A minimal valid mapper config followed by `more`.
fn minimal(more: &str) -> String {
    format!("[sensor]\n{SENSOR}[occupancy]\n{OCCUPANCY}{more}")
}

/// The file as `[scene]`'s parser sees it (the CLI's sections struct,
/// which is private to the binary, holds the same `SceneSection`).
#[derive(serde::Deserialize)]
struct SceneFile {
    scene: Option<SceneSection>,
}

fn scene(text: &str) -> Result<Option<SceneSection>, String> {
    let file: SceneFile = sections(text, "probe.toml").map_err(|e| e.to_string())?;
    if let Some(s) = &file.scene {
        s.options().map_err(|e| e.to_string())?;
    }
    Ok(file.scene)
}

#[test]
fn every_section_of_the_file_has_a_heading() {
    let accepted = expected_keys(&config_error(&format!("{}{}", probe_line(), minimal(""))));
    let page = Page::read();
    let documented: Keys = page.sections().into_keys().collect();
    assert_eq!(documented, accepted, "the `## [section]` headings against the sections the file accepts");
    let sensor = &page.sections()["sensor"];
    assert_eq!(sensor, "[sensor] and [[sensors]]");
}

#[test]
fn sensor_keys() {
    let page = Page::read();
    let lone = expected_keys(&config_error(&format!("[sensor]\n{}{SENSOR}[occupancy]\n{OCCUPANCY}", probe_line())));
    let entry = expected_keys(&config_error(&format!("[[sensors]]\n{}{SENSOR}[occupancy]\n{OCCUPANCY}", probe_line())));
    assert_eq!(lone, entry, "[sensor] and a [[sensors]] entry take the same keys");
    assert_eq!(page.table("[sensor] and [[sensors]]"), lone, "[sensor]");
}

/// `[occupancy]`, the log-odds probabilities among its keys.
#[test]
fn occupancy_keys() {
    let error = config_error(&format!("[sensor]\n{SENSOR}[occupancy]\n{}{OCCUPANCY}", probe_line()));
    assert_eq!(Page::read().table("[occupancy]"), expected_keys(&error), "[occupancy]");
}

#[test]
fn edt_global_and_memory_keys() {
    let page = Page::read();
    for section in ["edt", "global", "memory"] {
        let accepted = expected_keys(&config_error(&minimal(&format!("[{section}]\n{}", probe_line()))));
        assert_eq!(page.table(&format!("[{section}]")), accepted, "[{section}]");
    }
    let zone = format!("[global]\nforbidden = [{{ {PROBE} = 1, min_m = [0.0, 0.0, 0.0], max_m = [1.0, 1.0, 1.0] }}]\n");
    let accepted = expected_keys(&config_error(&minimal(&zone)));
    assert_eq!(page.table("[global] forbidden entries"), accepted, "[global] forbidden");
}

#[test]
fn scene_keys() {
    let error = scene(&format!("[scene]\n{}name = \"uav_pillars\"\n", probe_line())).expect_err("an unknown key");
    assert_eq!(Page::read().table("[scene]"), expected_keys(&error), "[scene]");
}

#[test]
fn dataset_keys() {
    let error = DatasetSection::parse(&format!("[dataset]\n{}", probe_line()), "probe.toml").expect_err("unknown key");
    assert_eq!(Page::read().table("[dataset]"), expected_keys(&error.to_string()), "[dataset]");
}

#[test]
fn ros_keys() {
    let error = RosSection::parse(&format!("[ros]\n{}", probe_line()), "probe.toml").expect_err("unknown key");
    assert_eq!(Page::read().table("[ros]"), expected_keys(&error.to_string()), "[ros]");
}

/// `[output]` is the binary's own: `edtmap run` refuses the file before it
/// maps anything, and says why on stderr.
#[test]
fn output_keys() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let config = dir.path().join("probe.toml");
    std::fs::write(&config, minimal(&format!("[output]\n{}", probe_line()))).expect("write the config");
    let out = Command::new(env!("CARGO_BIN_EXE_edtmap"))
        .args(["run", "--backend", "cpu", "--scene", "uav_pillars", "--frames", "1", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .expect("run edtmap");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "edtmap run accepted [output] {PROBE}: {stderr}");
    assert_eq!(Page::read().table("[output]"), expected_keys(&stderr), "[output]");
}

/// The page's example is a valid file for every section's parser.
#[test]
fn the_example_parses() {
    let example = Page::read().example();
    Config::parse(&example, "the example").unwrap_or_else(|e| panic!("{e}\n{example}"));
    let scene = scene(&example).unwrap_or_else(|e| panic!("{e}\n{example}"));
    let name = scene.expect("the example names a scene").name;
    assert!(name.parse::<edtmap_sim::SceneName>().is_ok(), "scene {name:?}");
    DatasetSection::parse(&example, "the example").unwrap_or_else(|e| panic!("{e}\n{example}"));
    RosSection::parse(&example, "the example").unwrap_or_else(|e| panic!("{e}\n{example}"));
}

/// Every shipped configuration is linked, and every link to one exists.
#[test]
fn shipped_configs_are_linked() {
    let page = Page::read();
    let linked: Keys = page
        .text
        .split("](../configs/")
        .skip(1)
        .map(|rest| rest.split(')').next().unwrap_or_default().to_string())
        .collect();
    for name in &linked {
        assert!(Path::new(&repo().join("configs").join(name)).is_file(), "a link to ../configs/{name}: no such file");
    }
    let shipped: Keys = std::fs::read_dir(repo().join("configs"))
        .expect("configs/")
        .map(|e| e.expect("an entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".toml"))
        .collect();
    assert_eq!(linked, shipped, "the configs the page links against those in configs/");
}
