//! Paper 004 end to end: the simulated robot over OPC UA (Basic256Sha256,
//! SignAndEncrypt), an agent supervising its charts, signed forced
//! transitions and the stop switch over Zenoh, the journal in SQLite, and
//! the PLC's own log of what was written to it.

use std::time::Duration;

use cellwatch::cell;
use cellwatch::config;
use cellwatch::operator::{Action, Command, OperatorKey};
use cellwatch::payload::AlarmPayload;
use cellwatch::sim::cnc::SimOptions;
use cellwatch::sim::robot::{SimulatedRobot, FORCE_SWITCH, STOP_SWITCH};
use cellwatch::sources::{opcua, pki};
use cellwatch_models::alarm::Transition;
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::agent::{alarm_until, free_port};
use crate::spawned::kim;
use crate::util::root;

const CELL: &str = "robot01";

/// A signed command of `key`'s operator.
fn signed(key: &OperatorKey, action: Action, value: &str) -> Command {
    let mut c = Command {
        action,
        alarm: String::new(),
        tag: None,
        value: Some(value.into()),
        reason: None,
        operator: key.operator.clone(),
        nonce: cellwatch::operator::nonce(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    c.sign(CELL, key);
    c
}

/// Sends a command once (a force is answered when the chart has moved)
/// and returns (accepted, detail).
async fn send(session: &zenoh::Session, c: &Command) -> (bool, String) {
    let replies = session
        .get(format!("cellwatch/{CELL}/command"))
        .payload(serde_json::to_string(c).unwrap())
        .timeout(Duration::from_secs(90))
        .await
        .unwrap();
    let reply = replies.recv_async().await.expect("the agent answers");
    let text = reply
        .result()
        .map(|s| s.payload().try_to_string().unwrap().into_owned())
        .unwrap_or_else(|e| e.payload().try_to_string().unwrap().into_owned());
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    (
        v["accepted"].as_bool().unwrap(),
        v["detail"].as_str().unwrap().to_string(),
    )
}

/// The journal's command rows of `nonce`: (stage, accepted, detail).
fn rows_of(db: &std::path::Path, nonce: &str) -> Vec<(String, bool, String)> {
    let c = rusqlite::Connection::open(db).unwrap();
    let mut st = c
        .prepare("SELECT stage, accepted, detail FROM commands WHERE nonce = ?1 ORDER BY seq")
        .unwrap();
    st.query_map([nonce], |r| {
        Ok((r.get(0)?, r.get::<_, i64>(1)? != 0, r.get(2)?))
    })
    .unwrap()
    .map(Result::unwrap)
    .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stuck_step_is_explained_and_forced_on_only_as_paper_004_allows() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let robot = SimulatedRobot::start(
        &SimOptions {
            listen: "127.0.0.1:0".parse().unwrap(),
            pki_dir: dir.join("sim-pki"),
            insecure: false,
            decoy: None,
        },
        Duration::from_millis(200),
    )
    .await
    .unwrap();
    // S2 is in error from the start, and the shuttle is not yet at its
    // waiting position (t3 false).
    robot.stick("F1.S2", true).unwrap();
    robot.pin("%IX0.0.3", Some(false));
    let scanning = tokio::spawn({
        let robot = robot.clone();
        async move { robot.run().await }
    });

    let mut c = config::load(&root().join("config/robot.toml")).unwrap();
    let ua = c.opcua.as_mut().unwrap();
    ua.endpoint = robot.endpoint();
    ua.pki_dir = dir.join("agent-pki");
    c.journal.path = dir.join("journal.sqlite");
    let zenoh_port = free_port();
    c.zenoh.listen = vec![format!("tls/127.0.0.1:{zenoh_port}")];
    crate::util::bus_pki(dir, &["agent-robot01"]);
    c.zenoh.tls = Some(crate::util::bus_tls(dir, "agent-robot01"));
    c.metrics = None;
    // Supervision of S2 shortened from 8 s for the test.
    let sfc = &mut c.sfc[0].sfc;
    let s2 = sfc.charts[0]
        .steps
        .iter_mut()
        .find(|s| s.name == "S2")
        .unwrap();
    s2.supervision_ms = Some(2000);
    // kim may do anything; lee may only acknowledge.
    let lee = OperatorKey::generate("lee");
    let operators = dir.join("operators.toml");
    std::fs::write(
        &operators,
        format!(
            "{}{}",
            kim().operators_entry(&Action::ALL),
            lee.operators_entry(&[Action::Ack])
        ),
    )
    .unwrap();
    c.operators_file = Some(operators);
    drop(opcua::client("test", c.opcua.as_ref().unwrap()).unwrap());
    pki::trust(
        &pki::own_cert(&c.opcua.as_ref().unwrap().pki_dir),
        &dir.join("sim-pki"),
    )
    .unwrap();
    pki::trust(
        &pki::own_cert(&dir.join("sim-pki")),
        &c.opcua.as_ref().unwrap().pki_dir,
    )
    .unwrap();
    let journal = c.journal.path.clone();
    let agent = cell::start(c, None).await.unwrap();
    let bus = crate::util::operator_session(dir, "operator-kim", zenoh_port).await;
    let sub = bus
        .declare_subscriber(format!("cellwatch/{CELL}/alarms/**"))
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    let mut seen: Vec<AlarmPayload> = Vec::new();

    // The stuck alarm: chart and step, how long, and the unmet operand of
    // t3 with its value, expected value and comment.
    let stuck = alarm_until(&sub, "S2 stuck", &mut seen, |a| {
        a.id == "sfc-F1-S2" && a.transition == Transition::Raised
    })
    .await;
    let lasted: f64 = stuck
        .message
        .strip_prefix("F1.S2 (Shuttle to waiting position) stuck for ")
        .and_then(|m| m.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{}", stuck.message));
    // Its supervision time, then at most one publishing interval (100 ms)
    // and one tick of the agent's clock (250 ms) — with a second of
    // leeway for a loaded machine.
    assert!((2.0..3.35).contains(&lasted), "{}", stuck.message);
    assert!(
        stuck.message.ends_with(
            "(supervision 2.0 s): t3 (Shuttle at waiting position) waits for %IX0.0.3 = 0 (expected 1): Shuttle at waiting position"
        ),
        "{}",
        stuck.message
    );
    assert_eq!(stuck.culprits.len(), 1);
    assert_eq!(stuck.culprits[0].address, "%IX0.0.3");

    // The agent's queryables are known to this session (a query that
    // finds no queryable ends without a reply; a command is sent once).
    crate::spawned::query(&bus, &format!("cellwatch/{CELL}/snapshot"), None)
        .await
        .unwrap();

    // Refused while t3 is false: the condition.
    let first = signed(&kim(), Action::Force, "F1.t3");
    let (ok, detail) = send(&bus, &first).await;
    assert!(!ok);
    assert_eq!(
        detail,
        "condition: t3 (Shuttle at waiting position) does not hold: %IX0.0.3 = 0 (expected 1): Shuttle at waiting position"
    );
    let rows = rows_of(&journal, &first.nonce);
    let stages: Vec<(&str, bool)> = rows.iter().map(|(s, a, _)| (s.as_str(), *a)).collect();
    assert_eq!(
        stages,
        [
            ("request", true),
            ("check", true),
            ("check", true),
            ("check", true),
            ("check", true),
            ("check", false),
            ("result", false)
        ],
        "{rows:?}"
    );
    // Refused for an operator without `force`.
    let (ok, detail) = send(&bus, &signed(&lee, Action::Force, "F1.t3")).await;
    assert!(!ok);
    assert_eq!(detail, "operator 'lee' may not force");
    // Refused with a bad signature.
    let mut forged = signed(&kim(), Action::Force, "F1.t3");
    forged.value = Some("F2.t18".into());
    let (ok, detail) = send(&bus, &forged).await;
    assert!(!ok);
    assert!(detail.contains("signature"), "{detail}");
    // Refused when replayed.
    let (ok, detail) = send(&bus, &first).await;
    assert!(!ok);
    assert!(detail.contains("replay"), "{detail}");
    // Not forcible: t2.
    let (ok, detail) = send(&bus, &signed(&kim(), Action::Force, "F1.t2")).await;
    assert!(!ok);
    assert!(
        detail.starts_with("forcible: F1.t2 is not declared forcible"),
        "{detail}"
    );
    // No check passed all the way: the force switch was never written.
    assert_eq!(robot.writes(), []);

    // The shuttle arrives: t3 holds (the agent sees it), and arm 1 is held
    // at its sub-job so that the arrival can be seen.
    robot.pin("%IX0.1.0", Some(false));
    robot.pin("%IX0.0.3", None);
    alarm_until(&sub, "t3 can fire", &mut seen, |a| {
        a.id == "sfc-F1-S2"
            && a.message
                .contains("t3 (Shuttle at waiting position) can fire")
    })
    .await;
    let force = signed(&kim(), Action::Force, "F1.t3");
    let (ok, detail) = send(&bus, &force).await;
    assert!(ok, "{detail}");
    assert!(
        detail.starts_with("F1.t3 forced: F2.S5 + F2.S8 + F2.S11 active "),
        "{detail}"
    );
    assert!(robot.active().contains(&"F2.S5".to_string()));
    assert_eq!(
        robot.writes(),
        [
            (FORCE_SWITCH.to_string(), true),
            (FORCE_SWITCH.to_string(), false)
        ]
    );
    // Request, every check, the write and the result, in order.
    let rows = rows_of(&journal, &force.nonce);
    let stages: Vec<&str> = rows.iter().map(|(s, _, _)| s.as_str()).collect();
    assert_eq!(
        stages,
        ["request", "check", "check", "check", "check", "check", "write", "result"],
        "{rows:?}"
    );
    assert!(rows.iter().all(|(_, ok, _)| *ok), "{rows:?}");
    let details: Vec<&str> = rows.iter().map(|(_, _, d)| d.as_str()).collect();
    assert_eq!(details[0], "force F1.t3 asked by kim");
    assert_eq!(details[1], "operator: kim may force (signature verified)");
    assert_eq!(
        details[2],
        "transition: F1.t3: F1.S2 -> F2.S5 + F2.S8 + F2.S11 when %IX0.0.3"
    );
    assert_eq!(details[3], "forcible: F1.t3 is declared forcible");
    assert_eq!(details[4], "stuck: F1.S2 is stuck (alarm sfc-F1-S2 active)");
    assert!(details[5].starts_with("condition: t3 (Shuttle at waiting position) holds"));
    assert_eq!(
        details[6],
        "FORCE_SW (%IX0.3.1) on for 300 ms, read back on, then off"
    );
    // The chart left S2: its alarm cleared.
    alarm_until(&sub, "S2 cleared", &mut seen, |a| {
        a.id == "sfc-F1-S2" && a.transition == Transition::Cleared
    })
    .await;

    // The stop switch: permission only.
    let (ok, detail) = send(&bus, &signed(&lee, Action::Stop, "F1")).await;
    assert!(!ok, "{detail}");
    let stop = signed(&kim(), Action::Stop, "F1");
    let (ok, detail) = send(&bus, &stop).await;
    assert!(ok, "{detail}");
    assert!(robot.stopped());
    assert_eq!(
        robot.writes()[2..],
        [
            (STOP_SWITCH.to_string(), true),
            (STOP_SWITCH.to_string(), false)
        ]
    );
    let stages: Vec<String> = rows_of(&journal, &stop.nonce)
        .into_iter()
        .map(|(s, _, _)| s)
        .collect();
    assert_eq!(stages, ["request", "check", "check", "write", "result"]);

    agent.stop().await;
    scanning.abort();
    robot.stop();
}
