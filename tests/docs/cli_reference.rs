//! The command-line reference (`docs/reference/cli.md`) lists every command
//! and flag of the CLI.

use std::collections::BTreeSet;

use crate::util::root;

/// A command of the CLI: its words after `cellwatch`, its long flags and
/// its positional arguments' names.
struct CliCommand {
    path: String,
    longs: Vec<String>,
    positionals: Vec<String>,
}

fn cli_commands() -> Vec<CliCommand> {
    fn walk(cmd: &clap::Command, path: &str, out: &mut Vec<CliCommand>) {
        for sub in cmd.get_subcommands() {
            if sub.get_name() == "help" {
                continue;
            }
            let path = format!("{path} {}", sub.get_name()).trim().to_string();
            let mut longs = Vec::new();
            let mut positionals = Vec::new();
            for arg in sub.get_arguments() {
                if arg.is_hide_set() || matches!(arg.get_id().as_str(), "help" | "version") {
                    continue;
                }
                if let Some(long) = arg.get_long() {
                    longs.push(long.to_string());
                } else if arg.is_positional() {
                    let name = arg
                        .get_value_names()
                        .and_then(|n| n.first())
                        .map_or_else(|| arg.get_id().as_str().to_uppercase(), |n| n.to_string());
                    positionals.push(name);
                }
            }
            out.push(CliCommand {
                path: path.clone(),
                longs,
                positionals,
            });
            walk(sub, &path, out);
        }
    }
    let mut out = Vec::new();
    walk(
        &<cellwatch::cli::Cli as clap::CommandFactory>::command(),
        "",
        &mut out,
    );
    out
}

/// The sections of a page by heading: (heading line, level, text up to the
/// next heading of the same or a higher level).
fn sections(text: &str) -> Vec<(String, usize, String)> {
    let lines: Vec<&str> = text.lines().collect();
    let level = |l: &str| {
        let n = l.chars().take_while(|&c| c == '#').count();
        (n > 0 && l[n..].starts_with(' ')).then_some(n)
    };
    let mut out = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        if let Some(n) = level(l) {
            let end = lines[i + 1..]
                .iter()
                .position(|m| level(m).is_some_and(|k| k <= n))
                .map_or(lines.len(), |p| i + 1 + p);
            out.push((l.to_string(), n, lines[i..end].join("\n")));
        }
    }
    out
}

/// The `--flags` written in `text`.
fn flags_in(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let bytes = text.as_bytes();
    let mut i = 0;
    while let Some(p) = text[i..].find("--") {
        let at = i + p;
        let before_ok =
            at == 0 || !(bytes[at - 1].is_ascii_alphanumeric() || bytes[at - 1] == b'-');
        let name: String = text[at + 2..]
            .chars()
            .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '-')
            .collect();
        if before_ok && name.starts_with(|c: char| c.is_ascii_lowercase()) {
            out.insert(name.trim_end_matches('-').to_string());
        }
        i = at + 2;
    }
    out
}

fn has_word(text: &str, word: &str) -> bool {
    text.match_indices(word).any(|(at, _)| {
        let before = text[..at].chars().next_back();
        let after = text[at + word.len()..].chars().next();
        let edge = |c: Option<char>| !c.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_');
        edge(before) && edge(after)
    })
}

#[test]
fn the_cli_reference_lists_every_command_and_flag() {
    let text = std::fs::read_to_string(root().join("docs/reference/cli.md")).unwrap();
    let sections = sections(&text);
    let commands = cli_commands();
    assert!(commands.len() > 30, "{} commands", commands.len());
    let mut problems = Vec::new();
    for c in &commands {
        let heading = format!("`cellwatch {}`", c.path);
        let Some((_, _, body)) = sections
            .iter()
            .find(|(h, _, _)| h.trim_start_matches('#').trim() == heading)
        else {
            problems.push(format!("no section headed {heading}"));
            continue;
        };
        let written = flags_in(body);
        for long in &c.longs {
            if !written.contains(long) {
                problems.push(format!("{heading}: --{long} is not described"));
            }
        }
        for p in &c.positionals {
            if !has_word(body, p) {
                problems.push(format!("{heading}: argument {p} is not described"));
            }
        }
        // Nothing stale: every flag written in a command's section is one
        // of its own or of a command under it.
        let known: BTreeSet<&str> = commands
            .iter()
            .filter(|d| d.path == c.path || d.path.starts_with(&format!("{} ", c.path)))
            .flat_map(|d| d.longs.iter().map(String::as_str))
            .chain(["help", "version"])
            .collect();
        for f in &written {
            if !known.contains(f.as_str()) {
                problems.push(format!("{heading}: --{f} is no flag of this command"));
            }
        }
    }
    // Every command section names a command that exists.
    let paths: BTreeSet<String> = commands.iter().map(|c| c.path.clone()).collect();
    for (h, _, _) in &sections {
        let title = h.trim_start_matches('#').trim();
        if let Some(path) = title
            .strip_prefix("`cellwatch ")
            .and_then(|t| t.strip_suffix('`'))
        {
            if !paths.contains(path) {
                problems.push(format!("section {title}: no such command"));
            }
        }
    }
    assert!(
        problems.is_empty(),
        "docs/reference/cli.md:\n{}",
        problems.join("\n")
    );
}
