//! Configuration texts for tests: a shipped file with one field changed.

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
