//! Shelving and out of service through the real agent (the binary, killed
//! and started again): only signed commands of operators allowed them
//! count, the shelf and the removal survive a restart, an alarm out of
//! service is not raised, and back in service it is if its condition holds.
//! Designed suppression by a machine mode read from the PLC's mode word:
//! the alarm evaluated, journaled and published as suppressed, announced
//! when the mode ends.

use cellwatch::operator::Action;

use crate::spawned::{alarm, operators_file, scrape, send, signed_with, snapshot_until, start};

/// The value of `metric` (no labels besides the cell) in `scrape`.
fn gauge(scrape: &str, metric: &str) -> f64 {
    scrape
        .lines()
        .find(|l| l.starts_with(&format!("{metric}{{")))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {metric} in\n{scrape}"))
}

fn tag_is(s: &serde_json::Value, address: &str, value: bool) -> bool {
    s["tags"]
        .as_array()
        .unwrap()
        .iter()
        .any(|t| t["address"] == address && t["value"] == value)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shelves_and_removals_are_signed_permitted_and_survive_a_restart() {
    let d = tempfile::tempdir().unwrap();
    let (sim, mut cell) = start(d.path()).await;
    // Kim may acknowledge and reset, nothing else.
    std::fs::write(
        d.path().join("operators.toml"),
        operators_file(&[Action::Ack, Action::Reset]),
    )
    .unwrap();
    let mut child = cell.spawn("agent-1.log").await;
    let client = cell.client().await;
    snapshot_until(&client, "the agent never settled", |s| {
        s["state"] == "running"
    })
    .await;
    sim.set("X0.06", false).unwrap();
    snapshot_until(&client, "ESE never raised", |s| alarm(s, "ese").is_some()).await;
    let shelve = || signed_with(Action::Shelve, "ese", Some("30m"), Some("sensor cable"));
    let (accepted, detail) = send(&client, &shelve()).await;
    assert!(!accepted && detail.contains("may not shelve"), "{detail}");
    // Unsigned: refused whoever it claims to be.
    let mut unsigned: serde_json::Value = serde_json::from_str(&shelve()).unwrap();
    unsigned["signature"] = "".into();
    let (accepted, detail) = send(&client, &unsigned.to_string()).await;
    assert!(!accepted, "{detail}");
    let (accepted, detail) = send(
        &client,
        &signed_with(Action::OutOfService, "csd", None, Some("switch replaced")),
    )
    .await;
    assert!(
        !accepted && detail.contains("may not out-of-service"),
        "{detail}"
    );
    let s = snapshot_until(&client, "ESE as it was", |s| alarm(s, "ese").is_some()).await;
    assert!(alarm(&s, "ese").unwrap()["shelved"].is_null());
    child.kill().unwrap();
    child.wait().unwrap();
    drop(client);

    // Kim may do everything now.
    std::fs::write(
        d.path().join("operators.toml"),
        operators_file(&Action::ALL),
    )
    .unwrap();
    let mut child = cell.spawn("agent-2.log").await;
    let client = cell.client().await;
    snapshot_until(&client, "ESE restored", |s| alarm(s, "ese").is_some()).await;
    assert_eq!(
        send(&client, &shelve()).await,
        (true, "shelve ese by kim".into())
    );
    // CSD has never been raised: it can be taken out of service all the same.
    assert_eq!(
        send(
            &client,
            &signed_with(Action::OutOfService, "csd", None, Some("switch replaced")),
        )
        .await,
        (true, "out-of-service csd by kim".into())
    );
    // Out of service needs a reason.
    let (accepted, detail) = send(
        &client,
        &signed_with(Action::OutOfService, "ese", None, None),
    )
    .await;
    assert!(!accepted && detail.contains("reason"), "{detail}");
    let before = snapshot_until(&client, "ESE shelved, CSD out of service", |s| {
        alarm(s, "ese").is_some_and(|a| a["shelved"]["by"] == "kim")
            && alarm(s, "csd").is_some_and(|a| a["out_of_service"]["by"] == "kim")
    })
    .await;
    let shelf = alarm(&before, "ese").unwrap()["shelved"].clone();
    assert_eq!(shelf["reason"], "sensor cable");
    assert!(shelf["until"].is_string(), "{shelf}");
    assert_eq!(alarm(&before, "csd").unwrap()["state"], "normal");
    child.kill().unwrap();
    child.wait().unwrap();
    drop(client);

    // A restart keeps the shelf, its expiry and the removal.
    let mut child = cell.spawn("agent-3.log").await;
    let client = cell.client().await;
    let after = snapshot_until(&client, "the restarted agent's alarms", |s| {
        alarm(s, "ese").is_some() && alarm(s, "csd").is_some()
    })
    .await;
    assert_eq!(alarm(&after, "ese").unwrap()["shelved"], shelf);
    assert_eq!(
        alarm(&after, "csd").unwrap()["out_of_service"],
        alarm(&before, "csd").unwrap()["out_of_service"]
    );
    let m = scrape(cell.metrics_port);
    assert_eq!(gauge(&m, "cellwatch_alarms_shelved"), 1.0, "{m}");
    assert_eq!(gauge(&m, "cellwatch_alarms_out_of_service"), 1.0, "{m}");
    assert_eq!(
        send(&client, &signed_with(Action::Unshelve, "ese", None, None)).await,
        (true, "unshelve ese by kim".into())
    );
    snapshot_until(&client, "ESE unshelved", |s| {
        alarm(s, "ese").is_some_and(|a| a["shelved"].is_null())
    })
    .await;

    // ESE out of service while active: the occurrence ends; the condition
    // going and coming back raises nothing.
    assert_eq!(
        send(
            &client,
            &signed_with(
                Action::OutOfService,
                "ese",
                None,
                Some("Y limit switch broken")
            ),
        )
        .await,
        (true, "out-of-service ese by kim".into())
    );
    snapshot_until(&client, "ESE out of service", |s| {
        alarm(s, "ese").is_some_and(|a| a["state"] == "normal" && a["out_of_service"].is_object())
            && s["state"] == "running"
    })
    .await;
    sim.set("X0.06", true).unwrap();
    snapshot_until(&client, "X0.06 closed", |s| tag_is(s, "X0.06", true)).await;
    sim.set("X0.06", false).unwrap();
    // The snapshot answering with the new value comes after the step that
    // would have raised it.
    let s = snapshot_until(&client, "X0.06 open", |s| tag_is(s, "X0.06", false)).await;
    assert_eq!(alarm(&s, "ese").unwrap()["state"], "normal", "{s:#}");
    assert_eq!(s["state"], "running");
    // Back in service while the switch is open: raised.
    assert_eq!(
        send(&client, &signed_with(Action::InService, "ese", None, None)).await,
        (true, "in-service ese by kim".into())
    );
    let s = snapshot_until(&client, "ESE raised again", |s| {
        alarm(s, "ese").is_some_and(|a| a["state"] == "active_unacknowledged")
    })
    .await;
    assert!(alarm(&s, "ese").unwrap()["out_of_service"].is_null());
    assert_eq!(alarm(&s, "ese").unwrap()["culprits"][0]["address"], "X0.06");
    child.kill().unwrap();
    child.wait().unwrap();
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mode_read_from_the_mode_word_suppresses_its_alarms_by_design_until_it_ends() {
    let d = tempfile::tempdir().unwrap();
    let (sim, mut cell) = start(d.path()).await;
    // JOG (mode word 2) is a setup: the emergency-stop chain is opened by
    // design while the setter works in the machine.
    let config = std::fs::read_to_string(&cell.config).unwrap();
    let config = config.replace(
        "[zenoh]\n",
        "[[state.modes]]\nid = \"setup\"\nwhen = \"mode_word == 2\"\nsuppress = [\"es*\"]\n\n[zenoh]\n",
    );
    std::fs::write(&cell.config, config).unwrap();
    let mut child = cell.spawn("agent.log").await;
    let client = cell.client().await;
    snapshot_until(&client, "the agent never settled", |s| {
        s["state"] == "running"
    })
    .await;
    let m = scrape(cell.metrics_port);
    assert!(
        m.contains("cellwatch_mode_active{cell=\"m01ps0004\",mode=\"setup\"} 0"),
        "{m}"
    );
    // Into JOG: the mode word says 2.
    sim.set("X201.02", false).unwrap();
    sim.set("X201.06", true).unwrap();
    snapshot_until(&client, "the machine never left running", |s| {
        s["state"] != "running"
    })
    .await;
    sim.set("X0.06", false).unwrap();
    let s = snapshot_until(&client, "ESE never raised", |s| alarm(s, "ese").is_some()).await;
    let ese = alarm(&s, "ese").unwrap();
    assert_eq!(ese["state"], "active_unacknowledged", "{ese:#}");
    assert_eq!(ese["suppressed_by_design"]["mode"], "setup", "{ese:#}");
    let m = scrape(cell.metrics_port);
    assert_eq!(
        gauge(&m, "cellwatch_alarms_suppressed_by_design"),
        1.0,
        "{m}"
    );
    assert_eq!(gauge(&m, "cellwatch_alarm_rate_by_design_10m"), 1.0, "{m}");
    assert!(
        m.contains("cellwatch_mode_active{cell=\"m01ps0004\",mode=\"setup\"} 1"),
        "{m}"
    );
    // Back to AUTO with the switch still open: announced now.
    sim.set("X201.06", false).unwrap();
    sim.set("X201.02", true).unwrap();
    let s = snapshot_until(&client, "ESE never announced", |s| {
        alarm(s, "ese").is_some_and(|a| a["suppressed_by_design"].is_null())
    })
    .await;
    assert_eq!(alarm(&s, "ese").unwrap()["state"], "active_unacknowledged");
    let m = scrape(cell.metrics_port);
    assert_eq!(
        gauge(&m, "cellwatch_alarms_suppressed_by_design"),
        0.0,
        "{m}"
    );
    child.kill().unwrap();
    child.wait().unwrap();
    sim.stop();
    // The journal keeps the mode's span and every transition of ESE.
    let journal = rusqlite::Connection::open(d.path().join("journal.sqlite")).unwrap();
    let modes: Vec<(String, bool)> = journal
        .prepare("SELECT mode, entered FROM modes ORDER BY seq")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(modes, [("setup".into(), true), ("setup".into(), false)]);
    let ese: Vec<(String, String)> = journal
        .prepare("SELECT transition, payload FROM alarm_events WHERE alarm = 'ese' ORDER BY seq")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let transitions: Vec<&str> = ese.iter().map(|(t, _)| t.as_str()).collect();
    assert_eq!(transitions, ["raised", "unsuppressed"], "{ese:#?}");
    assert!(
        ese[0]
            .1
            .contains(r#""suppressed_by_design":{"mode":"setup""#),
        "{}",
        ese[0].1
    );
}
