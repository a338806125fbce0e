//! Every `cellwatch` command shown in the docs parses, read from its fenced
//! block as far as the docs use the shell.

use std::collections::{BTreeMap, BTreeSet};

use crate::util::root;

use super::{blocks, pages};

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
