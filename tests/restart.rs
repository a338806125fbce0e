//! The real binary killed with SIGKILL and started again: alarms that were
//! not back to normal come back as they were (state, `acked_by`,
//! `raised_at`), are not counted as raised again, latched ones can be
//! reset, one whose condition ended while the agent was down clears on
//! the first fresh value, and a command accepted before the kill, sent
//! again after it, is a replay with its original outcome, not carried out
//! again.

use cellwatch::operator::Action;

use crate::spawned::{alarm, query, scrape, send, signed, snapshot_until, start};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn killed_agent_restores_its_alarms_and_answers_a_resent_command_once() {
    let d = tempfile::tempdir().unwrap();
    let (sim, mut cell) = start(d.path()).await;

    let mut child = cell.spawn("agent-1.log").await;
    let client = cell.client().await;
    snapshot_until(&client, "the agent never settled", |s| {
        s["state"] == "running"
    })
    .await;
    // ESE active, acknowledged by kim; two latched timer alarms.
    sim.set("X0.06", false).unwrap();
    snapshot_until(&client, "ESE never raised", |s| alarm(s, "ese").is_some()).await;
    let ack = signed(Action::Ack, "ese");
    assert_eq!(send(&client, &ack).await, (true, "ack ese by kim".into()));
    for (a, b) in [("F17.00", "F17.01"), ("F18.00", "F18.01")] {
        sim.set(a, false).unwrap();
        // The transition arms on the state PLC reports; wait for it.
        snapshot_until(&client, "the timer's start state", |s| {
            s["tags"]
                .as_array()
                .unwrap()
                .iter()
                .any(|t| t["address"] == a && t["value"] == false)
        })
        .await;
        sim.set(b, false).unwrap();
    }
    // The spindle too hot for longer than the limit's on-delay.
    sim.set_temperature(90.0).unwrap();
    let before = snapshot_until(
        &client,
        "two timer alarms, ESE acknowledged, the spindle hot",
        |s| {
            alarm(s, "tmr-001").is_some()
                && alarm(s, "tmr-002").is_some()
                && alarm(s, "ese").is_some_and(|a| a["state"] == "active_acknowledged")
                && alarm(s, "spindle-temp-h").is_some()
        },
    )
    .await;
    child.kill().unwrap();
    child.wait().unwrap();
    drop(client);
    // The spindle cools while the agent is down: the limit's check sees
    // only a normal value after the restart, never a return.
    sim.set_temperature(50.0).unwrap();

    let mut child = cell.spawn("agent-2.log").await;
    let client = cell.client().await;
    let after = snapshot_until(&client, "the restarted agent's alarms", |s| {
        ["ese", "tmr-001", "tmr-002", "spindle-temp-h"]
            .iter()
            .all(|id| alarm(s, id).is_some())
    })
    .await;
    for id in ["ese", "tmr-001", "tmr-002"] {
        let (b, a) = (alarm(&before, id).unwrap(), alarm(&after, id).unwrap());
        for field in ["state", "raised_at", "acked_by", "latched", "fault_type"] {
            assert_eq!(
                b[field],
                a[field],
                "{id}.{field}\n{}",
                cell.log("agent-2.log")
            );
        }
    }
    assert_eq!(alarm(&after, "ese").unwrap()["acked_by"], "kim");
    assert_eq!(alarm(&after, "tmr-001").unwrap()["latched"], true);
    // Restored, not raised again.
    let metrics = scrape(cell.metrics_port);
    assert!(
        !metrics
            .lines()
            .any(|l| l.starts_with("cellwatch_alarms_raised_total") && !l.ends_with(" 0")),
        "{metrics}"
    );
    // The journal says what happened at the restart.
    let history: serde_json::Value = serde_json::from_str(
        &query(
            &client,
            "cellwatch/m01ps0004/history?since=1h;kind=alarm",
            None,
        )
        .await
        .unwrap(),
    )
    .unwrap();
    let restored = history["rows"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["fields"]["transition"] == "restored")
        .count();
    assert!(restored >= 4, "{history:#}");
    // The spindle's alarm came back raised when it was, and cleared on the
    // first value: it waits for its acknowledgement only.
    let spindle = snapshot_until(&client, "the spindle's alarm cleared", |s| {
        alarm(s, "spindle-temp-h").is_some_and(|a| a["state"] == "cleared_unacknowledged")
    })
    .await;
    assert_eq!(
        alarm(&spindle, "spindle-temp-h").unwrap()["raised_at"],
        alarm(&before, "spindle-temp-h").unwrap()["raised_at"]
    );
    // The ack accepted before the kill, sent again after it: a replay with
    // its original outcome, read back from the journal (not carried out
    // again).
    assert_eq!(
        send(&client, &ack).await,
        (
            false,
            "replayed command: sent before (accepted: ack ese by kim); not carried out again"
                .into()
        )
    );
    // A latched one resets, its condition being gone.
    assert_eq!(
        send(&client, &signed(Action::Reset, "tmr-001")).await,
        (true, "reset tmr-001 by kim".into())
    );
    // A subscriber joining now still gets what happened before the restart.
    let mut follow = cell.follow_since("1h");
    let lines = crate::util::lines_of(&mut follow);
    let raised_at = alarm(&before, "ese").unwrap()["raised_at"].clone();
    let mut events = Vec::new();
    let wanted = |events: &[serde_json::Value]| {
        let has = |t: &str| {
            events
                .iter()
                .any(|e| e["id"] == "ese" && e["transition"] == t && e["raised_at"] == raised_at)
        };
        has("raised") && has("acknowledged") && has("restored")
    };
    while !wanted(&events) {
        let line = lines
            .recv_timeout(std::time::Duration::from_secs(30))
            .unwrap_or_else(|_| {
                panic!(
                    "alarms --follow --since 1h printed only {events:#?}\n{}\nagent:\n{}",
                    cell.log("follow.log"),
                    cell.log("agent-2.log")
                )
            });
        events.push(serde_json::from_str(&line).unwrap());
    }
    follow.kill().unwrap();
    follow.wait().unwrap();
    // ESE follows the fresh values: the switch closes, it clears.
    sim.set("X0.06", true).unwrap();
    snapshot_until(&client, "ESE cleared by fresh values", |s| {
        alarm(s, "ese").is_none()
    })
    .await;
    child.kill().unwrap();
    child.wait().unwrap();
    sim.stop();
}
