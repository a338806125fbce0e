//! A scripted alarm day in virtual time through a real agent (journal,
//! metrics over HTTP): the ISA-18.2 figures in the metrics as the day goes
//! and in `cellwatch report alarms` afterwards are the ones computed here
//! by hand from the script.
//!
//! Thirteen limit alarms `aNN-h` (tag `D2NN` above 50). The script, on
//! 2026-03-02 (UTC) unless said:
//! - 2026-03-01 10:00:01: a04 raised, never cleared (stale the next day);
//! - 00:01:00, 00:01:20, 00:01:50: a01 raised three times (chatters);
//! - 01:00:00 + k·30 s, k = 0..11: a01, a02, a03, a05..a13 raised once each
//!   (12 in one interval: a flood from the 11th raise, 01:05:00, until
//!   fewer than 5 are left in the window (ISA-18.2's hysteresis), when the
//!   eighth raise leaves it at 01:13:30: 510 s);
//! - 02:00:00 + k·50 s, k = 0..10: a02 raised 11 times (a flood from
//!   02:08:20 until the seventh raise leaves at 02:15:00: 400 s; not
//!   chattering, 50 s apart);
//! - 03:00:00: a03 raised, never cleared (21 h at the day's end: not stale);
//! - 10:00:00: a05 raised, cleared 10:05:00.
//!
//! Every other raise clears one second later.

use cellwatch::clock::Clock;
use cellwatch::sources::scripted::ScriptedSource;
use cellwatch::sources::SourceEvent;
use cellwatch_models::engine::{Reading, TagReading};
use cellwatch_models::value::Num;

const H: u64 = 3_600_000;

/// The metric's value (no labels besides the cell; counters summed over
/// their labels) in `scrape`.
fn sum_of(scrape: &str, metric: &str) -> f64 {
    scrape
        .lines()
        .filter(|l| l.starts_with(&format!("{metric}{{")))
        .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .sum()
}

fn config(dir: &std::path::Path) -> String {
    let mut c = format!(
        r#"[cell]
id = "kpi-day"

[opcua]
endpoint = "opc.tcp://127.0.0.1:4840/"
pki_dir = "pki"
namespace_uri = "urn:cellwatch:test"

[zenoh]
listen = ["quic/127.0.0.1:0"]

[zenoh.tls]
ca = "pki-bus/ca.pem"
cert = "pki-bus/agent-kpi-day.pem"
key = "pki-bus/agent-kpi-day.key"

[journal]
path = "{journal}"

[metrics]
listen = "127.0.0.1:0"
"#,
        journal = dir.join("journal.sqlite").display()
    );
    for n in 1..=13 {
        c += &format!(
            "\n[[tags]]\nname = \"a{n:02}\"\nnode_id = \"ns=2;s=D2{n:02}\"\naddress = \"D2{n:02}\"\ntype = \"Double\"\n"
        );
    }
    for n in 1..=13 {
        c += &format!(
            "\n[[checks.limit]]\nid = \"a{n:02}\"\ntag = \"D2{n:02}\"\nh = {{ limit = 50.0 }}\n"
        );
    }
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scripted_alarm_day_gives_the_kpis_and_the_report_computed_by_hand() {
    let d = tempfile::tempdir().unwrap();
    crate::util::bus_pki(d.path(), &["agent-kpi-day"]);
    let path = d.path().join("kpi-day.toml");
    std::fs::write(&path, config(d.path())).unwrap();
    let config = cellwatch::config::load(&path).unwrap();
    let db = config.journal.path.clone();
    let day = chrono::NaiveDate::from_ymd_opt(2026, 3, 2)
        .unwrap()
        .and_hms_opt(0, 0, 0)
        .unwrap()
        .and_utc()
        .timestamp_millis() as u64;
    let at = |h: u64, m: u64, s: u64| day + h * H + m * 60_000 + s * 1000;
    let clock = Clock::manual(day - 14 * H);
    let (source, script) = ScriptedSource::new();
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
    let metrics = agent.metrics_addr().unwrap();
    let mut committed = agent.committed();
    let value = |tag: usize, v: f64, t: u64| {
        SourceEvent::Readings(
            vec![TagReading {
                tag,
                reading: Reading::Number(Num::Float(v)),
                source_time: t,
            }]
            .into(),
        )
    };
    script
        .send(SourceEvent::Connected("scripted".into()))
        .await
        .unwrap();
    script
        .send(SourceEvent::Readings(
            (0..13)
                .map(|tag| TagReading {
                    tag,
                    reading: Reading::Number(Num::Float(0.0)),
                    source_time: day - 14 * H,
                })
                .collect::<Vec<_>>()
                .into(),
        ))
        .await
        .unwrap();
    // Sets `a<n>` to `v` at `t` and waits for the alarm event it makes.
    let mut set = async |n: usize, v: f64, t: u64| {
        clock.set(t);
        script.send(value(n - 1, v, t)).await.unwrap();
        crate::util::row_at(&mut committed, &db, "alarm_events", t).await;
    };
    // Waits until the metrics say what `ok` wants (at the clock's time,
    // which the loop's next tick brings).
    let metrics_until = async |what: &str, ok: &dyn Fn(&str) -> bool| {
        let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(30);
        loop {
            let s = crate::util::scrape(metrics).await;
            if ok(&s) {
                return s;
            }
            assert!(tokio::time::Instant::now() < deadline, "{what}:\n{s}");
            tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        }
    };

    set(4, 60.0, day - 14 * H + 1000).await;
    for s in [60, 80, 110] {
        set(1, 60.0, day + s * 1000).await;
        set(1, 0.0, day + (s + 1) * 1000).await;
    }
    clock.set(at(0, 1, 55));
    metrics_until("a01 chattering", &|s| {
        sum_of(s, "cellwatch_alarms_chattering") == 1.0
    })
    .await;
    clock.set(at(0, 2, 0));
    metrics_until("a01 no longer chattering", &|s| {
        sum_of(s, "cellwatch_alarms_chattering") == 0.0
    })
    .await;
    let flood = [1, 2, 3, 5, 6, 7, 8, 9, 10, 11, 12, 13];
    for (k, n) in flood.into_iter().enumerate() {
        let t = at(1, 0, 0) + k as u64 * 30_000;
        set(n, 60.0, t).await;
        set(n, 0.0, t + 1000).await;
    }
    let s = metrics_until("the first flood", &|s| {
        sum_of(s, "cellwatch_alarm_rate_10m") == 12.0
    })
    .await;
    assert_eq!(sum_of(&s, "cellwatch_alarm_flood"), 1.0, "{s}");
    for k in 0..11 {
        let t = at(2, 0, 0) + k * 50_000;
        set(2, 60.0, t).await;
        set(2, 0.0, t + 1000).await;
    }
    set(3, 60.0, at(3, 0, 0)).await;
    set(5, 60.0, at(10, 0, 0)).await;
    set(5, 0.0, at(10, 5, 0)).await;
    clock.set(day + 24 * H);
    let s = metrics_until("the day's end", &|s| {
        sum_of(s, "cellwatch_alarm_rate_10m") == 0.0 && sum_of(s, "cellwatch_alarms_stale") == 1.0
    })
    .await;
    // By hand: 510 s + 400 s of flood; 28 raises on the day and a04's the
    // day before; a04 (38 h) stale, a03 (21 h) not.
    assert_eq!(
        sum_of(&s, "cellwatch_alarm_flood_seconds_total"),
        910.0,
        "{s}"
    );
    assert_eq!(sum_of(&s, "cellwatch_alarm_flood"), 0.0, "{s}");
    assert_eq!(sum_of(&s, "cellwatch_alarms_raised_total"), 29.0, "{s}");
    assert_eq!(sum_of(&s, "cellwatch_alarms_chattering"), 0.0, "{s}");
    drop(script);
    agent.stop().await;

    let report = |format: Option<&str>| {
        let mut args = vec!["report", "alarms", "--date", "2026-03-02", "--db"];
        args.push(db.to_str().unwrap());
        args.extend(format);
        crate::util::cellwatch(&args)
    };
    let run = report(Some("--json"));
    assert_eq!(run.code, 0, "{}", run.stderr);
    let r: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    let close = |v: &serde_json::Value, x: f64| (v.as_f64().unwrap() - x).abs() < 1e-9;
    assert_eq!(r["raised"], 28, "{r:#}");
    assert_eq!(r["intervals"], 144);
    assert!(close(&r["average_rate"], 28.0 / 144.0), "{r:#}");
    assert_eq!(r["peak_rate"], 12);
    assert_eq!(r["flood_intervals"], 2);
    // No alarm of the day follows from another: the first-outs are every
    // raise, and flood as often.
    assert_eq!(
        (&r["first_outs"], &r["first_out_flood_intervals"]),
        (&serde_json::json!(28), &serde_json::json!(2)),
        "{r:#}"
    );
    assert!(close(&r["flood_percent"], 200.0 / 144.0), "{r:#}");
    let top: Vec<(&str, u64)> = r["top"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| (f["id"].as_str().unwrap(), f["raised"].as_u64().unwrap()))
        .collect();
    assert_eq!(
        top,
        [
            ("a02-h", 12),
            ("a01-h", 4),
            ("a03-h", 2),
            ("a05-h", 2),
            ("a06-h", 1),
            ("a07-h", 1),
            ("a08-h", 1),
            ("a09-h", 1),
            ("a10-h", 1),
            ("a11-h", 1)
        ]
    );
    assert!(close(&r["top_share"], 100.0 * 26.0 / 28.0), "{r:#}");
    assert!(close(&r["top"][0]["share"], 100.0 * 12.0 / 28.0));
    assert_eq!(r["chattering"][0]["id"], "a01-h");
    assert_eq!(r["chattering"][0]["raises_in_window"], 3);
    assert_eq!(r["chattering"].as_array().unwrap().len(), 1);
    assert_eq!(r["stale"].as_array().unwrap().len(), 1, "{r:#}");
    assert_eq!(r["stale"][0]["id"], "a04-h");
    assert!(close(&r["stale"][0]["hours"], 38.0 - 1.0 / 3600.0), "{r:#}");
    assert!(close(&r["priorities"]["high"], 100.0));
    let verdicts: Vec<(&str, Option<bool>)> = r["benchmarks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| (b["metric"].as_str().unwrap(), b["met"].as_bool()))
        .collect();
    assert_eq!(verdicts[0], ("average alarm rate (per 10 min)", Some(true)));
    assert_eq!(verdicts[1].1, Some(false), "peak 12 > 10");
    assert_eq!(verdicts[2].1, Some(false), "1.4 % of intervals in flood");
    // The same as a table and as CSV.
    let table = report(None);
    assert_eq!(table.code, 0, "{}", table.stderr);
    assert!(
        table.stdout.contains("28 alarms in 144 intervals")
            && table.stdout.contains("a04-h")
            && table.stdout.contains("38.0 h"),
        "{}",
        table.stdout
    );
    let csv = report(Some("--csv"));
    assert!(
        csv.stdout
            .lines()
            .any(|l| l == "\"peak alarm rate (per 10 min)\",\"12\",\"<= 10\",no"),
        "{}",
        csv.stdout
    );

    // The plant's own rules, from the cell's [kpi]: a flood above 11, a
    // chatter within 30 s, stale after 12 h.
    let own = d.path().join("own-rules.toml");
    std::fs::write(
        &own,
        std::fs::read_to_string(&path).unwrap()
            + "\n[kpi]\nflood_raises = 11\nchatter_window = \"30s\"\nstale_after = \"12h\"\n",
    )
    .unwrap();
    let run = crate::util::cellwatch(&[
        "report",
        "alarms",
        "--date",
        "2026-03-02",
        "--json",
        "--db",
        db.to_str().unwrap(),
        "--config",
        own.to_str().unwrap(),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let r: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    // Only 01:00's 12 is a flood now; a01's raises 20 s and 30 s apart are
    // two within 30 s at most; a03 (21 h) is stale as well as a04.
    assert_eq!(r["flood_intervals"], 1, "{r:#}");
    assert_eq!(r["chattering"].as_array().unwrap().len(), 0, "{r:#}");
    assert_eq!(r["stale"].as_array().unwrap().len(), 2, "{r:#}");
    assert_eq!(r["rules"]["flood_ends_below"], 6, "{r:#}");
    assert_eq!(
        r["benchmarks"][5]["metric"],
        "chattering alarms (3+ raises in 30 s)"
    );
}
