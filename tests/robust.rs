//! The agent never dies silently and never leaves a switch on:
//! - a cell loop that panics ends the agent ([`cellwatch::agent::Agent::wait`]
//!   says why) after its journal rows are committed and its liveliness
//!   token is gone;
//! - source timestamps out of order are counted, and neither stop the cell
//!   loop nor raise a timer alarm;
//! - SIGTERM is a clean stop of the real binary: exit status 0, every alarm
//!   the bus saw in the journal, even when the journal was busy;
//! - the robot's force switch is written off when the agent is stopped
//!   during a pulse, and by the next agent when one was killed during it.

use std::process::Child;
use std::time::Duration;

use cellwatch::agent::{self, Ended};
use cellwatch::cell::CellStep;
use cellwatch::operator::{Action, Command};
use cellwatch::payload::AlarmPayload;
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};
use cellwatch::sim::robot::{SimulatedRobot, FORCE_SWITCH};
use cellwatch::sinks::Sink;
use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::agent::alarm_until;
use crate::spawned::{kim, scrape, snapshot_until};
use crate::util::root;

pub(crate) type AlarmSubscriber =
    zenoh_ext::AdvancedSubscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

pub(crate) async fn alarms(session: &zenoh::Session, cell: &str) -> AlarmSubscriber {
    session
        .declare_subscriber(format!("cellwatch/{cell}/alarms/**"))
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap()
}

/// The sections after a test cell's tags and checks: its bus (QUIC on a
/// loopback port the system picks, TLS as `agent-m01ps0004` of a plant CA
/// made in `dir`, with `operator-kim` beside it), its metrics and its
/// journal in `dir`.
pub(crate) fn bus_metrics_journal(dir: &std::path::Path) -> String {
    crate::util::bus_pki(dir, &["agent-m01ps0004", "operator-kim"]);
    let tls = crate::util::bus_tls(dir, "agent-m01ps0004");
    let path = |p: &std::path::Path| format!("{:?}", p.display().to_string());
    format!(
        r#"[zenoh]
listen = ["quic/127.0.0.1:0"]

[zenoh.tls]
ca = {}
cert = {}
key = {}

[metrics]
listen = "127.0.0.1:0"

[journal]
path = {}
"#,
        path(&tls.ca),
        path(&tls.cert),
        path(&tls.key),
        path(&dir.join("journal.sqlite")),
    )
}

/// The agent of cell `m01ps0004` configured in `file` (the sections of
/// [`bus_metrics_journal`] in it) started, trusting the simulated PLC's
/// certificate from `dir/sim-pki`; `operator-kim`'s session on its bus;
/// and its alarms.
pub(crate) async fn started(
    dir: &std::path::Path,
    file: &std::path::Path,
) -> (agent::Agent, zenoh::Session, AlarmSubscriber) {
    let c = cellwatch::config::load(file).unwrap();
    crate::util::trust_sim(&c, &dir.join("sim-pki"));
    let agent = agent::start(c, None).await.unwrap();
    let port = crate::util::agent_port(&agent).await;
    let client = crate::util::operator_session(dir, "operator-kim", port).await;
    let sub = alarms(&client, "m01ps0004").await;
    (agent, client, sub)
}

/// How many liveliness tokens of agents of `cell` the bus knows.
async fn agents_alive(client: &zenoh::Session, cell: &str) -> usize {
    let replies = client
        .liveliness()
        .get(format!("cellwatch/{cell}/agent/*"))
        .timeout(Duration::from_secs(3))
        .await
        .unwrap();
    let mut n = 0;
    while replies.recv_async().await.is_ok() {
        n += 1;
    }
    n
}

/// A sink of the test's own that panics inside the cell loop when it is
/// handed the raise of alarm `ese` (after the journal and the bus).
struct PanicsOnEse;

impl Sink for PanicsOnEse {
    fn name(&self) -> &'static str {
        "panics-on-ese"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        let raised = step
            .alarms
            .iter()
            .any(|a| a.payload.id == "ese" && a.payload.transition.as_str() == "raised");
        async move {
            assert!(!raised, "the test's sink fails on ese");
        }
        .boxed()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_panicking_cell_loop_ends_the_agent_after_flushing_its_journal_and_token() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let config = crate::agent::config(dir, &sim.endpoint());
    crate::util::trust_sim(&config, &dir.join("sim-pki"));
    let journal = config.journal.path.clone();
    let mut agent = agent::start_with(
        config,
        agent::Options {
            sinks: vec![Box::new(PanicsOnEse)],
            ..agent::Options::default()
        },
    )
    .await
    .unwrap();
    let port = crate::util::agent_port(&agent).await;
    let client = crate::util::operator_session(dir, "operator-kim", port).await;
    let sub = alarms(&client, "m01ps0004").await;
    snapshot_until(&client, "connected and running", |s| {
        s["connected"] == true && s["state"] == "running"
    })
    .await;
    assert_eq!(agents_alive(&client, "m01ps0004").await, 1);
    // The client hears the agent's token come and go.
    let tokens = client
        .liveliness()
        .declare_subscriber("cellwatch/m01ps0004/agent/*")
        .history(true)
        .await
        .unwrap();

    sim.set("X0.06", false).unwrap();
    let mut seen = Vec::new();
    let raised = alarm_until(&sub, "ESE raised", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    // The loop panicked on that step: the agent says so, with why.
    let ended = tokio::time::timeout(Duration::from_secs(30), agent.wait())
        .await
        .expect("the agent reports its loop's end");
    match &ended {
        Ended::LoopPanicked(why) => assert!(why.contains("the test's sink fails on ese"), "{why}"),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        ended.to_string(),
        "the cell loop panicked: the test's sink fails on ese"
    );
    // Before anything else is stopped, the loop has closed its sinks: the
    // alarm the bus saw is committed, and the agent's token is gone.
    let conn = rusqlite::Connection::open(&journal).unwrap();
    let payloads: Vec<String> = conn
        .prepare("SELECT payload FROM alarm_events WHERE alarm = 'ese'")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let on_bus = serde_json::to_string(&raised).unwrap();
    assert!(
        payloads
            .iter()
            .any(|p| serde_json::from_str::<AlarmPayload>(p).unwrap() == raised),
        "{on_bus} not in {payloads:?}"
    );
    // The token was undeclared as the loop closed its sinks, before the
    // agent is stopped: the client hears it leave (over QUIC that can take
    // until its lease ends), and then finds no agent for the cell.
    loop {
        let sample = tokio::time::timeout(Duration::from_secs(30), tokens.recv_async())
            .await
            .expect("the agent's token is undeclared before the agent is stopped")
            .unwrap();
        if sample.kind() == zenoh::sample::SampleKind::Delete {
            break;
        }
    }
    assert_eq!(agents_alive(&client, "m01ps0004").await, 0);
    // The rest stops; the panic, already reported, is not raised again.
    agent.stop().await;
    sim.stop();
}

/// A transition timer (F17.00 off, then F17.01 off within 60-70 s)
/// judged on source timestamps that go back: the agent counts them, raises
/// no timer alarm, and goes on (a value after them is taken).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn source_timestamps_going_back_are_counted_and_the_agent_goes_on() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    std::fs::write(
        dir.join("timers.json"),
        r#"{"version": 1, "method": "full-state", "signals": ["F17.00", "F17.01"],
  "transitions": [{"id": 1, "from": ["-F17.00", "F17.01"], "event": {"tag": "F17.01", "edge": "fall"},
     "to": ["-F17.00", "-F17.01"], "delta_ms": 65000, "min_ms": 64000, "max_ms": 66000,
     "support": 4, "window_ms": [60000, 70000]}]}"#,
    )
    .unwrap();
    let server = cellwatch::sim::server::SimServer::start(
        &SimOptions {
            listen: "127.0.0.1:0".parse().unwrap(),
            pki_dir: dir.join("sim-pki"),
            insecure: false,
            decoy: None,
        },
        "cnc",
        "cellwatch simulated CNC",
        &[("F17.00".to_string(), true), ("F17.01".to_string(), true)],
    )
    .await
    .unwrap();
    let path = |p: &std::path::Path| format!("{:?}", p.display().to_string());
    let file = dir.join("cell.toml");
    std::fs::write(
        &file,
        format!(
            r#"[cell]
id = "m01ps0004"

[opcua]
endpoint = "{}"
pki_dir = {}
namespace_uri = "urn:cellwatch:sim:cnc:plc"

[[tags]]
name = "f17_00"
node_id = "ns=2;s=F17.00"
address = "F17.00"

[[tags]]
name = "f17_01"
node_id = "ns=2;s=F17.01"
address = "F17.01"

[[checks.timers]]
id = "tmr"
model = {}
severity = "high"

{}"#,
            server.endpoint(),
            path(&dir.join("agent-pki")),
            path(&dir.join("timers.json")),
            bus_metrics_journal(dir),
        ),
    )
    .unwrap();
    let (agent, client, sub) = started(dir, &file).await;
    let value_is = |address: &'static str, value: bool| {
        let client = client.clone();
        async move {
            snapshot_until(&client, &format!("{address} = {value}"), |s| {
                s["connected"] == true
                    && s["tags"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .any(|t| t["address"] == address && t["value"] == value)
            })
            .await;
        }
    };
    value_is("F17.01", true).await;
    let at = |ms: i64| {
        opcua::types::DateTime::from(chrono::Utc::now() + chrono::Duration::milliseconds(ms))
    };
    // F17.00 off now: transition 1 armed. F17.01 off stamped ten seconds
    // earlier: before the arming.
    server
        .set_at(&[("F17.00".to_string(), false)], at(0))
        .unwrap();
    value_is("F17.00", false).await;
    server
        .set_at(&[("F17.01".to_string(), false)], at(-10_000))
        .unwrap();
    value_is("F17.01", false).await;
    let metrics = crate::util::scrape(agent.metrics_addr().unwrap()).await;
    assert!(
        metrics.contains("cellwatch_out_of_order_readings_total{cell=\"m01ps0004\"} 1"),
        "{metrics}"
    );
    // Still running: a value after it is taken; no timer alarm came.
    server.set(&[("F17.00".to_string(), true)]).unwrap();
    value_is("F17.00", true).await;
    let mut seen = Vec::new();
    while let Ok(Some(sample)) = sub.try_recv() {
        seen.push(sample.payload().try_to_string().unwrap().into_owned());
    }
    assert!(!seen.iter().any(|p| p.contains("\"tmr-001\"")), "{seen:?}");
    agent.stop().await;
    server.stop();
}

/// A signed command of kim's to the robot cell.
fn force(value: &str) -> Command {
    let mut c = Command {
        action: Action::Force,
        alarm: String::new(),
        tag: None,
        value: Some(value.into()),
        reason: None,
        operator: "kim".into(),
        nonce: cellwatch::operator::nonce(),
        issued_at: cellwatch::clock::now_ms(),
        signature: String::new(),
    };
    c.sign("robot01", &kim());
    c
}

pub(crate) fn sigterm(child: &Child) {
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
}

/// Waits for `child` to end (it was told to); its exit code.
pub(crate) async fn exit_code(mut child: Child) -> Option<i32> {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code();
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the agent did not stop"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn sigterm_stops_the_binary_cleanly_with_every_alarm_the_bus_saw_journaled() {
    let d = tempfile::tempdir().unwrap();
    let (sim, mut cell) = crate::spawned::start(d.path()).await;
    let child = cell.spawn("agent.log").await;
    let client = cell.client().await;
    let sub = alarms(&client, "m01ps0004").await;
    snapshot_until(&client, "connected and running", |s| {
        s["connected"] == true && s["state"] == "running"
    })
    .await;
    // Another process holds the journal's write lock for a while: the
    // agent's rows wait.
    let admin = rusqlite::Connection::open(d.path().join("journal.sqlite")).unwrap();
    admin.execute_batch("BEGIN IMMEDIATE").unwrap();
    let mut seen = Vec::new();
    for k in 0..10 {
        sim.set("X0.06", k % 2 == 1).unwrap();
        let transition = if k % 2 == 0 { "raised" } else { "cleared" };
        alarm_until(&sub, transition, &mut seen, |a| {
            a.id == "ese" && a.transition.as_str() == transition
        })
        .await;
    }
    // Every alarm on the bus is a row not yet committed.
    let pending = |body: &str| -> f64 {
        body.lines()
            .find(|l| l.starts_with("cellwatch_journal_pending_rows{"))
            .and_then(|l| l.rsplit(' ').next()?.parse().ok())
            .unwrap_or(0.0)
    };
    let body = scrape(cell.metrics_port);
    assert!(
        pending(&body) >= seen.len() as f64,
        "{} alarms seen, {body}",
        seen.len()
    );
    sigterm(&child);
    // The agent is stopping while the journal is still busy; then the
    // lock goes.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while !cell.log("agent.log").contains("stopping") {
        assert!(
            tokio::time::Instant::now() < deadline,
            "{}",
            cell.log("agent.log")
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    admin.execute_batch("COMMIT").unwrap();
    assert_eq!(exit_code(child).await, Some(0), "{}", cell.log("agent.log"));
    sim.stop();
    while let Ok(Some(sample)) = sub.try_recv() {
        seen.push(serde_json::from_str(&sample.payload().try_to_string().unwrap()).unwrap());
    }
    let conn = rusqlite::Connection::open(d.path().join("journal.sqlite")).unwrap();
    let journaled: Vec<AlarmPayload> = conn
        .prepare("SELECT payload FROM alarm_events")
        .unwrap()
        .query_map([], |r| r.get::<_, String>(0))
        .unwrap()
        .map(|p| serde_json::from_str(&p.unwrap()).unwrap())
        .collect();
    let missing: Vec<&AlarmPayload> = seen.iter().filter(|a| !journaled.contains(a)).collect();
    assert!(
        missing.is_empty(),
        "{} of {} alarms on the bus not journaled: {missing:#?}\n{}",
        missing.len(),
        seen.len(),
        cell.log("agent.log")
    );
}

/// The robot cell for the real binary: the simulated robot (S2 stuck, arm
/// 1 held), and in `dir` an agent configuration whose force switch is held
/// for a minute, S2 supervised for 2 s.
async fn robot_cell(dir: &std::path::Path) -> (SimulatedRobot, crate::spawned::Cell) {
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
    robot.stick("F1.S2", true).unwrap();
    robot.pin("%IX0.1.0", Some(false));
    tokio::spawn({
        let robot = robot.clone();
        async move { robot.run().await }
    });
    let charts = std::fs::read_to_string(root().join("config/robot/robot.sfc.toml")).unwrap();
    std::fs::write(
        dir.join("robot.sfc.toml"),
        charts.replacen("supervision = \"8s\"", "supervision = \"2s\"", 1),
    )
    .unwrap();
    crate::util::bus_pki(dir, &["agent-robot01", "operator-kim"]);
    let tls = crate::util::bus_tls(dir, "agent-robot01");
    std::fs::write(
        dir.join("operators.toml"),
        crate::spawned::operators_file(&Action::ALL),
    )
    .unwrap();
    let path = |p: &std::path::Path| p.display().to_string();
    let config = std::fs::read_to_string(root().join("config/robot.toml"))
        .unwrap()
        .replace("opc.tcp://127.0.0.1:4847/", &robot.endpoint())
        .replace(
            "\"pki-robot\"",
            &format!("{:?}", path(&dir.join("agent-pki"))),
        )
        .replace(
            "\"robot/robot.sfc.toml\"",
            &format!("{:?}", path(&dir.join("robot.sfc.toml"))),
        )
        .replace("force_pulse = \"300ms\"", "force_pulse = \"60s\"")
        .replace("quic/127.0.0.1:7450", "quic/127.0.0.1:0")
        .replace("\"pki-bus/ca.pem\"", &format!("{:?}", path(&tls.ca)))
        .replace(
            "\"pki-bus/agent-robot01.pem\"",
            &format!("{:?}", path(&tls.cert)),
        )
        .replace(
            "\"pki-bus/agent-robot01.key\"",
            &format!("{:?}", path(&tls.key)),
        )
        .replace("listen = \"127.0.0.1:9467\"", "listen = \"127.0.0.1:0\"")
        + &format!(
            "\n[journal]\npath = {:?}\n\n[commands]\noperators_file = {:?}\n",
            path(&dir.join("journal.sqlite")),
            path(&dir.join("operators.toml"))
        );
    let file = dir.join("robot.toml");
    std::fs::write(&file, config).unwrap();
    crate::util::trust_sim(
        &cellwatch::config::load(&file).unwrap(),
        &dir.join("sim-pki"),
    );
    let cell = crate::spawned::Cell {
        dir: dir.to_path_buf(),
        config: file,
        zenoh_port: 0,
        metrics_port: 0,
        env: Vec::new(),
        watchdog_pid: false,
    };
    (robot, cell)
}

/// Waits until S2 is stuck and t3 can fire, asks for the force (its answer
/// is not awaited: the pulse lasts a minute), and returns once the robot
/// has the force switch on.
async fn force_switch_on(robot: &SimulatedRobot, cell: &crate::spawned::Cell) -> zenoh::Session {
    let client = cell.client().await;
    let sub = alarms(&client, "robot01").await;
    let mut seen = Vec::new();
    alarm_until(&sub, "t3 can fire", &mut seen, |a| {
        a.id == "sfc-F1-S2"
            && a.state.as_str().starts_with("active")
            && a.message
                .contains("t3 (Shuttle at waiting position) can fire")
    })
    .await;
    crate::spawned::query(&client, "cellwatch/robot01/snapshot", None)
        .await
        .unwrap();
    let asked = client
        .get("cellwatch/robot01/command")
        .payload(serde_json::to_string(&force("F1.t3")).unwrap())
        .timeout(Duration::from_secs(120))
        .await
        .unwrap();
    tokio::spawn(async move { while asked.recv_async().await.is_ok() {} });
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while !robot.writes().contains(&(FORCE_SWITCH.to_string(), true)) {
        assert!(
            tokio::time::Instant::now() < deadline,
            "no pulse: {:?}\n{}",
            robot.writes(),
            cell.log("agent.log")
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    client
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn sigterm_during_a_pulse_writes_the_force_switch_off() {
    let d = tempfile::tempdir().unwrap();
    let (robot, mut cell) = robot_cell(d.path()).await;
    let child = cell.spawn("agent.log").await;
    let _client = force_switch_on(&robot, &cell).await;
    sigterm(&child);
    assert_eq!(exit_code(child).await, Some(0), "{}", cell.log("agent.log"));
    assert_eq!(
        robot.writes(),
        [
            (FORCE_SWITCH.to_string(), true),
            (FORCE_SWITCH.to_string(), false)
        ],
        "{}",
        cell.log("agent.log")
    );
    robot.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_force_switch_left_on_by_a_killed_agent_is_written_off_by_the_next() {
    let d = tempfile::tempdir().unwrap();
    let (robot, mut cell) = robot_cell(d.path()).await;
    let mut child = cell.spawn("agent.log").await;
    let _client = force_switch_on(&robot, &cell).await;
    // Killed during the pulse: nothing writes the switch off.
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(robot.writes(), [(FORCE_SWITCH.to_string(), true)]);
    // The next agent writes it off as it connects.
    let mut child = cell.spawn("agent-2.log").await;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while robot.writes().len() < 2 {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the switch is still on: {:?}\n{}",
            robot.writes(),
            cell.log("agent-2.log")
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(
        robot.writes()[1..],
        [(FORCE_SWITCH.to_string(), false)],
        "{}",
        cell.log("agent-2.log")
    );
    child.kill().unwrap();
    child.wait().unwrap();
    robot.stop();
}

/// Shelves are for a while: a signed, permitted shelve longer than the
/// cell's `commands.max_shelve` (8 h by default) is refused whatever its
/// form, and journaled as refused.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_shelf_beyond_max_shelve_is_refused() {
    use crate::spawned::{send, signed_with};
    let mut fx = crate::agent::Fixture::start().await;
    for (duration, detail) in [
        ("9h", "shelve for 9h: at most 8h on this cell"),
        ("8h 1s", "shelve for 8h 1s: at most 8h on this cell"),
        (
            "1000000000y",
            "shelve for 1000000000y: at most 8h on this cell",
        ),
        (
            "99999999999999999999y",
            "shelve for '99999999999999999999y': give a duration (30m, 2h) or once",
        ),
        ("0s", "shelve for 0s: at most 8h on this cell"),
    ] {
        let command = signed_with(Action::Shelve, "ese", Some(duration), Some("sensor cable"));
        assert_eq!(
            send(fx.client(), &command).await,
            (false, detail.to_string()),
            "{duration}"
        );
    }
    let journal = fx.journal_path();
    fx.stop().await;
    let conn = rusqlite::Connection::open(journal).unwrap();
    let accepted: i64 = conn
        .query_row(
            "SELECT count(*) FROM commands WHERE action = 'shelve' AND accepted = 1",
            [],
            |r| r.get(0),
        )
        .unwrap();
    let refused: i64 = conn
        .query_row(
            "SELECT count(*) FROM commands WHERE action = 'shelve' AND accepted = 0",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!((accepted, refused), (0, 5));
    fx.sim.stop();
}

/// The simulators stop on SIGTERM too, with nothing on standard input
/// (as a service or a container runs them): exit status 0.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_simulators_stop_on_sigterm() {
    let d = tempfile::tempdir().unwrap();
    let pki = d.path().join("pki").display().to_string();
    for args in [
        vec![
            "simulate",
            "cnc",
            "--listen",
            "127.0.0.1:0",
            "--pki-dir",
            &pki,
            "--scenario",
            "none",
        ],
        vec![
            "simulate",
            "moulding",
            "--units",
            "1",
            "--tcp",
            "127.0.0.1:0",
            "--scenario",
            "none",
        ],
    ] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_cellwatch"))
            .args(&args)
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        // Its first line says it serves: its stop signals are set by then.
        let lines = crate::util::lines_of(&mut child);
        let first = lines.recv_timeout(Duration::from_secs(60)).unwrap();
        assert!(first.starts_with("simulated"), "{args:?}: {first}");
        sigterm(&child);
        assert_eq!(exit_code(child).await, Some(0), "{args:?}");
    }
}
