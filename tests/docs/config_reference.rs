//! The configuration reference (`docs/reference/config.md`) lists every key
//! the parser knows, and the parser accepts every key it documents.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use crate::util::root;

use super::documented_keys;

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
