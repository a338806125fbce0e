//! `cellwatch mad export` on the shipped cells: every alarm the cell can
//! raise is a row, once; the CSV and the JSON are the same rows; a mode's
//! designed suppression and a check's culprits with their comments are
//! written where a rationalisation team reads them.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

use crate::util::root;

type Row = BTreeMap<String, String>;

const COLUMNS: [&str; 16] = [
    "id",
    "kind",
    "priority",
    "class",
    "condition",
    "culprits",
    "causes",
    "effects",
    "suppressed_in_modes",
    "on_delay",
    "off_delay",
    "latched",
    "fault_type",
    "consequence_of_inaction",
    "corrective_action",
    "response_time",
];

/// `cellwatch mad export CONFIG --format FORMAT`'s standard output.
fn export(config: &std::path::Path, format: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["mad", "export"])
        .arg(config)
        .args(["--format", format])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}: {}",
        config.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn csv_rows(text: &str) -> (Vec<String>, Vec<Row>) {
    let mut r = csv::Reader::from_reader(text.as_bytes());
    let header = r.headers().unwrap().iter().map(str::to_string).collect();
    let rows = r.deserialize().map(Result::unwrap).collect();
    (header, rows)
}

#[test]
fn every_alarm_of_each_shipped_cell_is_one_row_the_same_in_csv_and_json() {
    for cell in ["demo", "line", "moulding", "robot"] {
        let path = root().join(format!("config/{cell}.toml"));
        let (header, rows) = csv_rows(&export(&path, "csv"));
        assert_eq!(header, COLUMNS, "{cell}");
        let json: Vec<Row> = serde_json::from_str(&export(&path, "json")).unwrap();
        assert_eq!(rows, json, "{cell}");
        let ids: Vec<&str> = rows.iter().map(|r| r["id"].as_str()).collect();
        let unique: BTreeSet<&str> = ids.iter().copied().collect();
        assert_eq!(ids.len(), unique.len(), "{cell}: {ids:?}");
        // Every alarm the engine can raise, and the agent's journal alarm.
        let config = cellwatch::config::load(&path).unwrap();
        let engine = cellwatch::cell::compile::engine(&config).unwrap();
        for entry in engine.catalogue() {
            let row = rows.iter().find(|r| r["id"] == entry.id);
            let row = row.unwrap_or_else(|| panic!("{cell}: no row for {}", entry.id));
            assert_eq!(
                row["priority"],
                entry.severity.as_str(),
                "{cell} {}",
                entry.id
            );
            assert!(
                !row["condition"].is_empty(),
                "{cell} {}: no condition",
                entry.id
            );
            for column in [
                "consequence_of_inaction",
                "corrective_action",
                "response_time",
            ] {
                assert_eq!(row[column], "", "{cell} {}", entry.id);
            }
        }
        assert!(unique.contains("journal"), "{cell}");
    }
}

#[test]
fn the_draft_says_the_condition_culprits_relation_and_designed_suppression() {
    let d = tempfile::tempdir().unwrap();
    let demo = std::fs::read_to_string(root().join("config/demo.toml")).unwrap();
    let config = demo
        .replace("program = \"cnc/", &format!("program = \"{}/config/cnc/", root().display()))
        .replace("comments = \"cnc/", &format!("comments = \"{}/config/cnc/", root().display()))
        .replace(
            "[zenoh]\n",
            "[[state.modes]]\nid = \"setup\"\nwhen = \"D104 == 2\"\nsuppress = [\"es*\"]\n\n[zenoh]\n",
        );
    let path = d.path().join("cell.toml");
    std::fs::write(&path, config).unwrap();
    let file = d.path().join("madb.csv");
    let status = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["mad", "export"])
        .arg(&path)
        .arg("--out")
        .arg(&file)
        .status()
        .unwrap();
    assert!(status.success());
    let (_, rows) = csv_rows(&std::fs::read_to_string(&file).unwrap());
    let row = |id: &str| rows.iter().find(|r| r["id"] == id).unwrap().clone();
    let ese = row("ese");
    assert_eq!(
        (
            ese["kind"].as_str(),
            ese["priority"].as_str(),
            ese["class"].as_str()
        ),
        ("switching", "critical", "fault")
    );
    assert!(
        ese["condition"].starts_with("fault while G8.02 is on; G8.02 = "),
        "{ese:?}"
    );
    assert!(
        ese["culprits"].contains("X0.06 (Y Over Travel Limit SW (B))"),
        "{ese:?}"
    );
    assert_eq!(ese["suppressed_in_modes"], "setup");
    // The discrete alarm on a limit switch is among ESE's causes.
    assert!(
        ese["causes"].split("; ").any(|c| c == "z2-overtravel"),
        "{ese:?}"
    );
    assert!(row("z2-overtravel")["effects"]
        .split("; ")
        .any(|e| e == "ese"));
    let limit = row("spindle-temp-h");
    assert!(
        limit["condition"].starts_with("D100 (spindle_temperature) > 85 °C"),
        "{limit:?}"
    );
    assert_eq!(row("communication")["off_delay"], "10s");
    assert_eq!(row("journal")["class"], "system");
}

#[test]
fn a_config_that_does_not_read_is_bad_input() {
    let out = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["mad", "export", "no-such-cell.toml"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no-such-cell.toml"));
}
