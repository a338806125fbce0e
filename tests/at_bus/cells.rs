//! A legacy bus run as a cell over TCP and over a serial line; cells run
//! together must be distinct and agree on their bus.

use cellwatch_models::at_bus::Status;

use super::moulding_agent;

/// The shipped `config/moulding.toml` run as an agent against the simulated
/// bus: a door-open stop on unit 2 is an alarm naming the unit's contact
/// and a fault state with stop cause 01; production is the units' parts;
/// line noise is retried and counts nothing twice; a silent unit is one
/// alarm and nothing else; the daily report says what the simulator did.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_legacy_bus_runs_as_a_cell_over_tcp() {
    bus_cell(false).await;
}

/// The same over a serial line (a pseudo-terminal at 9600 7E2).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_legacy_bus_runs_as_a_cell_over_a_serial_line() {
    bus_cell(true).await;
}

async fn bus_cell(serial: bool) {
    use cellwatch::payload::AlarmPayload;
    use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

    let dir = tempfile::tempdir().unwrap();
    let (bus, server, agent, client, _) = moulding_agent(
        dir.path(),
        &crate::spawned::operators_file(&cellwatch::operator::Action::ALL),
        serial,
    )
    .await;
    let sub = client
        .declare_subscriber("cellwatch/moulding-bus1/alarms/**")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    let snapshot_until = |what: &'static str, ready: fn(&serde_json::Value) -> bool| {
        let client = client.clone();
        async move { crate::spawned::cell_snapshot_until(&client, "moulding-bus1", what, ready).await }
    };
    let value = |snap: &serde_json::Value, address: &str| {
        snap["tags"]
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["address"] == address)
            .map(|t| t["value"].clone())
            .unwrap()
    };
    snapshot_until("running", |s| s["state"] == "running").await;

    // Five cycles on every unit, two answers corrupted on the way.
    bus.corrupt_next(2);
    for _ in 0..5 {
        bus.cycle();
    }
    let snap = snapshot_until("15 parts", |s| {
        ["P1", "P2", "P3"].iter().all(|a| {
            s["tags"]
                .as_array()
                .unwrap()
                .iter()
                .any(|t| t["address"] == *a && t["value"] == 5)
        })
    })
    .await;
    assert_eq!(value(&snap, "J2"), "ITEM-01");
    assert_eq!(value(&snap, "T2"), 1000);

    // Unit 2's front door opens.
    bus.stop(2, Some(Status::FRONT_DOOR_OPEN));
    let mut seen: Vec<AlarmPayload> = Vec::new();
    let door = crate::agent::alarm_until(&sub, "front-door raised", &mut seen, |a| {
        a.id == "front-door"
    })
    .await;
    assert_eq!(door.fault_type, "DOOR_FRONT");
    assert_eq!(door.culprits[0].address, "U2.01");
    assert_eq!(
        door.culprits[0].comment.as_deref(),
        Some("Unit 2: Front door open (stop cause 01)")
    );
    snapshot_until("fault", |s| s["state"] == "fault").await;
    bus.stop(2, None);
    crate::agent::alarm_until(&sub, "front-door cleared", &mut seen, |a| {
        a.id == "front-door" && a.transition == cellwatch_models::alarm::Transition::Cleared
    })
    .await;

    // Unit 3 goes silent: one alarm, nothing else.
    bus.set_silent(3, true);
    let silent = crate::agent::alarm_until(&sub, "unit 3 out of reach", &mut seen, |a| {
        a.id == "legacy-unit-03"
    })
    .await;
    assert!(
        silent.message.contains("unit 03 does not answer"),
        "{}",
        silent.message
    );
    bus.cycle();
    snapshot_until("unit 1 at 6 parts", |s| {
        s["tags"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["address"] == "P1" && t["value"] == 6)
    })
    .await;
    bus.set_silent(3, false);
    crate::agent::alarm_until(&sub, "unit 3 back", &mut seen, |a| {
        a.id == "legacy-unit-03" && a.transition == cellwatch_models::alarm::Transition::Cleared
    })
    .await;
    let raised: Vec<&str> = seen
        .iter()
        .filter(|a| a.transition == cellwatch_models::alarm::Transition::Raised)
        .map(|a| a.id.as_str())
        .collect();
    assert_eq!(raised, ["front-door", "legacy-unit-03"], "no other alarm");

    // Unit 3 made its sixth part while silent: counted once it answers.
    snapshot_until("unit 3 at 6 parts", |s| {
        s["tags"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["address"] == "P3" && t["value"] == 6)
    })
    .await;
    // Six cycles on every unit (unit 2 ran again before the sixth).
    let made: u64 = 6 + 6 + 6;
    let body = crate::util::scrape(agent.metrics_addr().unwrap()).await;
    assert!(
        body.contains(&format!(
            "cellwatch_parts_produced_total{{cell=\"moulding-bus1\"}} {made}"
        )),
        "{body}"
    );
    agent.stop().await;
    if let Some(server) = server {
        server.abort();
    }

    let v = crate::util::todays_report(&dir.path().join("journal.sqlite"));
    assert_eq!(v["production"], made, "{v}");
    let causes = v["stop_causes"].as_array().unwrap();
    assert!(
        causes.iter().any(|c| c["code"] == "01" && c["count"] == 1),
        "{v}"
    );
}

/// `cellwatch run` with several cells: two on one journal or id are
/// refused naming both files; two on one bus polling it differently are
/// refused naming what differs; nothing is started.
#[test]
fn cells_run_together_must_be_distinct_and_agree_on_their_bus() {
    let dir = tempfile::tempdir().unwrap();
    let unit = |n: u32| crate::util::root().join(format!("config/moulding/imm-0{n}.toml"));
    let one = unit(1);
    let r = crate::util::cellwatch(&["run", one.to_str().unwrap(), one.to_str().unwrap()]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr.contains("have the same cell id 'imm-01'"),
        "{}",
        r.stderr
    );
    // Unit 2 polled every 2 s beside unit 1's default: refused.
    let text = std::fs::read_to_string(unit(2))
        .unwrap()
        .replace("# poll_interval = \"1s\"", "poll_interval = \"2s\"")
        .replace(
            "\"unit.il\"",
            &format!("{:?}", crate::util::root().join("config/moulding/unit.il")),
        );
    let two = dir.path().join("imm-02.toml");
    std::fs::write(&two, text).unwrap();
    let r = crate::util::cellwatch(&["run", one.to_str().unwrap(), two.to_str().unwrap()]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(
        r.stderr
            .contains("share 127.0.0.1:4001 but poll it differently")
            && r.stderr.contains("poll every 1s")
            && r.stderr.contains("poll every 2s"),
        "{}",
        r.stderr
    );
}
