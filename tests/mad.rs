//! `cellwatch mad export` on the shipped cells: every alarm the cell can
//! raise is a row, once; the CSV and the JSON are the same rows; a mode's
//! designed suppression and a check's culprits with their comments are
//! written where a rationalisation team reads them. `cellwatch mad import`
//! takes the rationalised file back (shown as changes, `--dry-run` writing
//! nothing, every mistake at its row and column), and a later export keeps
//! the rationalisation and marks what is new, gone or changed.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

use crate::util::root;

type Row = BTreeMap<String, String>;

const COLUMNS: [&str; 17] = [
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
    "status",
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

/// The demo cell in `dir` with its program files found, its database
/// `madb.csv`.
fn demo_cell(dir: &std::path::Path) -> std::path::PathBuf {
    let demo = std::fs::read_to_string(root().join("config/demo.toml")).unwrap();
    let config = demo
        .replace(
            "program = \"cnc/",
            &format!("program = \"{}/config/cnc/", root().display()),
        )
        .replace(
            "comments = \"cnc/",
            &format!("comments = \"{}/config/cnc/", root().display()),
        )
        .replace(
            "[alarms.consequences]",
            "[alarms]\ndatabase = \"madb.csv\"\n\n[alarms.consequences]",
        );
    let path = dir.join("cell.toml");
    std::fs::write(&path, config).unwrap();
    path
}

fn cellwatch(args: &[&std::ffi::OsStr]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn write_rows(path: &std::path::Path, rows: &[Row]) {
    let mut w = csv::Writer::from_path(path).unwrap();
    w.write_record(COLUMNS).unwrap();
    for r in rows {
        w.write_record(
            COLUMNS
                .iter()
                .map(|c| r.get(*c).cloned().unwrap_or_default()),
        )
        .unwrap();
    }
    w.flush().unwrap();
}

#[test]
fn a_rationalised_file_comes_back_as_the_cells_and_a_later_export_keeps_it() {
    let d = tempfile::tempdir().unwrap();
    let config = demo_cell(d.path());
    let madb = d.path().join("madb.csv");
    // An empty database (its header only): every alarm is new.
    std::fs::write(&madb, COLUMNS.join(",") + "\n").unwrap();
    let (_, mut rows) = csv_rows(&export(&config, "csv"));
    assert!(rows.iter().all(|r| r["status"] == "new"), "{rows:?}");
    for r in rows.iter_mut().filter(|r| r["id"] == "ese") {
        r.insert("priority".into(), "high".into());
        r.insert("class".into(), "safety".into());
        r.insert(
            "corrective_action".into(),
            "Drive the axis off its limit switch in JOG, then reset".into(),
        );
        r.insert(
            "consequence_of_inaction".into(),
            "the machine stays stopped".into(),
        );
        r.insert("response_time".into(), "5m".into());
    }
    let rationalised = d.path().join("rationalised.csv");
    write_rows(&rationalised, &rows);
    let before = std::fs::read_to_string(&madb).unwrap();
    let (code, said, err) = cellwatch(&[
        "mad".as_ref(),
        "import".as_ref(),
        config.as_os_str(),
        rationalised.as_os_str(),
        "--dry-run".as_ref(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(
        said.lines().take(5).collect::<Vec<_>>(),
        [
            "ese: priority 'critical' -> 'high'",
            "ese: class 'fault' -> 'safety'",
            "ese: consequence_of_inaction - -> 'the machine stays stopped'",
            "ese: corrective_action - -> 'Drive the axis off its limit switch in JOG, then reset'",
            "ese: response_time - -> '5m'",
        ],
        "{said}"
    );
    assert!(said.contains("dry run"), "{said}");
    assert_eq!(std::fs::read_to_string(&madb).unwrap(), before);
    let (code, said, err) = cellwatch(&[
        "mad".as_ref(),
        "import".as_ref(),
        config.as_os_str(),
        rationalised.as_os_str(),
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(said.contains("wrote"), "{said}");
    // Exported again: the rationalisation kept, nothing new.
    let (_, again) = csv_rows(&export(&config, "csv"));
    let ese = again.iter().find(|r| r["id"] == "ese").unwrap();
    assert_eq!(
        (
            ese["priority"].as_str(),
            ese["class"].as_str(),
            ese["response_time"].as_str(),
            ese["status"].as_str()
        ),
        ("high", "safety", "5m", "")
    );
    assert!(again.iter().all(|r| r["status"].is_empty()), "{again:?}");
    // Imported again as it is: no change.
    let (code, said, _) = cellwatch(&[
        "mad".as_ref(),
        "import".as_ref(),
        config.as_os_str(),
        rationalised.as_os_str(),
        "--dry-run".as_ref(),
    ]);
    assert_eq!(
        (code, said.lines().next()),
        (
            Some(0),
            Some("0 changes; dry run: ".to_string() + &madb.display().to_string() + " not written")
                .as_deref()
        )
    );
    // The logic changed under the database: a row for an alarm gone, a
    // condition that is not the one rationalised, an alarm with no row.
    let mut kept: Vec<Row> = again.into_iter().filter(|r| r["id"] != "csd").collect();
    for r in kept.iter_mut().filter(|r| r["id"] == "ese") {
        r.insert(
            "condition".into(),
            "fault while G8.02 is on; as it was".into(),
        );
    }
    let mut old = kept[0].clone();
    old.insert("id".into(), "spindle-vibration".into());
    kept.push(old);
    write_rows(&madb, &kept);
    let (_, marked) = csv_rows(&export(&config, "csv"));
    let status = |id: &str| marked.iter().find(|r| r["id"] == id).unwrap()["status"].clone();
    assert_eq!(
        (
            status("csd"),
            status("ese"),
            status("spindle-vibration"),
            status("journal")
        ),
        ("new".into(), "changed".into(), "gone".into(), String::new())
    );
}

#[test]
fn every_mistake_of_an_imported_file_is_said_at_its_row_and_column_and_nothing_written() {
    let d = tempfile::tempdir().unwrap();
    let config = demo_cell(d.path());
    let bad = d.path().join("bad.csv");
    let import = |file: &std::path::Path| {
        cellwatch(&[
            "mad".as_ref(),
            "import".as_ref(),
            config.as_os_str(),
            file.as_os_str(),
        ])
    };
    std::fs::write(
        &bad,
        COLUMNS.join(",") + "\nese,switching,urgent,safety,,,,,,0s,0s,no,ESE,,,soon,\n",
    )
    .unwrap();
    let (code, _, err) = import(&bad);
    assert_eq!(code, Some(2));
    let name = bad.display().to_string();
    assert!(
        err.contains(&format!(
            "{name}:2:3: column 'priority': 'urgent' is no priority"
        )),
        "{err}"
    );
    assert!(
        err.contains(&format!("{name}:2:16: column 'response_time': 'soon'")),
        "{err}"
    );
    std::fs::write(
        &bad,
        COLUMNS.join(",") + "\nesx,switching,high,safety,,,,,,0s,0s,no,ESE,,,5m,\n",
    )
    .unwrap();
    let (code, _, err) = import(&bad);
    assert_eq!(code, Some(2));
    assert!(
        err.contains(&format!(
            "{name}:2:1: column 'id': 'esx' is no alarm of this cell"
        )),
        "{err}"
    );
    std::fs::write(&bad, "id,priority\nese,high\n").unwrap();
    let (code, _, err) = import(&bad);
    assert_eq!(code, Some(2));
    assert!(
        err.contains(&format!("{name}:1:1: no column 'class'")),
        "{err}"
    );
    assert!(!d.path().join("madb.csv").exists());
}
