//! Alarms from the agent to the bus: ESE raised on whole data with its culprit,
//! sealed with the state it changed, cleared and in history; one communication
//! alarm for a server outage; a published alarm already in history; an
//! unwritable journal's alarm; the body-shop line's timer alarm, played live.

use std::time::Duration;

use cellwatch::payload::AlarmPayload;
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use super::{alarm_until, line_cell, Fixture};

/// ESE's raise and the fault state it made, put in one step, are sealed
/// with one signature, and each opens alone against the trust file.
async fn sealed_with_the_state_it_changed(
    fx: &Fixture,
    raw: &zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
) {
    let trust = crate::util::trust(&fx.dir);
    let (alarm, state) = (
        "cellwatch/m01ps0004/alarms/ese",
        "cellwatch/m01ps0004/state",
    );
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    let (mut raise, mut fault) = (None, None);
    while raise.is_none() || fault.is_none() {
        let sample = tokio::time::timeout_at(deadline, raw.recv_async())
            .await
            .expect("ESE's raise and the fault state on the bus")
            .unwrap();
        let key = sample.key_expr().as_str().to_string();
        let bytes = sample.payload().to_bytes().to_vec();
        let Ok(opened) = trust.open(&bytes, cellwatch::bus::envelope::Kind::Put, &key, "") else {
            continue;
        };
        let env: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        if key == alarm && opened.body.contains("\"transition\":\"raised\"") {
            raise = Some(env);
        } else if key == state && opened.body.contains("\"fault\"") {
            fault = Some(env);
        }
    }
    let (raise, fault) = (raise.unwrap(), fault.unwrap());
    assert_eq!(raise["schema"], "cellwatch.signed.v2", "{raise}");
    assert_eq!(raise["signature"], fault["signature"], "{raise}\n{fault}");
    assert_eq!(
        (
            raise["tree"]["size"].as_u64(),
            fault["tree"]["size"].as_u64()
        ),
        (Some(2), Some(2))
    );
    assert_ne!(raise["tree"]["index"], fault["tree"]["index"]);
}

type AlarmSubscriber =
    zenoh_ext::AdvancedSubscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

/// Subscribes to `key`, waits for the agent to settle, opens the Y
/// over-travel switch and waits for ESE to be raised.
async fn ese_raised(fx: &Fixture, key: &str) -> (AlarmSubscriber, AlarmPayload, Vec<AlarmPayload>) {
    let sub = fx
        .client
        .declare_subscriber(key.to_string())
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let mut seen = Vec::new();
    let raised = alarm_until(&sub, "ESE raised", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    (sub, raised, seen)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_fault_present_at_start_is_raised_on_whole_data() {
    // The over-travel switch is open before the agent starts: its first
    // values make ESE's fault certain from X0.06 alone, whatever order
    // they come in. The raise names the step and the switch, and no
    // contact the server reports as unknown.
    let fx = Fixture::start_with_sim(|sim| sim.set("X0.06", false).unwrap(), |_| {}).await;
    let sub = fx
        .client
        .declare_subscriber("cellwatch/m01ps0004/alarms/ese")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    let mut seen = Vec::new();
    let raised = alarm_until(&sub, "ESE raised", &mut seen, |a| {
        a.transition.as_str() == "raised"
    })
    .await;
    assert!(
        raised
            .message
            .starts_with("ESE at step 6: X0.06 = 0 (expected 1)"),
        "{}",
        raised.message
    );
    assert!(!raised.message.contains("unknown"), "{}", raised.message);
    assert_eq!(raised.culprits.len(), 1, "{:?}", raised.culprits);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn ese_alarm_with_culprit_then_cleared_and_in_history() {
    let fx = Fixture::start().await;
    let raw = fx
        .client
        .declare_subscriber("cellwatch/m01ps0004/**")
        .await
        .unwrap();
    let (sub, raised, mut seen) = ese_raised(&fx, "cellwatch/m01ps0004/alarms/**").await;
    sealed_with_the_state_it_changed(&fx, &raw).await;
    assert_eq!(raised.schema, "cellwatch.alarm.v1");
    assert_eq!(raised.cell, "m01ps0004");
    assert_eq!(raised.kind.as_str(), "switching");
    assert_eq!(raised.severity.as_str(), "critical");
    assert_eq!(raised.state.as_str(), "active_unacknowledged");
    assert_eq!(raised.fault_step, Some(6));
    assert_eq!(raised.culprits.len(), 1);
    let c = &raised.culprits[0];
    assert_eq!(
        (c.address.as_str(), c.value, c.expected, c.trigger),
        ("X0.06", false, true, true)
    );
    assert_eq!(c.comment.as_deref(), Some("Y Over Travel Limit SW (B)"));
    fx.sim.set("X0.06", true).unwrap();
    let cleared = alarm_until(&sub, "ESE cleared", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "cleared"
    })
    .await;
    assert_eq!(cleared.state.as_str(), "cleared_unacknowledged");
    assert!(cleared.cleared_at.is_some());
    // History: the fault with its type and element, then the recovery.
    let rows = fx
        .history_rows("cellwatch/m01ps0004/history?since=1h;kind=state")
        .await;
    let kinds: Vec<(String, String, String)> = rows
        .iter()
        .map(|r| {
            let f = &r["fields"];
            (
                f["kind"].as_str().unwrap().to_string(),
                f["fault_type"].as_str().unwrap_or("").to_string(),
                f["element"].as_str().unwrap_or("").to_string(),
            )
        })
        .collect();
    let fault = kinds
        .iter()
        .position(|k| *k == ("fault".to_string(), "ESE".to_string(), "X0.06".to_string()));
    let recovery = kinds.iter().rposition(|k| k.0 == "recovery");
    assert!(fault.is_some() && recovery > fault, "{kinds:?}");
    // A bad query says why.
    assert_eq!(
        fx.query("cellwatch/m01ps0004/history?kind=weather", None)
            .await
            .unwrap_err(),
        "unknown kind 'weather': use alarm, state, command, recording, kpi or production"
    );
    // Metrics over HTTP: the alarm counter and the connection state.
    let metrics = fx.scrape().await;
    assert!(metrics.contains("cellwatch_alarms_raised_total{cell=\"m01ps0004\",check=\"ese\",kind=\"switching\",severity=\"critical\"} 1"), "{metrics}");
    assert!(
        metrics.contains("cellwatch_opcua_connected{cell=\"m01ps0004\"} 1"),
        "{metrics}"
    );
    // The agent's own latency: values received → alarm published, once
    // for the raise and once for the clear (both came from readings).
    let latencies = metrics
        .lines()
        .find_map(|l| l.strip_prefix("cellwatch_alarm_latency_seconds_count{cell=\"m01ps0004\"} "))
        .and_then(|n| n.parse::<u64>().ok());
    assert!(latencies.is_some_and(|n| n >= 2), "{metrics}");
    // The signatures made, their CPU time and the process's, so that their
    // share can be read.
    let value = |name: &str| {
        metrics
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{name}{{cell=\"m01ps0004\"}} ")))
            .and_then(|n| n.parse::<f64>().ok())
            .unwrap_or_else(|| panic!("{name} missing: {metrics}"))
    };
    let (signatures, signing, cpu) = (
        value("cellwatch_bus_signatures_total"),
        value("cellwatch_bus_signing_seconds_total"),
        value("process_cpu_seconds_total"),
    );
    assert!(
        signatures >= 2.0 && signing > 0.0 && cpu > signing,
        "{metrics}"
    );
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn server_outage_is_one_communication_alarm_and_faults_resume() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
    let mut fx = Fixture::start().await;
    let sub = fx
        .client
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    fx.settled().await;
    let mut seen = Vec::new();
    fx.sim.stop();
    alarm_until(&sub, "communication lost", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() == "raised"
    })
    .await;
    // While the PLC is away, nothing else is raised.
    tokio::time::sleep(Duration::from_secs(2)).await;
    fx.restart_sim().await;
    alarm_until(&sub, "communication restored", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() == "cleared"
    })
    .await;
    fx.settled().await;
    fx.sim.set("X0.04", false).unwrap();
    let raised = alarm_until(&sub, "ESE after the outage", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(raised.culprits[0].address, "X0.04");
    let comm: Vec<&AlarmPayload> = seen
        .iter()
        .filter(|a| a.id == "communication" && a.transition.as_str() == "raised")
        .collect();
    assert_eq!(comm.len(), 1, "{seen:#?}");
    let process_during_outage: Vec<&AlarmPayload> = seen
        .iter()
        .filter(|a| {
            a.kind.as_str() == "switching" && a.transition.as_str() == "raised" && a.id != "ese"
        })
        .collect();
    assert!(process_during_outage.is_empty(), "{seen:#?}");
    assert_eq!(
        seen.iter()
            .filter(|a| a.id == "ese" && a.transition.as_str() == "raised")
            .count(),
        1,
        "{seen:#?}"
    );
    let metrics = fx.scrape().await;
    assert!(
        metrics.contains("cellwatch_opcua_reconnects_total{cell=\"m01ps0004\"} 1"),
        "{metrics}"
    );
    fx.agent.take().unwrap().stop().await;
    fx.sim.stop();
}

/// The body-shop line played live over OPC UA into the agent with the
/// shipped timer model: a slowed motion raises the timer alarm of that
/// motion's sensor, latched, over Zenoh.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn live_line_slow_motion_raises_its_timer_alarm() {
    use cellwatch_models::timer::line::{Fault, FaultKind};

    let d = tempfile::tempdir().unwrap();
    let (sim, agent, zenoh_port) = line_cell(d.path()).await;
    let client = crate::util::operator_session(d.path(), "operator-kim", zenoh_port).await;
    let sub = client
        .declare_subscriber("cellwatch/line01/alarms/**")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    // The agent has its subscription, and every tag's first value, before
    // the line starts moving.
    crate::spawned::cell_snapshot_until(
        &client,
        "line01",
        "the line's agent never had every tag",
        |snap| {
            let known = snap["tags"]
                .as_array()
                .is_some_and(|tags| tags.iter().all(|t| t["quality"] == "good"));
            known && snap["connected"] == true
        },
    )
    .await;
    let (note_tx, mut note_rx) = tokio::sync::mpsc::unbounded_channel();
    let player_sim = sim.clone();
    let player = tokio::spawn(async move {
        player_sim
            .play(
                1006,
                Some(Fault {
                    kind: FaultKind::TooSlow,
                    step: 0,
                }),
                move |n| {
                    let _ = note_tx.send(n);
                },
            )
            .await;
    });
    let note = tokio::time::timeout(Duration::from_secs(40), note_rx.recv())
        .await
        .unwrap()
        .unwrap();
    assert!(note.contains("TR0_AT_STATION"), "{note}");
    let mut seen = Vec::new();
    let raised = alarm_until(&sub, "the slowed motion's timer alarm", &mut seen, |a| {
        a.kind.as_str() == "timer" && a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(raised.culprits[0].address, "TR0_AT_STATION", "{seen:#?}");
    // The sensor's comment, in the culprit and at the message's end.
    assert_eq!(
        raised.culprits[0].comment.as_deref(),
        Some("Transport robot 0: at station 0 sensor")
    );
    assert!(
        raised
            .message
            .ends_with("ms: Transport robot 0: at station 0 sensor"),
        "{}",
        raised.message
    );
    assert_eq!(raised.state.as_str(), "active_unacknowledged");
    assert!(
        raised
            .message
            .contains("+TR0_AT_STATION after +TR0_IN) too late"),
        "{}",
        raised.message
    );
    let timers: Vec<&AlarmPayload> = seen
        .iter()
        .filter(|a| a.kind.as_str() == "timer" && a.transition.as_str() == "raised")
        .collect();
    assert_eq!(timers.len(), 1, "only the slowed motion: {seen:#?}");
    player.abort();
    agent.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_published_alarm_is_already_in_history() {
    let fx = Fixture::start().await;
    let (_sub, raised, _) = ese_raised(&fx, "cellwatch/m01ps0004/alarms/ese").await;
    // Asked once, at once: the query waits for the rows queued before it.
    let rows = fx
        .history_rows("cellwatch/m01ps0004/history?kind=alarm;since=1h")
        .await;
    assert!(
        rows.iter().any(|r| r["fields"]["alarm"] == "ese"
            && r["fields"]["transition"] == "raised"
            && r["fields"]["payload"]["raised_at"] == raised.raised_at.as_str()),
        "{rows:#?}"
    );
    // A query that does not parse is refused, answered with why, and counted.
    let bad = fx
        .query("cellwatch/m01ps0004/history?since=yesterday-ish", None)
        .await
        .unwrap_err();
    assert!(bad.contains("yesterday-ish"), "{bad}");
    let metrics = fx.scrape().await;
    assert!(
        metrics.contains(
            "cellwatch_requests_refused_total{cell=\"m01ps0004\",reason=\"invalid\",service=\"history\"} 1"
        ),
        "{metrics}"
    );
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_unwritable_journal_raises_its_alarm_and_alarms_still_reach_zenoh() {
    let fx = Fixture::start().await;
    fx.settled().await;
    let sub = fx
        .client
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    // Another connection holds the journal's write lock: the agent cannot
    // write (as with a full disk), only queue.
    let lock = rusqlite::Connection::open(&fx.config.journal.path).unwrap();
    lock.execute_batch("BEGIN EXCLUSIVE").unwrap();
    fx.sim.set("X0.06", false).unwrap();
    let mut seen = Vec::new();
    alarm_until(&sub, "ESE while the journal is held", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    let journal_raised = |a: &AlarmPayload| a.id == "journal" && a.transition.as_str() == "raised";
    if !seen.iter().any(journal_raised) {
        alarm_until(&sub, "the journal alarm", &mut seen, journal_raised).await;
    }
    let journal = seen.iter().find(|a| journal_raised(a)).unwrap();
    assert_eq!(journal.kind.as_str(), "system");
    assert!(journal.message.starts_with("journal: "), "{journal:?}");
    let metrics = fx.scrape().await;
    let pending = metrics
        .lines()
        .find(|l| l.starts_with("cellwatch_journal_pending_rows{"))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap();
    assert!(pending >= 1.0, "{metrics}");
    // Writable again: the alarm clears and the queued rows are written.
    lock.execute_batch("ROLLBACK").unwrap();
    drop(lock);
    alarm_until(&sub, "the journal alarm cleared", &mut seen, |a| {
        a.id == "journal" && a.transition.as_str() == "cleared"
    })
    .await;
    let rows = fx
        .history_rows("cellwatch/m01ps0004/history?kind=alarm;since=1h")
        .await;
    assert!(
        rows.iter()
            .any(|r| r["fields"]["alarm"] == "ese" && r["fields"]["transition"] == "raised"),
        "{rows:#?}"
    );
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
}
