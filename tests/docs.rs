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

mod cli_reference;
mod commands;
mod config_reference;
mod links;
mod metrics_reference;

use std::collections::BTreeSet;
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
// Keys in the references' tables (the configuration's and the metrics').

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
