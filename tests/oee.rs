//! A scripted shift in virtual time through a real agent (journal,
//! metrics over HTTP, the snapshot over the bus), stopped and started again
//! in the middle: the OEE the agent reports live, in its snapshot and in
//! `cellwatch report daily` is the one computed here from the journal's
//! rows by a computation of this test's own, and the one worked out by
//! hand from the script.
//!
//! The plant is at UTC+01:00; the shift `early` runs 06:00–14:00 local
//! with a break 10:00–10:15 (465 planned minutes); the ideal cycle is
//! one minute; idle stops under 5 min are small stops; rejects within
//! 10 min of a restart are start-up rejects. The script, local time, two
//! days ago:
//! - 05:30 connected, `RUN` on, `PARTS` 0 (the first value counts
//!   nothing), `REJ` 0, `JAM` off;
//! - 06:30 `PARTS` 20, 07:00 `PARTS` 50;
//! - 07:00–07:20 `JAM` on (the jam interlock ANDed with the run request
//!   makes the fault coil `JAMMED`: `fault`);
//! - 08:00–08:02 `RUN` off (a small stop, 2 min);
//! - 09:00–09:30 `RUN` off (a long stop, 30 min: a breakdown);
//! - 09:35 `REJ` 3 (start-up rejects), 11:00 `PARTS` 200, 11:30 `REJ` 5;
//! - 12:00 the agent stopped and started again on the same journal;
//! - 13:00 and 14:30 the figures read.
//!
//! By hand: run time 60 + 40 + 2 + 58 + 255 = 415 min (the break not
//! planned); breakdowns 20 + 30 = 50 min; 200 parts, 5 rejects.

use cellwatch::clock::Clock;
use cellwatch::sources::scripted::ScriptedSource;
use cellwatch::sources::SourceEvent;
use cellwatch_models::engine::{Reading, TagReading};
use cellwatch_models::value::Num;

const MIN: u64 = 60_000;
const H: u64 = 60 * MIN;
const CELL: &str = "oee-day";

fn config(dir: &std::path::Path) -> String {
    format!(
        r#"[cell]
id = "{CELL}"

[opcua]
endpoint = "opc.tcp://127.0.0.1:4840/"
pki_dir = "pki"
namespace_uri = "urn:cellwatch:test"

[zenoh]
listen = ["quic/127.0.0.1:0"]

[zenoh.tls]
ca = "pki-bus/ca.pem"
cert = "pki-bus/agent-{CELL}.pem"
key = "pki-bus/agent-{CELL}.key"

[journal]
path = "{journal}"

[metrics]
listen = "127.0.0.1:0"

[state]
running = "RUN"

[production]
counter = "PARTS"

[oee]
utc_offset = "+01:00"
ideal_cycle = "1m"
reject_counter = "REJ"

[[oee.shifts]]
name = "early"
start = "06:00"
end = "14:00"
breaks = ["10:00-10:15"]

[[tags]]
name = "run"
node_id = "ns=2;s=RUN"
address = "RUN"
type = "Boolean"

[[tags]]
name = "parts"
node_id = "ns=2;s=PARTS"
address = "PARTS"
type = "Int32"

[[tags]]
name = "rejects"
node_id = "ns=2;s=REJ"
address = "REJ"
type = "Int32"

[[tags]]
name = "jam"
node_id = "ns=2;s=JAM"
address = "JAM"
type = "Boolean"

[[checks.switching]]
id = "jammed"
program = "jam.il"
dialect = "iec"
coil = "JAMMED"
fault_type = "JAMMED"
"#,
        journal = dir.join("journal.sqlite").display()
    )
}

const RUN: usize = 0;
const PARTS: usize = 1;
const REJ: usize = 2;
const JAM: usize = 3;

fn reading(tag: usize, r: Reading, t: u64) -> SourceEvent {
    SourceEvent::Readings(
        vec![TagReading {
            tag,
            reading: r,
            source_time: t,
        }]
        .into(),
    )
}

fn int(v: i64) -> Reading {
    Reading::Number(Num::Int(v))
}

/// The metric's value for the cell in `scrape`.
fn gauge(scrape: &str, metric: &str) -> Option<f64> {
    scrape
        .lines()
        .find(|l| l.starts_with(&format!("{metric}{{")))
        .and_then(|l| l.rsplit(' ').next()?.parse().ok())
}

/// A loss's seconds in `scrape`.
fn loss(scrape: &str, name: &str) -> Option<f64> {
    scrape
        .lines()
        .find(|l| {
            l.starts_with("cellwatch_oee_loss_seconds{") && l.contains(&format!("loss=\"{name}\""))
        })
        .and_then(|l| l.rsplit(' ').next()?.parse().ok())
}

/// The shift's figures computed from the journal's rows alone: the state
/// history clipped to the shift less its break, `idle` stretches shorter
/// than 5 min counted as run time, the parts and rejects of the
/// production rows. `(planned, run, parts, rejects)`, ms and counts.
fn from_the_journal(db: &std::path::Path, shift: (u64, u64), pause: (u64, u64)) -> [u64; 4] {
    let c = rusqlite::Connection::open(db).unwrap();
    let mut rows: Vec<(u64, String)> = c
        .prepare("SELECT at_ms, state FROM state_history ORDER BY at_ms, seq")
        .unwrap()
        .query_map([], |r| Ok((r.get::<_, i64>(0)? as u64, r.get(1)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    // Stretches of one state, the same state repeated being one.
    rows.dedup_by(|b, a| a.1 == b.1);
    let planned_in = |from: u64, to: u64| {
        let (from, to) = (from.max(shift.0), to.min(shift.1));
        if from >= to {
            return 0;
        }
        let overlap = to.min(pause.1).saturating_sub(from.max(pause.0));
        to - from - overlap
    };
    let mut run = 0;
    for (i, (at, state)) in rows.iter().enumerate() {
        let until = rows.get(i + 1).map_or(shift.1, |n| n.0);
        let small_stop = state == "idle" && until - at < 5 * MIN;
        if state == "running" || small_stop {
            run += planned_in(*at, until);
        }
    }
    let (parts, rejects): (i64, i64) = c
        .query_row(
            "SELECT coalesce(sum(parts), 0), coalesce(sum(rejects), 0) FROM production \
             WHERE at_ms >= ?1 AND at_ms < ?2",
            [shift.0 as i64, shift.1 as i64],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .unwrap();
    [
        planned_in(shift.0, shift.1),
        run,
        parts as u64,
        rejects as u64,
    ]
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_shifts_oee_live_in_the_snapshot_and_in_the_report_is_the_journals() {
    let d = tempfile::tempdir().unwrap();
    crate::util::bus_pki(d.path(), &[&format!("agent-{CELL}"), "kim"]);
    let path = d.path().join("oee-day.toml");
    std::fs::write(&path, config(d.path())).unwrap();
    // The jam interlock ANDed with the run request: a fault while running.
    std::fs::write(d.path().join("jam.il"), "LD JAM\nAND RUN\nST JAMMED\n").unwrap();
    let db = d.path().join("journal.sqlite");
    // Two days ago (the journal keeps what is younger than its retention,
    // by the machine's clock); 00:00 local is 23:00 UTC the day before.
    let day = chrono::Utc::now().date_naive() - chrono::Days::new(2);
    let midnight = day
        .and_hms_opt(0, 0, 0)
        .unwrap()
        .and_utc()
        .timestamp_millis() as u64
        - H;
    let at = |h: u64, m: u64| midnight + h * H + m * MIN;
    let clock = Clock::manual(at(5, 29));
    let start = async |clock: &Clock| {
        let (source, script) = ScriptedSource::new();
        let config = cellwatch::config::load(&path).unwrap();
        let agent = cellwatch::agent::start_with(
            config,
            cellwatch::agent::Options {
                source: Some(Box::new(source)),
                clock: clock.clone(),
                ..Default::default()
            },
        )
        .await
        .unwrap();
        script
            .send(SourceEvent::Connected("scripted".into()))
            .await
            .unwrap();
        (agent, script)
    };
    let (agent, script) = start(&clock).await;
    let mut committed = agent.committed();
    // The connection's row before the clock moves on: each change is
    // stamped when the loop takes it.
    crate::util::row_at(&mut committed, &db, "state_history", at(5, 29)).await;
    let t = at(5, 30);
    clock.set(t);
    script
        .send(SourceEvent::Readings(
            [
                (RUN, Reading::Good(true)),
                (PARTS, int(0)),
                (REJ, int(0)),
                (JAM, Reading::Good(false)),
            ]
            .into_iter()
            .map(|(tag, reading)| TagReading {
                tag,
                reading,
                source_time: t,
            })
            .collect::<Vec<_>>()
            .into(),
        ))
        .await
        .unwrap();
    crate::util::row_at(&mut committed, &db, "state_history", t).await;
    // Sets `tag` to `r` at `t` and waits for the journal's row of it.
    let set = async |script: &tokio::sync::mpsc::Sender<SourceEvent>,
                     committed: &mut tokio::sync::watch::Receiver<u64>,
                     tag: usize,
                     r: Reading,
                     t: u64,
                     table: &str| {
        clock.set(t);
        script.send(reading(tag, r, t)).await.unwrap();
        crate::util::row_at(committed, &db, table, t).await;
    };
    let c = &mut committed;
    set(&script, c, PARTS, int(20), at(6, 30), "production").await;
    set(&script, c, PARTS, int(50), at(7, 0), "production").await;
    set(
        &script,
        c,
        JAM,
        Reading::Good(true),
        at(7, 0),
        "state_history",
    )
    .await;
    set(
        &script,
        c,
        JAM,
        Reading::Good(false),
        at(7, 20),
        "state_history",
    )
    .await;
    set(
        &script,
        c,
        RUN,
        Reading::Good(false),
        at(8, 0),
        "state_history",
    )
    .await;
    set(
        &script,
        c,
        RUN,
        Reading::Good(true),
        at(8, 2),
        "state_history",
    )
    .await;
    set(
        &script,
        c,
        RUN,
        Reading::Good(false),
        at(9, 0),
        "state_history",
    )
    .await;
    set(
        &script,
        c,
        RUN,
        Reading::Good(true),
        at(9, 30),
        "state_history",
    )
    .await;
    set(&script, c, REJ, int(3), at(9, 35), "production").await;
    set(&script, c, PARTS, int(200), at(11, 0), "production").await;
    set(&script, c, REJ, int(5), at(11, 30), "production").await;

    // 12:00: what the metrics say, then the agent stopped and started
    // again; its live figures go on from the journal.
    let metrics_until =
        async |addr: std::net::SocketAddr, what: &str, ok: &dyn Fn(&str) -> bool| {
            let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(60);
            loop {
                let s = crate::util::scrape(addr).await;
                if ok(&s) {
                    return s;
                }
                assert!(tokio::time::Instant::now() < deadline, "{what}:\n{s}");
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        };
    // Until noon: planned 6 h less the break, run 295 min of it.
    let at_noon =
        |s: &str| gauge(s, "cellwatch_oee_availability").is_some_and(|a| close(a, 295.0 / 345.0));
    clock.set(at(12, 0));
    let before = metrics_until(agent.metrics_addr().unwrap(), "noon's figures", &at_noon).await;
    drop(script);
    agent.stop().await;
    let (agent, script) = start(&clock).await;
    let after = metrics_until(
        agent.metrics_addr().unwrap(),
        "noon's figures after the restart",
        &at_noon,
    )
    .await;
    for m in [
        "cellwatch_oee_availability",
        "cellwatch_oee_performance",
        "cellwatch_oee_quality",
        "cellwatch_oee_oee",
    ] {
        assert_eq!(
            gauge(&before, m),
            gauge(&after, m),
            "{m}:\n{before}\n{after}"
        );
    }
    // The PLC's values again (the counters count from them), seen in
    // the snapshot before the clock moves on.
    for (tag, v) in [(RUN, Reading::Good(true)), (PARTS, int(200)), (REJ, int(5))] {
        script.send(reading(tag, v, at(12, 0))).await.unwrap();
    }
    script
        .send(reading(JAM, Reading::Good(false), at(12, 0)))
        .await
        .unwrap();
    let port = crate::util::agent_port(&agent).await;
    let kim = crate::util::operator_session(d.path(), "kim", port).await;
    crate::spawned::cell_snapshot_until(&kim, CELL, "the values after the restart", |s| {
        s["tags"]
            .as_array()
            .unwrap()
            .iter()
            .all(|t| t["quality"] == "good")
            && s["state"] == "running"
    })
    .await;

    // 14:30: the shift is over; its figures stay until the next.
    clock.set(at(14, 30));
    let s = metrics_until(agent.metrics_addr().unwrap(), "the shift's end", &|s| {
        gauge(s, "cellwatch_oee_availability").is_some_and(|a| close(a, 415.0 / 465.0))
    })
    .await;
    assert!(
        close(
            gauge(&s, "cellwatch_oee_performance").unwrap(),
            200.0 / 415.0
        ),
        "{s}"
    );
    assert!(
        close(gauge(&s, "cellwatch_oee_quality").unwrap(), 195.0 / 200.0),
        "{s}"
    );
    assert!(
        close(
            gauge(&s, "cellwatch_oee_oee").unwrap(),
            415.0 / 465.0 * 200.0 / 415.0 * 195.0 / 200.0
        ),
        "{s}"
    );
    assert_eq!(loss(&s, "breakdowns"), Some(50.0 * 60.0), "{s}");
    assert_eq!(loss(&s, "small_stops"), Some(2.0 * 60.0), "{s}");
    assert_eq!(loss(&s, "reduced_speed"), Some(213.0 * 60.0), "{s}");

    // The snapshot says the same.
    let snap = crate::spawned::cell_snapshot_until(&kim, CELL, "the snapshot's OEE", |s| {
        s["oee"]["run_ms"] == 415 * MIN
    })
    .await;
    let o = &snap["oee"];
    assert_eq!(o["shift"], "early", "{o:#}");
    assert_eq!(o["from"], format!("{day}T05:00:00.000Z"), "{o:#}");
    assert_eq!(
        (&o["planned_ms"], &o["parts"], &o["rejects"]),
        (
            &serde_json::json!(465 * MIN),
            &serde_json::json!(200),
            &serde_json::json!(5)
        ),
        "{o:#}"
    );
    assert!(close(o["availability"].as_f64().unwrap(), 415.0 / 465.0));
    assert_eq!(o["losses"]["breakdowns_ms"], 50 * MIN, "{o:#}");
    drop(kim);
    drop(script);
    agent.stop().await;

    // The journal, read here: the same times and counts.
    let [planned, run, parts, rejects] =
        from_the_journal(&db, (at(6, 0), at(14, 0)), (at(10, 0), at(10, 15)));
    assert_eq!(
        [planned, run, parts, rejects],
        [465 * MIN, 415 * MIN, 200, 5]
    );

    // And the report, with the plant's offset from the configuration.
    let report = crate::util::cellwatch(&[
        "report",
        "daily",
        "--date",
        &day.to_string(),
        "--json",
        "--db",
        db.to_str().unwrap(),
        "--config",
        path.to_str().unwrap(),
    ]);
    assert_eq!(report.code, 0, "{}", report.stderr);
    let r: serde_json::Value = serde_json::from_str(&report.stdout).unwrap();
    let shift = &r["oee"]["shifts"][0];
    assert_eq!(shift["shift"]["name"], "early", "{r:#}");
    let f = &shift["figures"];
    assert_eq!(
        [&f["planned_ms"], &f["run_ms"], &f["parts"], &f["rejects"]],
        [
            &serde_json::json!(planned),
            &serde_json::json!(run),
            &serde_json::json!(parts),
            &serde_json::json!(rejects)
        ],
        "{f:#}"
    );
    let ratio = |k: &str| f[k].as_f64().unwrap();
    assert!(close(ratio("availability"), run as f64 / planned as f64));
    assert!(close(
        ratio("performance"),
        (parts * MIN) as f64 / run as f64
    ));
    assert!(close(
        ratio("quality"),
        (parts - rejects) as f64 / parts as f64
    ));
    // The live figures named the breakdowns as the report does.
    assert_eq!(f["breakdowns"], o["breakdowns"], "{f:#}\n{o:#}");
    assert_eq!(f["breakdowns"].as_array().unwrap().len(), 2, "{f:#}");
    assert_eq!(f["losses"]["startup_rejects"], 3, "{f:#}");
    assert_eq!(f["losses"]["production_rejects"], 2, "{f:#}");
}

/// The report's CSV carries the OEE too, and the days are cut at the
/// plant's offset of `[oee]`: another `--utc-offset` is refused.
#[test]
fn the_reports_csv_has_the_oee_and_one_offset_cuts_days_and_shifts() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("oee-day.toml");
    std::fs::write(&path, config(d.path())).unwrap();
    std::fs::write(d.path().join("jam.il"), "LD JAM\nAND RUN\nST JAMMED\n").unwrap();
    let db = d.path().join("journal.sqlite");
    let conn = cellwatch::journal::open(&db).unwrap();
    drop(conn);
    let c = rusqlite::Connection::open(&db).unwrap();
    // 06:00-10:00 local (+01:00) running, then idle; 100 parts, 4 rejects.
    let day = chrono::Utc::now().date_naive() - chrono::Days::new(2);
    let six = day
        .and_hms_opt(5, 0, 0)
        .unwrap()
        .and_utc()
        .timestamp_millis();
    c.execute(
        "INSERT INTO state_history (at_ms, kind, state) VALUES (?1, 'normal', 'running'), (?2, 'normal', 'idle')",
        [six, six + 4 * H as i64],
    )
    .unwrap();
    c.execute(
        "INSERT INTO production (at_ms, parts, rejects) VALUES (?1, 100, 4)",
        [six + H as i64],
    )
    .unwrap();
    drop(c);
    let date = day.to_string();
    let report = |extra: &[&str]| {
        let mut args = vec![
            "report",
            "daily",
            "--date",
            &date,
            "--db",
            db.to_str().unwrap(),
            "--config",
            path.to_str().unwrap(),
        ];
        args.extend(extra);
        crate::util::cellwatch(&args)
    };
    let csv = report(&["--csv"]);
    assert_eq!(csv.code, 0, "{}", csv.stderr);
    let lines: Vec<&str> = csv.stdout.lines().collect();
    assert!(lines[0].ends_with(",rejects"), "{}", csv.stdout);
    let width = lines[0].split(',').count();
    assert!(
        lines.iter().all(|l| l.split(',').count() == width),
        "{}",
        csv.stdout
    );
    // 240 of 465 planned minutes run; 100 parts of 1 min in 240 min.
    let shift = lines
        .iter()
        .find(|l| l.starts_with("oee-shift,"))
        .unwrap_or_else(|| panic!("{}", csv.stdout));
    assert_eq!(
        *shift,
        format!("oee-shift,{day},\"early\",,,,,,,51.6,100,,41.7,96.0,20.6,465.0,240.0,0.0,4"),
    );
    let table = report(&[]);
    assert_eq!(table.code, 0, "{}", table.stderr);
    assert!(table.stdout.contains("(UTC+01:00)"), "{}", table.stdout);
    let other = report(&["--utc-offset", "+02:00"]);
    assert_eq!(other.code, 2, "{}", other.stdout);
    assert!(
        other
            .stderr
            .contains("--utc-offset '+02:00' is not the plant's offset")
            && other.stderr.contains("oee.utc_offset = \"+01:00\""),
        "{}",
        other.stderr
    );
    assert_eq!(report(&["--utc-offset", "+01:00"]).code, 0);
}

/// A PackML machine (OPC 30050 `StateCurrent` as a number tag): Execute
/// is running, Held is a planned stop (a machine mode), Suspended and
/// Stopped are stops. Its shift's availability, from the machine's own
/// states, is the one worked out by hand.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_packml_machines_own_states_give_its_availability() {
    let d = tempfile::tempdir().unwrap();
    crate::util::bus_pki(d.path(), &["agent-packml"]);
    let db = d.path().join("journal.sqlite");
    let path = d.path().join("packml.toml");
    std::fs::write(
        &path,
        format!(
            r#"[cell]
id = "packml"

[opcua]
endpoint = "opc.tcp://127.0.0.1:4840/"
pki_dir = "pki"
namespace_uri = "urn:cellwatch:test"

[zenoh]
listen = ["quic/127.0.0.1:0"]

[zenoh.tls]
ca = "pki-bus/ca.pem"
cert = "pki-bus/agent-packml.pem"
key = "pki-bus/agent-packml.key"

[journal]
path = "{}"

[metrics]
listen = "127.0.0.1:0"

[state]
running = "STATE_CURRENT == 6"

[[state.modes]]
id = "held"
when = "STATE_CURRENT == 11"
suppress = ["pressure-l"]

[oee]
ideal_cycle = "1m"
planned_stops = ["held"]

[[oee.shifts]]
name = "early"
start = "06:00"
end = "14:00"
breaks = ["10:00-10:15"]

[[tags]]
name = "state"
node_id = "ns=2;s=StateCurrent"
address = "STATE_CURRENT"
type = "Int32"

[[tags]]
name = "pressure"
node_id = "ns=2;s=Pressure"
address = "PRESSURE"
type = "Double"

[[checks.limit]]
id = "pressure"
tag = "PRESSURE"
l = {{ limit = 2.0 }}
"#,
            db.display()
        ),
    )
    .unwrap();
    let day = chrono::Utc::now().date_naive() - chrono::Days::new(2);
    let midnight = day
        .and_hms_opt(0, 0, 0)
        .unwrap()
        .and_utc()
        .timestamp_millis() as u64;
    let at = |h: u64, m: u64| midnight + h * H + m * MIN;
    let clock = Clock::manual(at(5, 29));
    let (source, script) = ScriptedSource::new();
    let agent = cellwatch::agent::start_with(
        cellwatch::config::load(&path).unwrap(),
        cellwatch::agent::Options {
            source: Some(Box::new(source)),
            clock: clock.clone(),
            ..Default::default()
        },
    )
    .await
    .unwrap();
    let mut committed = agent.committed();
    script
        .send(SourceEvent::Connected("scripted".into()))
        .await
        .unwrap();
    // The connection's row before the clock moves on: each change is
    // stamped when the loop takes it.
    crate::util::row_at(&mut committed, &db, "state_history", at(5, 29)).await;
    clock.set(at(5, 30));
    script
        .send(SourceEvent::Readings(
            [(0, int(6)), (1, Reading::Number(Num::Float(5.0)))]
                .into_iter()
                .map(|(tag, reading)| TagReading {
                    tag,
                    reading,
                    source_time: at(5, 30),
                })
                .collect::<Vec<_>>()
                .into(),
        ))
        .await
        .unwrap();
    crate::util::row_at(&mut committed, &db, "state_history", at(5, 30)).await;
    // PackML states: 6 Execute, 11 Held, 5 Suspended, 2 Stopped.
    for (h, m, state, table) in [
        (7, 0, 11, "modes"),
        (7, 30, 6, "modes"),
        (8, 0, 5, "state_history"),
        (8, 10, 6, "state_history"),
        (12, 0, 2, "state_history"),
    ] {
        clock.set(at(h, m));
        script.send(reading(0, int(state), at(h, m))).await.unwrap();
        crate::util::row_at(&mut committed, &db, table, at(h, m)).await;
    }
    clock.set(at(14, 30));
    // Planned: 465 min less 30 held; run 60 + 30 + 215; stops 10 + 120.
    let addr = agent.metrics_addr().unwrap();
    let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(60);
    let s = loop {
        let s = crate::util::scrape(addr).await;
        if gauge(&s, "cellwatch_oee_availability").is_some_and(|a| close(a, 305.0 / 435.0)) {
            break s;
        }
        assert!(tokio::time::Instant::now() < deadline, "{s}");
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    };
    assert_eq!(loss(&s, "breakdowns"), Some(130.0 * 60.0), "{s}");
    drop(script);
    agent.stop().await;
    let [planned, run, _, _] =
        from_the_journal(&db, (at(6, 0), at(14, 0)), (at(10, 0), at(10, 15)));
    // The held half hour is in neither (the journal's own modes rows say
    // when): run time from the journal alone is the same.
    assert_eq!((planned - 30 * MIN, run), (435 * MIN, 305 * MIN));
}
