//! Configuration texts for tests: a shipped file with one field changed,
//! and what the error for an out-of-range value must say.

use std::path::PathBuf;

/// The repository's `configs/` folder.
pub fn configs_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../configs")
}

/// The text of the shipped configuration `configs/NAME`.
pub fn shipped(name: &str) -> String {
    std::fs::read_to_string(configs_dir().join(name)).unwrap_or_else(|e| panic!("configs/{name}: {e}"))
}

/// Checks that `message`, the error for `[section] field = value`, names
/// the section, the field exactly once, the value as `shown`, and the
/// accepted range ("must ...").
pub fn assert_names_the_value(message: &str, section: &str, field: &str, value: &str, shown: &str) {
    let case = format!("[{section}] {field} = {value}: {message}");
    assert!(message.contains(&format!("[{section}]")), "no section: {case}");
    assert_eq!(message.matches(field).count(), 1, "field not named exactly once: {case}");
    assert!(message.contains(shown), "value not shown: {case}");
    assert!(message.contains("must"), "no accepted range: {case}");
}

/// `text` (a TOML configuration) with `key = value` in `[section]`: the
/// key's line replaced where the section has it, else inserted under the
/// header; the section appended where the text has none.
pub fn set(text: &str, section: &str, key: &str, value: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let header = format!("[{section}]");
    let start = match lines.iter().position(|l| l.trim() == header) {
        Some(i) => i,
        None => {
            lines.push(header);
            lines.len() - 1
        }
    };
    let end =
        lines[start + 1..].iter().position(|l| l.trim_start().starts_with('[')).map_or(lines.len(), |i| start + 1 + i);
    let at = (start + 1..end).find(|&i| lines[i].split('=').next().is_some_and(|k| k.trim() == key));
    match at {
        Some(i) => lines[i] = format!("{key} = {value}"),
        None => lines.insert(start + 1, format!("{key} = {value}")),
    }
    lines.join("\n") + "\n"
}

#[cfg(test)]
mod tests {
    use super::set;

    #[test]
    fn replaces_inserts_and_appends() {
        let text = "[a]\nx = 1\ny = 2\n\n[b]\nx = 3\n";
        assert_eq!(set(text, "a", "y", "5"), "[a]\nx = 1\ny = 5\n\n[b]\nx = 3\n");
        assert_eq!(set(text, "b", "z", "6"), "[a]\nx = 1\ny = 2\n\n[b]\nz = 6\nx = 3\n");
        assert_eq!(set(text, "c", "w", "7"), "[a]\nx = 1\ny = 2\n\n[b]\nx = 3\n[c]\nw = 7\n");
    }
}
