//! Configuration tests of `alarms.database`: the cell's master alarm
//! database read, each problem at its line and column, and its rows given
//! to the engine (a row naming no alarm refused when it is built).

use super::*;

fn with_database(csv: &str) -> (String, Mem) {
    let mut files = mem();
    files
        .0
        .insert(PathBuf::from("base/madb.csv"), csv.as_bytes().to_vec());
    (
        format!("{GOOD}\n[alarms]\ndatabase = \"madb.csv\"\n"),
        files,
    )
}

const HEADER: &str = "id,priority,class,consequence_of_inaction,corrective_action,response_time\n";

#[test]
fn a_database_gives_its_alarms_their_priority_and_guidance() {
    let (text, files) = with_database(&format!(
        "{HEADER}fig6,low,quality,scrap,Clean the sensor,10m\ncommunication,,system,,Check the cable,\n"
    ));
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    let (path, db) = c.database.as_ref().unwrap();
    assert_eq!(path, Path::new("base/madb.csv"));
    assert_eq!(db.rows["fig6"].guidance.response_time_ms, Some(600_000));
    let engine = crate::cell::compile::engine(&c).unwrap();
    let fig6 = engine
        .catalogue()
        .into_iter()
        .find(|e| e.id == "fig6")
        .unwrap();
    assert_eq!(fig6.severity.as_str(), "low");
}

#[test]
fn a_bad_database_is_an_error_at_its_line_and_column() {
    let (text, files) = with_database(&format!("{HEADER}fig6,urgent,,,,\n"));
    assert_eq!(
        parse("cell.toml", &text, Path::new("base"), &files)
            .unwrap_err()
            .to_string(),
        "base/madb.csv:2:2: column 'priority': 'urgent' is no priority: low, medium, high or critical"
    );
    let (text, files) = with_database(&format!("{HEADER}fig7,high,,,,\n"));
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    let Err(e) = crate::cell::compile::engine(&c) else {
        panic!("fig7 taken");
    };
    assert_eq!(
        e.to_string(),
        "base/madb.csv:2:1: column 'id': 'fig7' is no alarm of this cell (`cellwatch mad export` lists them)"
    );
    let text = format!("{GOOD}\n[alarms]\ndatabase = \"none.csv\"\n");
    let e = errors(&text);
    assert!(e.starts_with("cell.toml:"), "{e}");
    assert!(
        e.contains("alarms.database: cannot read the master alarm database 'base/none.csv'"),
        "{e}"
    );
}
