//! The flight recorder end to end: a fault injected on the simulated CNC
//! (real OPC UA, real Zenoh, a SQLite journal) gives ESE's recording — the
//! signals its check reads around the raise — on the bus, in the journal's
//! history, drawn by `cellwatch explain --alarm ese --timeline`, and
//! counted in the metrics.

use std::time::Duration;

use cellwatch::payload::RecordingPayload;
use cellwatch_models::engine::{RecorderConfig, Sample};
use zenoh_ext::AdvancedSubscriberBuilderExt;

use crate::agent::Fixture;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_fault_is_recorded_with_the_signals_its_check_reads_and_read_back() {
    let fx = Fixture::start_with(|c| {
        c.recorder = Some(RecorderConfig {
            after: 1_000,
            ..RecorderConfig::default()
        });
    })
    .await;
    let sub = fx
        .client()
        .declare_subscriber("cellwatch/m01ps0004/recordings/**")
        .await
        .unwrap();
    fx.settled().await;
    // The Y axis's over-travel switch opens: ESE.
    fx.sim.set("X0.06", false).unwrap();
    // One recording per alarm raised: ESE's.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    let mut got = Vec::new();
    let on_bus = loop {
        let sample = tokio::time::timeout_at(deadline, sub.recv_async())
            .await
            .unwrap_or_else(|_| panic!("no recording with X0.06 open; got {got:#?}"))
            .unwrap();
        let json = crate::util::opened(sample.payload());
        let p: RecordingPayload = serde_json::from_str(&json).unwrap();
        let opened = p.recording.signals.iter().any(|s| {
            s.address == "X0.06"
                && s.changes
                    .iter()
                    .any(|(_, v)| *v == Some(Sample::Bool(false)))
        });
        got.push(p.recording.alarm.clone());
        if p.recording.alarm == "ese" && opened {
            break (json, p);
        }
    };
    let (json, p) = on_bus;
    assert_eq!(p.schema, "cellwatch.recording.v1");
    assert_eq!(p.cell, "m01ps0004");
    let r = &p.recording;
    assert_eq!((r.from, r.to), (r.raised_at - 10_000, r.raised_at + 1_000));
    // Exactly the signals ESE's switching function reads (its 20 leaves).
    let mut read: Vec<&str> = r.signals.iter().map(|s| s.address.as_str()).collect();
    read.sort_unstable();
    let mut leaves: Vec<&str> = [
        "R1024.00", "G0.00", "F0.00", "X200.04", "X200.00", "R1023.00", "R1023.01", "F0.01",
        "X0.07", "X0.05", "Y0.00", "F28.03", "F28.02", "F28.01", "F28.00", "X200.03", "X0.0F",
        "X0.0A", "X0.08", "X0.06", "X0.04",
    ]
    .into();
    leaves.sort_unstable();
    assert_eq!(read, leaves);
    // The Y switch: closed at the raise's window start, open at the raise.
    let y = r.signals.iter().position(|s| s.address == "X0.06").unwrap();
    assert_eq!(
        r.value_at(y, r.raised_at - 1),
        Some(Some(&Sample::Bool(true)))
    );
    assert_eq!(r.value_at(y, r.raised_at), Some(Some(&Sample::Bool(false))));
    // The journal has it as published, and serves it over the bus.
    let rows = fx
        .history_rows("cellwatch/m01ps0004/history?since=1h;kind=recording")
        .await;
    let row = rows
        .iter()
        .rev()
        .find(|row| row["fields"]["alarm"] == "ese")
        .unwrap_or_else(|| panic!("no ese recording in {rows:#?}"));
    assert_eq!(row["table"], "recording");
    assert_eq!(
        row["fields"]["payload"],
        serde_json::from_str::<serde_json::Value>(&json).unwrap()
    );
    // Drawn from the journal file.
    let journal = fx.journal_path();
    let run = crate::util::cellwatch(&[
        "explain",
        "--alarm",
        "ese",
        "--journal",
        journal.to_str().unwrap(),
        "--timeline",
        "--width",
        "60",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let chart = run.stdout;
    assert!(chart.starts_with("m01ps0004/ese raised "), "{chart}");
    let y_row = chart
        .lines()
        .find(|l| l.starts_with("X0.06"))
        .unwrap_or_else(|| panic!("no X0.06 row in\n{chart}"));
    assert!(
        y_row.contains('╲'),
        "the Y switch falls at the raise:\n{chart}"
    );
    assert!(chart.contains('▼'), "{chart}");
    // As a list of changes: the fall at +0.000 s.
    let run = crate::util::cellwatch(&[
        "explain",
        "--alarm",
        "ese",
        "--journal",
        journal.to_str().unwrap(),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(run.stdout.contains("+0.000 s  X0.06 = 0"), "{}", run.stdout);
    // An alarm never recorded: said, with the journal named.
    let run = crate::util::cellwatch(&[
        "explain",
        "--alarm",
        "csd",
        "--journal",
        journal.to_str().unwrap(),
    ]);
    assert_eq!(run.code, 2, "{}", run.stdout);
    assert!(
        run.stderr.contains("no recording of alarm 'csd'"),
        "{}",
        run.stderr
    );
    let metrics = fx.scrape().await;
    assert!(
        metrics
            .lines()
            .filter_map(|l| l.strip_prefix("cellwatch_recordings_total{cell=\"m01ps0004\"} "))
            .any(|n| n.parse::<u64>().is_ok_and(|n| n >= 1)),
        "{metrics}"
    );
    fx.sim.stop();
}

/// A recording under way when the agent stops is journaled with what came
/// until then, saying so — not lost with the process.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_recording_under_way_when_the_agent_stops_is_kept_cut_short() {
    let mut fx = Fixture::start_with(|c| {
        c.recorder = Some(RecorderConfig {
            after: 3_600_000,
            ..RecorderConfig::default()
        });
    })
    .await;
    let sub = fx
        .client()
        .declare_subscriber("cellwatch/m01ps0004/alarms/ese")
        .history(zenoh_ext::HistoryConfig::default().detect_late_publishers())
        .await
        .unwrap();
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let mut seen = Vec::new();
    crate::agent::alarm_until(&sub, "ESE raised", &mut seen, |a| {
        a.transition.as_str() == "raised"
    })
    .await;
    fx.stop().await;
    let journal = fx.journal_path();
    let run = crate::util::cellwatch(&[
        "explain",
        "--alarm",
        "ese",
        "--journal",
        journal.to_str().unwrap(),
        "--timeline",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(
        run.stdout
            .contains("only: the agent stopped or read its configuration again"),
        "{}",
        run.stdout
    );
}
