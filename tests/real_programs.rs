//! `cellwatch sf` on every program of the real-program corpus
//! (`tests/data/real/`): it exits 0 (read) or 2 (refused), never panics,
//! and every message it prints names the file, line and column.

use crate::util::{cellwatch, root};

/// Whether `line` starts `FILE:LINE:COL:` (optionally after `error: `).
fn located(line: &str, file: &str) -> bool {
    let rest = line.strip_prefix("error: ").unwrap_or(line);
    let Some(rest) = rest.strip_prefix(file).and_then(|r| r.strip_prefix(':')) else {
        return false;
    };
    let mut parts = rest.splitn(3, ':');
    let number =
        |p: Option<&str>| p.is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
    number(parts.next()) && number(parts.next())
}

#[test]
fn every_real_program_is_read_or_refused_with_located_messages() {
    let dir = root().join("tests/data/real");
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n != "README.md")
        .collect();
    files.sort();
    assert!(files.len() >= 16, "{files:?}");
    let mut refused = Vec::new();
    for name in &files {
        let file = format!("tests/data/real/{name}");
        let run = cellwatch(&["sf", &file]);
        assert!(
            run.code == 0 || run.code == 2,
            "{file}: exit {}\n{}",
            run.code,
            run.stderr
        );
        for line in run.stderr.lines() {
            // The cap's summary line is the only one without a place.
            if line.starts_with("... and ") {
                continue;
            }
            assert!(located(line, &file), "{file}: unlocated message: {line}");
        }
        // A coil that is not derivable says where the reason is.
        for line in run
            .stdout
            .lines()
            .filter(|l| l.contains("is not derivable"))
        {
            assert!(line.trim_start().starts_with(&format!("{file}:")), "{line}");
        }
        if run.code == 2 {
            refused.push(name.as_str());
        }
    }
    // Only the project whose one ladder body is empty is refused.
    assert_eq!(refused, ["matiec-LD_TEST.xml"]);
}
