//! The documentation held to the code: every `cellwatch` command shown in
//! a fenced block of `README.md` or `docs/**/*.md` is parsed by the CLI's
//! own clap parser, and the references (`docs/reference/cli.md`,
//! `config.md`, `metrics.md`) list exactly what the code has, no more, no
//! less.
//!
//! Completeness comes from the code, never from a list kept here:
//! - commands and flags: clap's introspection of [`cellwatch::cli::Cli`],
//!   walked recursively;
//! - configuration keys: the parser itself, [`cellwatch::config::parse`].
//!   Every table of the file rejects unknown keys, and its error lists the
//!   keys it knows ("unknown field `zz_probe`, expected one of `id`, …").
//!   Probing each table with a key that does not exist gives its keys;
//!   probing each of those as a table, then as an array of tables, tells
//!   tables from values. So the keys are found wherever the raw structs
//!   live, and the example configurations in `config/` check the probe;
//! - metrics: an agent's registry ([`cellwatch::metrics::Metrics`]) with a
//!   sample in every labelled family, rendered as `/metrics` renders it,
//!   and every `cellwatch_…` name written in the agent's sources.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::util::root;

// ---------------------------------------------------------------------------
// Pages and their fenced blocks.

/// `README.md` and every Markdown page under `docs/`.
fn pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "md") {
                out.push(p);
            }
        }
    }
    let mut out = vec![root().join("README.md")];
    walk(&root().join("docs"), &mut out);
    out
}

/// A fenced code block: its info string and its lines with their numbers.
struct Block {
    info: String,
    lines: Vec<(usize, String)>,
}

fn blocks(text: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut open: Option<(String, Block)> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        match &mut open {
            None => {
                if let Some(rest) = trimmed.strip_prefix("```") {
                    let fence = "```".to_string();
                    open = Some((
                        fence,
                        Block {
                            info: rest.trim().to_string(),
                            lines: Vec::new(),
                        },
                    ));
                }
            }
            Some((fence, block)) => {
                if trimmed.starts_with(fence.as_str()) {
                    out.push(std::mem::replace(
                        block,
                        Block {
                            info: String::new(),
                            lines: Vec::new(),
                        },
                    ));
                    open = None;
                } else {
                    block.lines.push((i + 1, line.to_string()));
                }
            }
        }
    }
    out
}

// ---------------------------------------------------------------------------
// Shell words, as far as the docs use the shell.

#[derive(Debug, PartialEq)]
enum Token {
    Word(String),
    /// `|`, `&&`, `;`, `>`, `<`, …: ends a command (or names a file).
    Op(String),
}

/// Splits one logical shell line into words and operators: quotes,
/// backslashes, `# comments`, and `$VAR` / `${VAR}` from `vars`
/// (unknown ones are empty, as in the shell; unquoted ones split on
/// whitespace).
fn tokens(line: &str, vars: &BTreeMap<String, String>) -> Result<Vec<Token>, String> {
    let mut out = Vec::new();
    let mut word = String::new();
    // A word exists even when empty if it had quotes ("").
    let mut started = false;
    let mut chars = line.chars().peekable();
    fn end(out: &mut Vec<Token>, word: &mut String, started: &mut bool) {
        if *started {
            out.push(Token::Word(std::mem::take(word)));
            *started = false;
        }
    }
    fn name(chars: &mut std::iter::Peekable<std::str::Chars<'_>>) -> String {
        let mut n = String::new();
        if chars.peek() == Some(&'{') {
            chars.next();
            for c in chars.by_ref() {
                if c == '}' {
                    break;
                }
                n.push(c);
            }
        } else {
            while let Some(&c) = chars.peek() {
                if c.is_ascii_alphanumeric() || c == '_' {
                    n.push(c);
                    chars.next();
                } else {
                    break;
                }
            }
        }
        n
    }
    while let Some(c) = chars.next() {
        match c {
            ' ' | '\t' => end(&mut out, &mut word, &mut started),
            '#' if !started => break,
            '\\' => {
                if let Some(n) = chars.next() {
                    word.push(n);
                    started = true;
                }
            }
            '\'' => {
                started = true;
                loop {
                    match chars.next() {
                        Some('\'') => break,
                        Some(c) => word.push(c),
                        None => return Err("unterminated '".into()),
                    }
                }
            }
            '"' => {
                started = true;
                loop {
                    match chars.next() {
                        Some('"') => break,
                        Some('\\') => match chars.next() {
                            Some(c @ ('"' | '\\' | '$' | '`')) => word.push(c),
                            Some(c) => {
                                word.push('\\');
                                word.push(c);
                            }
                            None => return Err("unterminated \"".into()),
                        },
                        Some('$') => {
                            let n = name(&mut chars);
                            word += vars.get(&n).map_or("", String::as_str);
                        }
                        Some(c) => word.push(c),
                        None => return Err("unterminated \"".into()),
                    }
                }
            }
            '$' => {
                let n = name(&mut chars);
                let value = vars.get(&n).cloned().unwrap_or_default();
                let mut fields = value.split_whitespace();
                if let Some(first) = fields.next() {
                    word += first;
                    started = true;
                    for f in fields {
                        end(&mut out, &mut word, &mut started);
                        word += f;
                        started = true;
                    }
                }
            }
            '|' | '&' | ';' | '>' | '<' => {
                end(&mut out, &mut word, &mut started);
                let mut op = c.to_string();
                while let Some(&n) = chars.peek() {
                    if matches!(n, '|' | '&' | '>') {
                        op.push(n);
                        chars.next();
                    } else {
                        break;
                    }
                }
                out.push(Token::Op(op));
            }
            c => {
                word.push(c);
                started = true;
            }
        }
    }
    end(&mut out, &mut word, &mut started);
    Ok(out)
}

/// `NAME=value` as a shell assignment.
fn assignment(word: &str) -> Option<(&str, &str)> {
    let (name, value) = word.split_once('=')?;
    let ok = !name.is_empty()
        && !name.starts_with(|c: char| c.is_ascii_digit())
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    ok.then_some((name, value))
}

/// A `cellwatch` command line found in a page.
struct Shown {
    place: String,
    text: String,
    args: Vec<String>,
}

/// The arguments after `cellwatch` in one simple command, if it runs
/// `cellwatch` (as `cellwatch`, a path to it, `cargo run -p cellwatch --`,
/// or a unit file's `ExecStart=…/cellwatch`).
fn cellwatch_args(words: &[String]) -> Option<Vec<String>> {
    let mut rest = words;
    // Leading assignments (`VAR=x cellwatch …`); a unit file's
    // `ExecStart=/usr/local/bin/cellwatch` is the command itself.
    while let Some((first, tail)) = rest.split_first() {
        match assignment(first) {
            Some((_, value)) if value.ends_with("cellwatch") => return Some(tail.to_vec()),
            Some(_) => rest = tail,
            None => break,
        }
    }
    let (first, tail) = rest.split_first()?;
    if first == "cellwatch" || first.ends_with("/cellwatch") {
        return Some(tail.to_vec());
    }
    if first == "cargo"
        && tail.first().is_some_and(|w| w == "run")
        && tail.windows(2).any(|w| w[0] == "-p" && w[1] == "cellwatch")
    {
        let dashes = tail.iter().position(|w| w == "--")?;
        return Some(tail[dashes + 1..].to_vec());
    }
    None
}

/// Every `cellwatch` command in the fenced blocks of `text` (blocks marked
/// `text` are output, not commands).
fn commands_in(file: &str, text: &str) -> Result<Vec<Shown>, String> {
    let mut out = Vec::new();
    for block in blocks(text) {
        if block.info == "text" {
            continue;
        }
        let mut vars = BTreeMap::new();
        let mut lines = block.lines.iter();
        while let Some((number, first)) = lines.next() {
            let mut logical = first.clone();
            while logical.ends_with('\\') {
                logical.pop();
                match lines.next() {
                    Some((_, next)) => logical += next,
                    None => break,
                }
            }
            let place = format!("{file}:{number}");
            let toks = tokens(&logical, &vars).map_err(|e| format!("{place}: {e}"))?;
            let mut simple: Vec<Vec<String>> = vec![Vec::new()];
            let mut redirect = false;
            for t in toks {
                match t {
                    // The file a redirection names is no argument.
                    Token::Word(_) if redirect => redirect = false,
                    Token::Word(w) => simple.last_mut().unwrap().push(w),
                    Token::Op(op) if op.starts_with('>') || op.starts_with('<') => redirect = true,
                    Token::Op(_) => simple.push(Vec::new()),
                }
            }
            for words in simple {
                if !words.is_empty() && words.iter().all(|w| assignment(w).is_some()) {
                    for w in &words {
                        let (n, v) = assignment(w).unwrap();
                        vars.insert(n.to_string(), v.to_string());
                    }
                    continue;
                }
                if let Some(args) = cellwatch_args(&words) {
                    out.push(Shown {
                        place: place.clone(),
                        text: logical.trim().to_string(),
                        args,
                    });
                }
            }
        }
    }
    Ok(out)
}

/// Clap's verdict on one command line: `None` if it parses.
fn clap_error(args: &[String]) -> Option<String> {
    use clap::Parser;
    let argv = std::iter::once("cellwatch".to_string()).chain(args.iter().cloned());
    match cellwatch::cli::Cli::try_parse_from(argv) {
        Ok(_) => None,
        Err(e)
            if matches!(
                e.kind(),
                clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion
            ) =>
        {
            None
        }
        Err(e) => Some(e.to_string().lines().next().unwrap_or_default().to_string()),
    }
}

#[test]
fn every_command_in_the_docs_parses() {
    let mut shown = Vec::new();
    for page in pages() {
        let file = page.strip_prefix(root()).unwrap().display().to_string();
        let text = std::fs::read_to_string(&page).unwrap();
        shown.extend(commands_in(&file, &text).unwrap());
    }
    let wrong: Vec<String> = shown
        .iter()
        .filter_map(|s| clap_error(&s.args).map(|e| format!("{}: {}\n    {e}", s.place, s.text)))
        .collect();
    assert!(
        wrong.is_empty(),
        "commands in the docs that cellwatch does not accept:\n{}",
        wrong.join("\n")
    );
    // Not a test that finds nothing: the quickstart alone shows a dozen.
    assert!(shown.len() > 40, "only {} commands found", shown.len());
    let subcommands: BTreeSet<&str> = shown
        .iter()
        .filter_map(|s| s.args.first().map(String::as_str))
        .collect();
    assert!(subcommands.len() > 15, "{subcommands:?}");
}

/// The reader of the docs' commands finds what a shell would run, and
/// clap refuses what cellwatch does not know.
#[test]
fn the_command_reader_splits_as_a_shell_does() {
    let page = "```sh\n\
        Z=\"--trust t.toml --plain\"   # two flags\n\
        cellwatch alarms --follow $Z  # a comment\n\
        cargo run -p cellwatch -- history --cell 'm 1' \\\n    --since 1h $Z\n\
        cellwatch discover opc.tcp://h:4840/ --pki-dir pki > cell.toml && zenohd -c x\n\
        curl -s localhost:9464/metrics | grep cellwatch_\n\
        cellwatch frobnicate --now\n\
        ```\n\
        ```text\ncellwatch is not run here\n```\n\
        ```ini\nExecStart=/usr/local/bin/cellwatch run a.toml\n```\n";
    let shown = commands_in("page.md", page).unwrap();
    let args: Vec<(String, Vec<String>)> = shown
        .iter()
        .map(|s| (s.place.clone(), s.args.clone()))
        .collect();
    let v = |s: &[&str]| s.iter().map(|w| w.to_string()).collect::<Vec<_>>();
    assert_eq!(
        args,
        [
            (
                "page.md:3".into(),
                v(&["alarms", "--follow", "--trust", "t.toml", "--plain"])
            ),
            (
                "page.md:4".into(),
                v(&["history", "--cell", "m 1", "--since", "1h", "--trust", "t.toml", "--plain"])
            ),
            (
                "page.md:6".into(),
                v(&["discover", "opc.tcp://h:4840/", "--pki-dir", "pki"])
            ),
            ("page.md:8".into(), v(&["frobnicate", "--now"])),
            ("page.md:14".into(), v(&["run", "a.toml"])),
        ]
    );
    let verdicts: Vec<bool> = shown
        .iter()
        .map(|s| clap_error(&s.args).is_none())
        .collect();
    assert_eq!(verdicts, [true, true, true, false, true]);
}

// ---------------------------------------------------------------------------
// The command-line reference.

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

// ---------------------------------------------------------------------------
// The configuration reference.

/// The parser's verdict on a configuration text: its problems, or `None`.
fn config_problems(text: &str) -> Option<String> {
    cellwatch::config::parse("probe.toml", text, &root(), &cellwatch::config::Disk)
        .err()
        .map(|e| e.to_string())
}

/// The keys the table at `path` knows, if it is a table whose unknown-key
/// error lists them. `arrays[i]` says whether `path[..=i]` is an array of
/// tables; `last_array` how to write the table itself.
fn keys_of(path: &[String], arrays: &[bool], last_array: bool) -> Option<Vec<String>> {
    let mut text = String::new();
    for end in 1..=path.len() {
        let dotted = path[..end].join(".");
        if end == path.len() {
            if last_array {
                text += &format!("[[{dotted}]]\n");
            } else {
                text += &format!("[{dotted}]\n");
            }
        } else if arrays.get(end - 1).copied().unwrap_or(false) {
            text += &format!("[[{dotted}]]\n");
        }
    }
    text += "zz_probe = 1\n";
    let problems = config_problems(&text)?;
    let message = problems
        .lines()
        .find(|l| l.contains("unknown field `zz_probe`"))?;
    let expected = message.split("unknown field `zz_probe`").nth(1)?;
    if expected.contains("there are no fields") {
        return Some(Vec::new());
    }
    let names = expected
        .split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect();
    Some(names)
}

/// What a key of the configuration file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Shape {
    /// A value (a string, a number, a list, or a map taken whole).
    Value,
    /// A table with keys of its own (`[opcua]`, `hh = { … }`).
    Table,
    /// An array of tables (`[[tags]]`).
    Array,
}

/// Every key the configuration parser knows, dotted (`checks.limit.hh`),
/// with its shape, found by probing the parser (see the module's doc).
fn parser_keys() -> BTreeMap<String, Shape> {
    fn walk(path: &mut Vec<String>, arrays: &mut Vec<bool>, out: &mut BTreeMap<String, Shape>) {
        let is_array = arrays.last().copied().unwrap_or(false);
        let keys = keys_of(path, arrays, is_array)
            .unwrap_or_else(|| panic!("{}: a table lists its keys", path.join(".")));
        for key in keys {
            path.push(key);
            let probe = |array: bool| {
                let mut a = arrays.clone();
                a.push(array);
                keys_of(path, &a, array).is_some()
            };
            let shape = if probe(false) {
                Shape::Table
            } else if probe(true) {
                Shape::Array
            } else {
                Shape::Value
            };
            out.insert(path.join("."), shape);
            if shape != Shape::Value {
                arrays.push(shape == Shape::Array);
                walk(path, arrays, out);
                arrays.pop();
            }
            path.pop();
        }
    }
    let mut out = BTreeMap::new();
    walk(&mut Vec::new(), &mut Vec::new(), &mut out);
    out
}

/// The keys in the first cell of every table row of `text`.
fn documented_keys(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for line in text.lines() {
        let Some(row) = line.strip_prefix('|') else {
            continue;
        };
        let first = row.split('|').next().unwrap_or_default();
        for key in first.split('`').skip(1).step_by(2) {
            out.insert(key.to_string());
        }
    }
    out
}

/// The keys an example configuration uses, dotted; values of keys the
/// parser takes as one value (a map of supervision times) are not
/// descended into.
fn keys_used(
    value: &toml::Value,
    prefix: &str,
    shapes: &BTreeMap<String, Shape>,
    out: &mut BTreeSet<String>,
) {
    match value {
        toml::Value::Table(t) => {
            for (k, v) in t {
                let path = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                out.insert(path.clone());
                if shapes.get(&path) != Some(&Shape::Value) {
                    keys_used(v, &path, shapes, out);
                }
            }
        }
        toml::Value::Array(a) => {
            for v in a {
                if v.is_table() {
                    keys_used(v, prefix, shapes, out);
                }
            }
        }
        _ => {}
    }
}

/// The cell configurations in `config/`, by path.
fn example_configs() -> Vec<(String, toml::Value)> {
    let mut out = Vec::new();
    for dir in ["config", "config/moulding"] {
        let mut files: Vec<PathBuf> = std::fs::read_dir(root().join(dir))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        files.sort();
        for f in files {
            let v: toml::Value = toml::from_str(&std::fs::read_to_string(&f).unwrap()).unwrap();
            if v.get("cell").is_some() {
                out.push((f.strip_prefix(root()).unwrap().display().to_string(), v));
            }
        }
    }
    out
}

#[test]
fn the_config_reference_lists_every_key_the_parser_knows() {
    let keys = parser_keys();
    // The probe found the file's shape, not nothing.
    for known in [
        "cell.id",
        "opcua.identity.kind",
        "tags.node_id",
        "checks.limit.hh.limit",
        "zenoh.tls.ca",
    ] {
        assert_eq!(keys.get(known), Some(&Shape::Value), "{known} in {keys:?}");
    }
    for (known, shape) in [
        ("tags", Shape::Array),
        ("checks.sfc", Shape::Array),
        ("opcua.identity", Shape::Table),
    ] {
        assert_eq!(keys.get(known), Some(&shape), "{known} in {keys:?}");
    }
    let text = std::fs::read_to_string(root().join("docs/reference/config.md")).unwrap();
    let documented = documented_keys(&text);
    let mut problems = Vec::new();
    for (key, shape) in &keys {
        if *shape == Shape::Value && !documented.contains(key) {
            problems.push(format!(
                "{key}: the parser knows it, the reference does not"
            ));
        }
    }
    for key in &documented {
        if !keys.contains_key(key) {
            problems.push(format!(
                "{key}: documented, but the parser does not know it"
            ));
        }
    }
    // The example configurations use no key the probe missed.
    let configs = example_configs();
    assert!(
        configs.len() >= 7,
        "{} example configurations",
        configs.len()
    );
    for (file, value) in &configs {
        let mut used = BTreeSet::new();
        keys_used(value, "", &keys, &mut used);
        for key in used {
            if !keys.contains_key(&key) {
                problems.push(format!(
                    "{file}: {key} is used but was not found by the probe"
                ));
            }
            if !documented.contains(&key) && keys.get(&key) == Some(&Shape::Value) {
                problems.push(format!("{file}: {key} is used but not documented"));
            }
        }
    }
    assert!(
        problems.is_empty(),
        "docs/reference/config.md:\n{}",
        problems.join("\n")
    );
}

/// Each key the reference documents, written in a configuration, is never
/// an unknown key to the parser (whatever else is wrong with that file).
#[test]
fn every_documented_config_key_is_accepted_by_the_parser() {
    let text = std::fs::read_to_string(root().join("docs/reference/config.md")).unwrap();
    // Tables and arrays as the probe found them; a key it did not find is
    // written as a value in plain tables, and the parser says what it is.
    let shapes = parser_keys();
    let shape = |k: &str| shapes.get(k).copied().unwrap_or(Shape::Value);
    let mut refused = Vec::new();
    for key in documented_keys(&text) {
        let parts: Vec<&str> = key.split('.').collect();
        let (leaf, parents) = parts.split_last().unwrap();
        let mut config = String::new();
        for end in 1..=parents.len() {
            let dotted = parents[..end].join(".");
            if shape(&dotted) == Shape::Array {
                config += &format!("[[{dotted}]]\n");
            }
        }
        if !parents.is_empty() {
            let dotted = parents.join(".");
            if shape(&dotted) != Shape::Array {
                config += &format!("[{dotted}]\n");
            }
        }
        let value = match shape(&key) {
            Shape::Value => "\"x\"",
            Shape::Table => "{}",
            Shape::Array => "[{}]",
        };
        config += &format!("{leaf} = {value}\n");
        if let Some(problems) = config_problems(&config) {
            if problems.contains("unknown field") {
                refused.push(format!("{key}:\n{config}{problems}"));
            }
        }
    }
    assert!(refused.is_empty(), "{}", refused.join("\n\n"));
}

// ---------------------------------------------------------------------------
// The metrics reference.

/// The metric families an agent exports, as `/metrics` renders them, with
/// a sample in every labelled family.
fn exported_metrics() -> BTreeSet<String> {
    use cellwatch_models::alarm::{AlarmKind, Severity};
    let m = cellwatch::metrics::Metrics::new("docs");
    m.raised("ese", AlarmKind::Switching, Severity::High);
    m.active_delta(AlarmKind::Switching, Severity::High, 1);
    m.state("running", "idle", 1.0);
    m.add_state_time("running", 1.0);
    m.culprit("ese", "high", "ESE", Some("X0.06"), None, true);
    m.command(None, false);
    m.refused("command", "busy");
    m.transition_seconds
        .with_label_values(&["line-001"])
        .observe(1.0);
    m.transition_window_seconds
        .with_label_values(&["line-001", "lo"])
        .set(1.0);
    m.transition_window_position
        .with_label_values(&["line-001"])
        .set(0.1);
    m.tag_value.with_label_values(&["t"]).set(1.0);
    m.opcua_requests.with_label_values(&["Read", "good"]).inc();
    m.sfc_step_active
        .with_label_values(&["sfc", "F1", "S2"])
        .set(1);
    m.render()
        .lines()
        .filter_map(|l| l.strip_prefix("# TYPE "))
        .filter_map(|l| l.split(' ').next())
        .map(str::to_string)
        .collect()
}

/// Every `cellwatch_…` metric name written in the agent's sources (the
/// console's, which exports no metric, name its session cookie so).
fn metric_names_in_sources() -> BTreeSet<String> {
    fn walk(dir: &Path, out: &mut BTreeSet<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.ends_with("agent/src/console") {
                continue;
            }
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&p).unwrap();
                for (at, _) in text.match_indices("\"cellwatch_") {
                    let name: String = text[at + 1..]
                        .chars()
                        .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_')
                        .collect();
                    if text[at + 1 + name.len()..].starts_with('"') {
                        out.insert(name);
                    }
                }
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(&root().join("agent/src"), &mut out);
    out
}

#[test]
fn the_metrics_reference_lists_every_metric() {
    let exported = exported_metrics();
    let declared = metric_names_in_sources();
    assert!(exported.len() > 30, "{exported:?}");
    let text = std::fs::read_to_string(root().join("docs/reference/metrics.md")).unwrap();
    let rows = documented_keys(&text);
    let named: BTreeSet<String> = text
        .match_indices("cellwatch_")
        .map(|(at, _)| {
            text[at..]
                .chars()
                .take_while(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_')
                .collect::<String>()
        })
        .collect();
    let mut problems = Vec::new();
    for m in exported.union(&declared) {
        if !rows.contains(m) {
            problems.push(format!("{m}: exported, but has no row"));
        }
    }
    for m in named.iter().filter(|m| m.len() > "cellwatch_".len()) {
        if !exported.contains(m) {
            problems.push(format!("{m}: named, but the agent exports no such metric"));
        }
    }
    assert!(
        problems.is_empty(),
        "docs/reference/metrics.md:\n{}",
        problems.join("\n")
    );
}

/// The OPC UA services the source counts requests of, as its sources name
/// them (`requests.answered("Read", …)`, `requests.status("Republish", …)`).
fn opcua_services_in_sources() -> BTreeSet<String> {
    fn walk(dir: &Path, out: &mut BTreeSet<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&p).unwrap();
                for call in [".answered(", ".status("] {
                    for (at, _) in text.match_indices(call) {
                        let rest = text[at + call.len()..].trim_start();
                        if let Some(name) = rest.strip_prefix('"').and_then(|r| r.split('"').next())
                        {
                            out.insert(name.to_string());
                        }
                    }
                }
            }
        }
    }
    let mut out = BTreeSet::new();
    walk(&root().join("agent/src/sources/opcua"), &mut out);
    out
}

/// Labels whose values are a fixed set the code names (not a check id, a
/// tag, a culprit or a version); the OPC UA requests' `result` is the
/// status code's name, of which the reference lists `good`.
const FIXED_LABELS: [&str; 8] = [
    "kind", "severity", "state", "action", "result", "service", "reason", "bound",
];

#[test]
fn the_metrics_reference_lists_every_label_value() {
    use cellwatch_models::alarm::{AlarmKind, Severity};
    // Every value the code gives each fixed label: the enums' every member,
    // the series made at start (machine states, refusals, Alertmanager's
    // results), the OPC UA services the source names.
    let m = cellwatch::metrics::Metrics::new("docs");
    for kind in AlarmKind::ALL {
        for severity in Severity::ALL {
            m.raised("c", kind, severity);
            m.active_delta(kind, severity, 1);
            m.culprit("c", severity.as_str(), "F", Some("X0.00"), None, true);
        }
    }
    let actions = cellwatch::operator::Action::ALL.map(Some);
    for action in actions.into_iter().chain([None]) {
        m.command(action, true);
        m.command(action, false);
    }
    let services = opcua_services_in_sources();
    assert!(services.len() >= 10, "{services:?}");
    for service in &services {
        m.opcua_requests.with_label_values(&[service, "good"]).inc();
    }
    for bound in ["lo", "hi"] {
        m.transition_window_seconds
            .with_label_values(&["line-001", bound])
            .set(1.0);
    }
    let text = std::fs::read_to_string(root().join("docs/reference/metrics.md")).unwrap();
    let row = |metric: &str| {
        ["", "_bucket", "_sum", "_count"].iter().find_map(|suffix| {
            let name = metric.strip_suffix(suffix)?;
            text.lines()
                .find(|l| l.starts_with(&format!("| `{name}` |")))
        })
    };
    let mut problems = BTreeSet::new();
    let mut checked = 0;
    for line in m.render().lines().filter(|l| !l.starts_with('#')) {
        let Some((metric, rest)) = line.split_once('{') else {
            continue;
        };
        let labels = rest.rsplit_once('}').map_or("", |(l, _)| l);
        for pair in labels.split("\",") {
            let Some((label, value)) = pair.split_once("=\"") else {
                continue;
            };
            let value = value.trim_end_matches('"');
            let open = metric == "cellwatch_opcua_requests_total" && label == "result";
            if !FIXED_LABELS.contains(&label) || (open && value != "good") {
                continue;
            }
            checked += 1;
            match row(metric) {
                Some(r) if r.contains(&format!("`{value}`")) => {}
                Some(_) => {
                    problems.insert(format!("{metric}: {label} `{value}` not in its row"));
                }
                None => {
                    problems.insert(format!("{metric}: no row"));
                }
            }
        }
    }
    assert!(checked > 200, "{checked} label values checked");
    assert!(
        problems.is_empty(),
        "docs/reference/metrics.md:\n{}",
        problems.into_iter().collect::<Vec<_>>().join("\n")
    );
}

// ---------------------------------------------------------------------------
// Links between the pages.

/// GitHub's anchor for a heading: lower case, punctuation dropped, spaces
/// as `-`.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == '-' || *c == '_' || *c == ' ')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a page's headings (outside code blocks).
fn anchors(text: &str) -> BTreeSet<String> {
    let mut fenced = false;
    let mut out = BTreeSet::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        } else if !fenced && line.starts_with('#') {
            out.insert(anchor(line.trim_start_matches('#')));
        }
    }
    out
}

#[test]
fn every_link_between_the_pages_leads_somewhere() {
    let mut broken = Vec::new();
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        let dir = page.parent().unwrap();
        for (at, _) in text.match_indices("](") {
            let target: String = text[at + 2..].chars().take_while(|&c| c != ')').collect();
            if target.contains("://") || target.contains(' ') {
                continue;
            }
            let (path, fragment) = target.split_once('#').unwrap_or((&target, ""));
            let file = if path.is_empty() {
                page.clone()
            } else {
                dir.join(path)
            };
            let place = page.strip_prefix(root()).unwrap().display();
            if !file.exists() {
                broken.push(format!("{place}: {target}: no such file"));
            } else if !fragment.is_empty() && file.extension().is_some_and(|e| e == "md") {
                let there = std::fs::read_to_string(&file).unwrap();
                if !anchors(&there).contains(fragment) {
                    broken.push(format!("{place}: {target}: no such heading"));
                }
            }
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}
