//! With `[oee]`, the device's births and data carry the current shift's
//! OEE, as a Tahu host reads them. The script, in virtual time, on
//! Monday 2026-03-02 (UTC), shift `early` 06:00–14:00, ideal cycle 30 s:
//! - 08:00:00: the PLC connected, the machine running (before it, the
//!   shift was not observed);
//! - 08:09:30: three parts done, one of them rejected.
//!
//! So at 08:10:00: planned time = run time = 600 s; availability 1;
//! performance = 3 × 30 s ÷ 600 s = 0.15; quality = (3 − 1) ÷ 3 = 2/3;
//! OEE = 0.1.

use serde_json::Value;

use super::{
    contact, current, metrics, named, no_gaps, scripted_node, Broker, Host, PART, REJECT, RUN,
};

const OEE: &str = r#"
[oee]
ideal_cycle = "30s"
reject_signal = "X0.02"

[[oee.shifts]]
name = "early"
start = "06:00"
end = "14:00"
"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_shifts_oee_computed_by_hand_is_in_the_births_and_data() {
    let d = tempfile::tempdir().unwrap();
    let broker = Broker::start(d.path(), crate::util::restartable_port()).await;
    let mut host = Host::start(&broker).await;
    let monday = chrono::NaiveDate::from_ymd_opt(2026, 3, 2)
        .unwrap()
        .and_hms_opt(0, 0, 0)
        .unwrap()
        .and_utc()
        .timestamp_millis() as u64;
    let at = |h: u64, m: u64| monday + h * 3_600_000 + m * 60_000;
    let clock = cellwatch::clock::Clock::manual(at(8, 0));
    let (agent, script) = scripted_node(d.path(), &broker, OEE, &clock).await;

    // DBIRTH declares the OEE metrics; no part yet: quality and OEE null.
    let dbirth = host.message("DBIRTH", |_| true).await;
    for (name, kind) in [
        ("OEE/Shift", "String"),
        ("OEE/Availability", "Double"),
        ("OEE/Performance", "Double"),
        ("OEE/Quality", "Double"),
        ("OEE/OEE", "Double"),
        ("OEE/Parts", "UInt64"),
        ("OEE/Rejects", "UInt64"),
        ("OEE/Planned Time", "UInt64"),
        ("OEE/Run Time", "UInt64"),
    ] {
        assert_eq!(named(&dbirth, name)["type"], kind, "{name}");
    }
    assert_eq!(named(&dbirth, "OEE/Quality")["value"], Value::Null);
    assert_eq!(named(&dbirth, "OEE/OEE")["value"], Value::Null);
    let unit = &named(&dbirth, "OEE/Run Time")["properties"]["engUnit"]["value"];
    assert_eq!(unit, "ms");

    // 08:00 running, no part, no reject; 08:09:30 three parts, one
    // rejected.
    script
        .send(cellwatch::sources::SourceEvent::Connected(
            "scripted".into(),
        ))
        .await
        .unwrap();
    for (tag, on) in [(RUN, true), (PART, false), (REJECT, false)] {
        script.send(contact(tag, on, at(8, 0))).await.unwrap();
    }
    // Taken at 08:00 before the clock moves on.
    let state = named(&dbirth, "Machine/State")["alias"].clone();
    host.message("DDATA", |p| {
        metrics(p)
            .iter()
            .any(|m| m["alias"] == state && m["value"] == "running")
    })
    .await;
    let second = 1000;
    clock.set(at(8, 9) + 30 * second);
    for (tag, on) in [
        (PART, true),
        (PART, false),
        (PART, true),
        (REJECT, true),
        (PART, false),
        (PART, true),
    ] {
        script.send(contact(tag, on, clock.now_ms())).await.unwrap();
    }
    let produced = named(&dbirth, "Production/Parts Produced")["alias"].clone();
    host.message("DDATA", |p| {
        metrics(p)
            .iter()
            .any(|m| m["alias"] == produced && m["value"] == 3)
    })
    .await;
    // The shift's figures count what came before the moment they are of.
    clock.set(at(8, 10));
    let parts = named(&dbirth, "OEE/Parts")["alias"].clone();
    host.message("DDATA", |p| {
        metrics(p)
            .iter()
            .any(|m| m["alias"] == parts && m["value"] == 3)
    })
    .await;
    // The reject came before the third part: the view has it.
    let now = current(&host.seen);
    let ratio = |name: &str| {
        now[name]
            .as_f64()
            .unwrap_or_else(|| panic!("{name}: {:?}", now[name]))
    };
    assert_eq!(now["OEE/Shift"], "early");
    assert_eq!(now["OEE/Parts"], 3);
    assert_eq!(now["OEE/Rejects"], 1);
    assert_eq!(now["OEE/Planned Time"], 600_000);
    assert_eq!(now["OEE/Run Time"], 600_000);
    assert_eq!(now["Production/Parts Produced"], 3);
    for (name, by_hand) in [
        ("OEE/Availability", 1.0),
        ("OEE/Performance", 0.15),
        ("OEE/Quality", 2.0 / 3.0),
        ("OEE/OEE", 0.1),
    ] {
        assert!(
            (ratio(name) - by_hand).abs() < 1e-9,
            "{name}: {} by hand {by_hand}",
            ratio(name)
        );
    }
    no_gaps(&host.seen);
    agent.stop().await;
}
