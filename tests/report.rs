//! Reports over a journal produced by a scripted run: the engine driven in
//! virtual time through a known day, its state changes journaled, then
//! `cellwatch report` in all three formats.

use std::time::Duration;

use cellwatch::config;
use cellwatch::journal::{Entry, Journal};
use cellwatch_models::engine::{CellEngine, EngineEvent, Reading, SwitchingChecks};
use cellwatch_models::signal::Signal;
use cellwatch_models::value::Num;

use crate::util::{cellwatch, root};

/// 2026-11-20T00:00:00Z.
const DAY: u64 = 1_795_132_800_000;
const MIN: u64 = 60_000;

async fn scripted_journal(path: &std::path::Path) {
    let c = config::load(&root().join("config/demo.toml")).unwrap();
    let mut e = CellEngine::new(
        &c.cell,
        c.engine_tags(),
        vec![Box::new(SwitchingChecks::new(c.switching.clone()))],
        c.state.clone(),
    )
    .unwrap();
    let j = Journal::start(
        path,
        &cellwatch::config::Keep::all(Duration::from_secs(10 * 365 * 86_400)),
        crate::util::NoCommits,
    )
    .unwrap();
    let mut rows = 0u64;
    let record = |events: Vec<EngineEvent>, out: &mut Vec<Entry>| {
        for ev in events {
            if let EngineEvent::State { state, kind, at } = ev {
                let (fault_type, element) = match &state {
                    cellwatch_models::engine::MachineState::Fault {
                        fault_type,
                        element,
                    } => (Some(fault_type.clone()), element.clone()),
                    _ => (None, None),
                };
                out.push(Entry::State {
                    at,
                    kind: kind.as_str().into(),
                    state: state.name().into(),
                    fault_type,
                    element,
                });
            }
        }
    };
    let mut entries = Vec::new();
    let set = |e: &mut CellEngine, a: &str, v: bool, at: u64| {
        let t = e.tag_index(&Signal::new(a)).unwrap();
        e.on_reading(t, Reading::Good(v), at, at).events
    };
    // 00:00 connected, the normal image: running.
    record(e.on_connection(true, DAY).events, &mut entries);
    for (file, text) in [
        ("ese", include_str!("../config/cnc/ese-normal.values")),
        ("csd", include_str!("../config/cnc/csd-normal.values")),
    ] {
        let _ = file;
        for line in text
            .lines()
            .filter(|l| l.contains(',') && !l.starts_with('#') && !l.starts_with("address"))
        {
            let (a, v) = line.split_once(',').unwrap();
            record(set(&mut e, a, v == "1", DAY), &mut entries);
        }
    }
    // The mode word says AUTO (the running rule reads `D104 == 1`).
    let mode = e.tag_index(&Signal::new("D104")).unwrap();
    record(
        e.on_reading(mode, Reading::Number(Num::Int(1)), DAY, DAY)
            .events,
        &mut entries,
    );
    // 01:00-01:30 the Y over-travel switch is open: ESE.
    record(set(&mut e, "X0.06", false, DAY + 60 * MIN), &mut entries);
    record(set(&mut e, "X0.06", true, DAY + 90 * MIN), &mut entries);
    // 03:00-04:00 machine not ready: idle.
    record(set(&mut e, "X200.00", false, DAY + 180 * MIN), &mut entries);
    record(set(&mut e, "X200.00", true, DAY + 240 * MIN), &mut entries);
    // 23:00 the PLC connection drops for the rest of the day.
    record(
        e.on_connection(false, DAY + 23 * 60 * MIN).events,
        &mut entries,
    );
    // Ten parts in the morning.
    for k in 0..10 {
        entries.push(Entry::Part {
            at: DAY + (300 + 10 * k) * MIN,
            count: 1,
        });
    }
    for entry in entries {
        j.write(entry).await.unwrap();
        rows += 1;
    }
    let mut committed = j.committed();
    committed.wait_for(|n| *n >= rows).await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn daily_and_monthly_reports_in_three_formats() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("journal.sqlite");
    scripted_journal(&db).await;
    let db = db.to_str().unwrap();
    let causes = root().join("config/stop-causes.toml");
    let causes = causes.to_str().unwrap();

    let r = cellwatch(&[
        "report",
        "daily",
        "--date",
        "2026-11-20",
        "--db",
        db,
        "--causes",
        causes,
        "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(
        v["total"],
        serde_json::json!({"running": 1290.0, "idle": 60.0, "fault": 30.0, "offline": 60.0})
    );
    assert_eq!(
        v["hours"][1],
        serde_json::json!({"running": 30.0, "idle": 0.0, "fault": 30.0, "offline": 0.0})
    );
    assert_eq!(
        v["hours"][3],
        serde_json::json!({"running": 0.0, "idle": 60.0, "fault": 0.0, "offline": 0.0})
    );
    assert_eq!(
        v["hours"][23],
        serde_json::json!({"running": 0.0, "idle": 0.0, "fault": 0.0, "offline": 60.0})
    );
    assert!((v["availability"].as_f64().unwrap() - 100.0 * 1290.0 / 1380.0).abs() < 1e-9);
    assert_eq!(
        v["stop_causes"],
        serde_json::json!([
            {"code": "05", "name": "stopped", "count": 1, "minutes": 60.0},
            {"code": "07", "name": "emergency stop (ESE)", "count": 1, "minutes": 30.0}
        ])
    );
    assert_eq!(v["production"], 10);

    let r = cellwatch(&[
        "report",
        "daily",
        "--date",
        "2026-11-20",
        "--db",
        db,
        "--causes",
        causes,
        "--csv",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let lines: Vec<&str> = r.stdout.lines().collect();
    assert_eq!(lines[0], "section,key,name,running_min,idle_min,fault_min,offline_min,stops,stop_min,availability_pct,parts,target");
    assert_eq!(lines[2], "hour,01,,30.0,0.0,30.0,0.0,,,,,");
    assert!(
        lines.contains(&"cause,07,\"emergency stop (ESE)\",,,,,1,30.0,,,"),
        "{}",
        r.stdout
    );
    assert_eq!(
        *lines.last().unwrap(),
        "total,day,,1290.0,60.0,30.0,60.0,,,93.5,10,"
    );

    let r = cellwatch(&[
        "report",
        "daily",
        "--date",
        "2026-11-20",
        "--db",
        db,
        "--causes",
        causes,
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("\n01       30.0      0.0     30.0      0.0\n"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("\nday    1290.0     60.0     30.0     60.0\n"),
        "{}",
        r.stdout
    );
    assert!(r.stdout.contains("availability: 93.5 %"), "{}", r.stdout);
    assert!(
        r.stdout
            .contains("  07  emergency stop (ESE)                1 stop      30.0 min"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout.ends_with(
            "production: 10 parts\norders (item / mould, target, made):\n  none known\n"
        ),
        "{}",
        r.stdout
    );

    let r = cellwatch(&[
        "report", "monthly", "--month", "2026-11", "--db", db, "--causes", causes, "--csv",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("\nday,2026-11-20,,1290.0,60.0,30.0,60.0,,,93.5,10,\n"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("\nday,2026-11-19,,0.0,0.0,0.0,1440.0,,,,0,\n"),
        "{}",
        r.stdout
    );
    let r = cellwatch(&[
        "report", "monthly", "--month", "2026-11", "--db", db, "--causes", causes, "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    assert_eq!(v["days"].as_array().unwrap().len(), 30);
    assert_eq!(v["production"], 10);
    let r = cellwatch(&[
        "report", "monthly", "--month", "2026-11", "--db", db, "--causes", causes,
    ]);
    assert!(
        r.stdout
            .contains("2026-11-20    1290.0     60.0     30.0     60.0     93.5      10"),
        "{}",
        r.stdout
    );

    // Bad input names itself.
    let r = cellwatch(&[
        "report",
        "daily",
        "--date",
        "20.11.2026",
        "--db",
        db,
        "--causes",
        causes,
    ]);
    assert_eq!(
        (r.code, r.stderr.as_str()),
        (2, "error: --date '20.11.2026': write it as 2026-11-21\n")
    );
    let r = cellwatch(&[
        "report",
        "daily",
        "--date",
        "2026-11-20",
        "--db",
        "nowhere.sqlite",
        "--causes",
        causes,
    ]);
    assert_eq!(
        (r.code, r.stderr.as_str()),
        (2, "error: --db 'nowhere.sqlite': no such journal\n")
    );
}
