//! The agent with real parts: the simulated CNC over OPC UA (Basic256Sha256,
//! SignAndEncrypt), Zenoh on loopback, a SQLite file, an HTTP scrape.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use cellwatch::agent::{self, Agent};
use cellwatch::archive::router::PlantRouter;
use cellwatch::config::{self, CellConfig};
use cellwatch::operator::Command;
use cellwatch::payload::AlarmPayload;
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::util::root;

/// The demo configuration, pointed at `sim`, at files under `dir`, and at
/// ports the system chooses (its Zenoh listener on port 0: ask the agent).
pub(crate) fn config(dir: &Path, sim_endpoint: &str) -> CellConfig {
    let mut c = config::load(&root().join("config/demo.toml")).unwrap();
    c.opcua.as_mut().unwrap().endpoint = sim_endpoint.to_string();
    c.opcua.as_mut().unwrap().pki_dir = dir.join("agent-pki");
    c.journal.path = dir.join("journal.sqlite");
    c.zenoh.signing_key = Some(c.journal.path.with_extension("agent.key"));
    c.zenoh.listen = vec!["quic/127.0.0.1:0".into()];
    crate::util::bus_pki(dir, &["agent-m01ps0004"]);
    c.zenoh.tls = Some(crate::util::bus_tls(dir, "agent-m01ps0004"));
    c.metrics = Some("127.0.0.1:0".parse().unwrap());
    let secrets = dir.join("operators.toml");
    std::fs::write(
        &secrets,
        crate::spawned::operators_file(&cellwatch::operator::Action::ALL),
    )
    .unwrap();
    c.operators_file = Some(secrets);
    c
}

pub(crate) struct Fixture {
    _dir: tempfile::TempDir,
    dir: PathBuf,
    pub(crate) sim: SimulatedCnc,
    sim_addr: SocketAddr,
    pub(crate) agent: Option<Agent>,
    client: zenoh::Session,
    config: CellConfig,
    /// Where the agent's Zenoh session listens.
    zenoh_port: u16,
}

impl Fixture {
    pub(crate) async fn start() -> Fixture {
        Fixture::start_with(|_| {}).await
    }

    /// [`Fixture::start`] with the agent's configuration changed by
    /// `change` first.
    pub(crate) async fn start_with(change: impl FnOnce(&mut CellConfig)) -> Fixture {
        Fixture::start_with_sim(|_| {}, change).await
    }

    /// [`Fixture::start_with`], the simulated CNC set up by `setup` before
    /// the agent starts (registers added).
    pub(crate) async fn start_with_sim(
        setup: impl FnOnce(&SimulatedCnc),
        change: impl FnOnce(&mut CellConfig),
    ) -> Fixture {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path().to_path_buf();
        let sim_opts = SimOptions {
            listen: "127.0.0.1:0".parse().unwrap(),
            pki_dir: dir.join("sim-pki"),
            insecure: false,
            decoy: None,
        };
        let sim = SimulatedCnc::start(&sim_opts).await.unwrap();
        setup(&sim);
        let mut config = config(&dir, &sim.endpoint());
        change(&mut config);
        crate::util::trust_sim(&config, &dir.join("sim-pki"));
        let agent = agent::start(config.clone(), None).await.unwrap();
        let zenoh_port = crate::util::agent_port(&agent).await;
        let client = crate::util::operator_session(&dir, "operator-kim", zenoh_port).await;
        let sim_addr = sim.addr();
        Fixture {
            _dir: d,
            dir,
            sim,
            sim_addr,
            agent: Some(agent),
            client,
            config,
            zenoh_port,
        }
    }

    /// Starts the simulated CNC again (after `sim.stop()`): the same
    /// server on the same address with the same certificate.
    pub(crate) async fn restart_sim(&mut self) {
        let opts = SimOptions {
            listen: self.sim_addr,
            pki_dir: self.dir.join("sim-pki"),
            insecure: false,
            decoy: None,
        };
        let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
        self.sim = loop {
            match SimulatedCnc::start(&opts).await {
                Ok(s) => break s,
                Err(e) => {
                    assert!(tokio::time::Instant::now() < deadline, "{e}");
                    tokio::time::sleep(Duration::from_millis(200)).await;
                }
            }
        };
    }

    /// Stops the agent and starts it again on the same configuration and
    /// journal: a real restart (a new bus session, on a new port; kim's
    /// client session opened again to it).
    pub(crate) async fn restart(&mut self) {
        self.stop().await;
        let agent = agent::start(self.config.clone(), None).await.unwrap();
        self.zenoh_port = crate::util::agent_port(&agent).await;
        self.client =
            crate::util::operator_session(&self.dir, "operator-kim", self.zenoh_port).await;
        self.agent = Some(agent);
    }

    /// The fixture's directory (certificates, keys, journal).
    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where the agent's Zenoh session listens.
    pub(crate) fn zenoh_port(&self) -> u16 {
        self.zenoh_port
    }

    pub(crate) fn client(&self) -> &zenoh::Session {
        &self.client
    }

    /// The agent's configuration.
    pub(crate) fn config(&self) -> &CellConfig {
        &self.config
    }

    /// The agent's journal file.
    pub(crate) fn journal_path(&self) -> PathBuf {
        self.config.journal.path.clone()
    }

    /// Stops the agent (its journal drains and closes).
    pub(crate) async fn stop(&mut self) {
        if let Some(a) = self.agent.take() {
            a.stop().await;
        }
    }

    /// Waits until the agent's snapshot shows tag `address` at `value`
    /// (any JSON value: a number, a string).
    pub(crate) async fn tag_value_is(&self, address: &str, value: serde_json::Value) {
        self.snapshot_until(&format!("{address} never became {value}"), |snap| {
            snap["tags"]
                .as_array()
                .unwrap()
                .iter()
                .any(|t| t["address"] == address && t["value"] == value)
        })
        .await;
    }

    pub(crate) fn agent(&self) -> &Agent {
        self.agent.as_ref().unwrap()
    }

    async fn query(&self, selector: &str, payload: Option<String>) -> Result<String, String> {
        crate::spawned::query(&self.client, selector, payload).await
    }

    /// The rows of one history page.
    pub(crate) async fn history_rows(&self, selector: &str) -> Vec<serde_json::Value> {
        let page: serde_json::Value =
            serde_json::from_str(&self.query(selector, None).await.unwrap()).unwrap();
        assert_eq!(page["schema"], "cellwatch.history.v1", "{page}");
        page["rows"].as_array().unwrap().clone()
    }

    /// Waits until the agent's snapshot satisfies `ready`; `what` names it.
    async fn snapshot_until(&self, what: &str, ready: impl Fn(&serde_json::Value) -> bool) {
        let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
        loop {
            let snap: serde_json::Value = serde_json::from_str(
                &self
                    .query("cellwatch/m01ps0004/snapshot", None)
                    .await
                    .unwrap(),
            )
            .unwrap();
            if ready(&snap) {
                return;
            }
            assert!(tokio::time::Instant::now() < deadline, "{what}: {snap}");
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// Waits until the agent has every tag and no alarm.
    pub(crate) async fn settled(&self) {
        self.snapshot_until("agent never settled", |snap| {
            let known = snap["tags"]
                .as_array()
                .unwrap()
                .iter()
                .all(|t| t["quality"] == "good");
            known && snap["connected"] == true && snap["state"] == "running"
        })
        .await;
    }

    /// Waits until the agent's snapshot shows tag `address` at `value`.
    pub(crate) async fn tag_is(&self, address: &str, value: bool) {
        self.snapshot_until(&format!("{address} never became {value}"), |snap| {
            snap["tags"]
                .as_array()
                .unwrap()
                .iter()
                .any(|t| t["address"] == address && t["value"] == value)
        })
        .await;
    }

    pub(crate) async fn scrape(&self) -> String {
        crate::util::scrape(self.agent().metrics_addr().unwrap()).await
    }
}

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

/// Receives alarm payloads until `f` accepts one.
pub(crate) async fn alarm_until(
    sub: &zenoh_ext::AdvancedSubscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    what: &str,
    seen: &mut Vec<AlarmPayload>,
    f: impl Fn(&AlarmPayload) -> bool,
) -> AlarmPayload {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let sample = tokio::time::timeout_at(deadline, sub.recv_async())
            .await
            .unwrap_or_else(|_| panic!("timed out waiting for {what}; saw {seen:#?}"))
            .unwrap();
        let a: AlarmPayload = serde_json::from_str(&crate::util::opened(sample.payload())).unwrap();
        seen.push(a.clone());
        if f(&a) {
            return a;
        }
    }
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

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn only_correctly_signed_acks_are_carried_out_and_all_are_journaled() {
    let fx = Fixture::start().await;
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    // Wait for the alarm to be active.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    loop {
        let snap: serde_json::Value = serde_json::from_str(
            &fx.query("cellwatch/m01ps0004/snapshot", None)
                .await
                .unwrap(),
        )
        .unwrap();
        if snap["alarms"]
            .as_array()
            .unwrap()
            .iter()
            .any(|a| a["id"] == "ese")
        {
            assert_eq!(snap["last_fault"]["alarm"], "ese");
            break;
        }
        assert!(tokio::time::Instant::now() < deadline);
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let now = cellwatch::clock::now_ms();
    let cmd = || Command {
        action: cellwatch::operator::Action::Ack,
        alarm: "ese".into(),
        tag: None,
        value: None,
        reason: None,
        operator: "kim".into(),
        nonce: cellwatch::operator::nonce(),
        issued_at: now,
        signature: String::new(),
    };
    let fxr = &fx;
    let send = |c: Command| {
        let json = serde_json::to_string(&c).unwrap();
        async move {
            let r: serde_json::Value = serde_json::from_str(
                &fxr.query("cellwatch/m01ps0004/command", Some(json))
                    .await
                    .unwrap(),
            )
            .unwrap();
            (
                r["accepted"].as_bool().unwrap(),
                r["detail"].as_str().unwrap().to_string(),
            )
        }
    };
    assert_eq!(send(cmd()).await, (false, "unsigned command".to_string()));
    let mut wrong = cmd();
    wrong.sign(
        "m01ps0004",
        &cellwatch::operator::OperatorKey::generate("kim"),
    );
    assert_eq!(send(wrong).await, (false, "bad signature".to_string()));
    let mut good = cmd();
    good.sign("m01ps0004", &crate::spawned::kim());
    assert_eq!(
        send(good.clone()).await,
        (true, "ack ese by kim".to_string())
    );
    // Sent again (an answer lost): a replay with its original outcome,
    // carried out once.
    assert_eq!(
        send(good).await,
        (
            false,
            "replayed command: sent before (accepted: ack ese by kim); not carried out again"
                .to_string()
        )
    );
    let snap: serde_json::Value = serde_json::from_str(
        &fx.query("cellwatch/m01ps0004/snapshot", None)
            .await
            .unwrap(),
    )
    .unwrap();
    let ese = snap["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["id"] == "ese")
        .unwrap()
        .clone();
    assert_eq!(ese["state"], "active_acknowledged");
    assert_eq!(ese["acked_by"], "kim");
    // Every command, refused or not, is in the journal.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    loop {
        let rows = fx
            .history_rows("cellwatch/m01ps0004/history?since=1h;kind=command")
            .await;
        let outcomes: Vec<(bool, String)> = rows
            .iter()
            .map(|r| {
                (
                    r["fields"]["accepted"].as_bool().unwrap(),
                    r["fields"]["detail"].as_str().unwrap().to_string(),
                )
            })
            .collect();
        // The same command sent again is not a command of its own.
        if outcomes.len() == 3 {
            assert_eq!(
                outcomes,
                [
                    (false, "unsigned command".to_string()),
                    (false, "bad signature".to_string()),
                    (true, "ack ese by kim".to_string()),
                ]
            );
            break;
        }
        assert!(tokio::time::Instant::now() < deadline, "{outcomes:?}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let _ = &fx.config;
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
}

/// A simulated line and an agent on `config/line.toml` watching it, with
/// fresh ports and files under `dir`; returns them and the Zenoh port.
pub(crate) async fn line_cell(dir: &Path) -> (cellwatch::sim::line::SimulatedLine, Agent, u16) {
    use cellwatch::sim::line::SimulatedLine;
    let sim = SimulatedLine::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let mut c = config::load(&root().join("config/line.toml")).unwrap();
    c.opcua.as_mut().unwrap().endpoint = sim.endpoint();
    c.opcua.as_mut().unwrap().pki_dir = dir.join("agent-pki");
    c.journal.path = dir.join("journal.sqlite");
    c.zenoh.signing_key = Some(c.journal.path.with_extension("agent.key"));
    c.zenoh.listen = vec!["quic/127.0.0.1:0".into()];
    crate::util::bus_pki(dir, &["agent-line01"]);
    c.zenoh.tls = Some(crate::util::bus_tls(dir, "agent-line01"));
    c.metrics = Some("127.0.0.1:0".parse().unwrap());
    crate::util::trust_sim(&c, &dir.join("sim-pki"));
    let agent = agent::start(c, None).await.unwrap();
    let zenoh_port = crate::util::agent_port(&agent).await;
    (sim, agent, zenoh_port)
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
async fn a_stopped_agent_frees_its_port_and_its_liveliness_token() {
    let mut fx = Fixture::start().await;
    fx.settled().await;
    let token = "cellwatch/m01ps0004/agent/*";
    let alive = |client: zenoh::Session| async move {
        let replies = client
            .liveliness()
            .get(token)
            .timeout(Duration::from_secs(3))
            .await
            .unwrap();
        let mut n = 0;
        while replies.recv_async().await.is_ok() {
            n += 1;
        }
        n
    };
    // The client hears the token come and go (its current tokens first).
    let tokens = fx
        .client
        .liveliness()
        .declare_subscriber(token)
        .history(true)
        .await
        .unwrap();
    let next = |kind: zenoh::sample::SampleKind| {
        let tokens = &tokens;
        async move {
            loop {
                let sample = tokio::time::timeout(Duration::from_secs(30), tokens.recv_async())
                    .await
                    .unwrap_or_else(|_| panic!("no {kind:?} of the agent's token"))
                    .unwrap();
                if sample.kind() == kind {
                    break;
                }
            }
        }
    };
    next(zenoh::sample::SampleKind::Put).await;
    assert_eq!(alive(fx.client.clone()).await, 1);
    let agent = fx.agent.take().unwrap();
    let addr = agent.metrics_addr().unwrap();
    agent.stop().await;
    // Stop has returned: the port is free.
    std::net::TcpListener::bind(addr).unwrap();
    // The token is gone, once the client has heard the agent leave.
    next(zenoh::sample::SampleKind::Delete).await;
    assert_eq!(alive(fx.client.clone()).await, 0);
    fx.sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn part_done_edges_are_counted_and_reported() {
    let fx = Fixture::start().await;
    fx.settled().await;
    let mut committed = fx.agent().committed();
    let before = *committed.borrow();
    for k in 1..=3 {
        // Each rising edge is one `part` row, committed before the next.
        fx.sim.set("X12.03", true).unwrap();
        committed.wait_for(|n| *n >= before + k).await.unwrap();
        fx.sim.set("X12.03", false).unwrap();
        fx.tag_is("X12.03", false).await;
    }
    let metrics = fx.scrape().await;
    assert!(
        metrics.contains("cellwatch_parts_produced_total{cell=\"m01ps0004\"} 3"),
        "{metrics}"
    );
    let journal = fx.config.journal.path.clone();
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
    let today = cellwatch::clock::rfc3339(cellwatch::clock::now_ms())[..10].to_string();
    let run = crate::util::cellwatch(&[
        "report",
        "daily",
        "--date",
        &today,
        "--db",
        journal.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let report: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    assert_eq!(report["production"], 3, "{report:#}");
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

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn only_clients_with_a_plant_certificate_get_in() {
    let fx = Fixture::start().await;
    let port = fx.zenoh_port;
    // Plain TCP to a TLS endpoint, and TLS without a client certificate
    // from the plant CA: nothing to talk to.
    let mut plain = crate::util::client_config(&fx.dir, "operator-kim", port);
    plain.connect = vec![format!("tcp/127.0.0.1:{port}")];
    plain.tls = None;
    assert!(cellwatch::bus::open(&plain).await.is_err());
    let elsewhere = fx.dir.join("elsewhere");
    crate::util::bus_pki(&elsewhere, &["operator-kim"]);
    let mut foreign = crate::util::client_config(&elsewhere, "operator-kim", port);
    // Trusting the plant CA is not enough: the certificate must be from it.
    foreign.tls.as_mut().unwrap().ca = fx.dir.join("pki-bus/ca.pem");
    assert!(cellwatch::bus::open(&foreign).await.is_err());
    // A certificate from the plant CA: queries and subscriptions work.
    fx.settled().await;
    fx.agent.unwrap().stop().await;
    fx.sim.stop();
}

/// The shipped router configuration (`config/zenoh/router.json5`), its
/// certificates, port and archive folder replaced, as a real router in
/// this process (`cellwatch router`'s).
async fn router(dir: &Path, access_control: bool) -> (PlantRouter, u16) {
    crate::util::bus_pki(dir, &["router-1"]);
    let mut cfg = zenoh::Config::from_file(root().join("config/zenoh/router.json5")).unwrap();
    let pki = dir.join("pki-bus");
    let file = |name: &str| serde_json::to_string(&pki.join(name).display().to_string()).unwrap();
    for (key, value) in [
        ("listen/endpoints", "[\"quic/127.0.0.1:0\"]".to_string()),
        ("transport/link/tls/root_ca_certificate", file("ca.pem")),
        (
            "transport/link/tls/listen_certificate",
            file("router-1.pem"),
        ),
        (
            "transport/link/tls/listen_private_key",
            file("router-1.key"),
        ),
        (
            "transport/link/tls/connect_certificate",
            file("router-1.pem"),
        ),
        (
            "transport/link/tls/connect_private_key",
            file("router-1.key"),
        ),
        ("access_control/enabled", access_control.to_string()),
        (
            "plugins/storage_manager/volumes/sqlite/dir",
            serde_json::to_string(&dir.join("archive").display().to_string()).unwrap(),
        ),
    ] {
        cfg.insert_json5(key, &value).unwrap();
    }
    let router = PlantRouter::start(cfg, Path::new("config/zenoh/router.json5"))
        .await
        .unwrap();
    let port = crate::util::tls_port(&router.locators());
    (router, port)
}

/// A router (its access control on or off), the simulated CNC, and its
/// agent in client mode behind the router.
pub(crate) async fn behind_a_router(
    dir: &Path,
    access_control: bool,
) -> (PlantRouter, u16, SimulatedCnc, Agent) {
    let (router, port) = router(dir, access_control).await;
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let mut c = config(dir, &sim.endpoint());
    c.zenoh.mode = cellwatch::config::ZenohMode::Client;
    c.zenoh.listen = Vec::new();
    c.zenoh.connect = vec![format!("quic/127.0.0.1:{port}")];
    crate::util::trust_sim(&c, &dir.join("sim-pki"));
    let agent = agent::start(c, None).await.unwrap();
    (router, port, sim, agent)
}

/// A client-mode session of `name`'s certificate to the router on `port`.
async fn router_client(dir: &Path, name: &str, port: u16) -> zenoh::Session {
    crate::util::bus_pki(dir, &[name]);
    let mut c = crate::util::client_config(dir, name, port);
    c.mode = cellwatch::config::ZenohMode::Client;
    cellwatch::bus::open(&c).await.unwrap()
}

/// Through the shipped router, an intruder with a valid plant certificate
/// (an operator's) can neither publish an alarm for a cell nor answer for
/// it; the operator sees the agent's alarms and answers only.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn through_the_router_nobody_else_publishes_or_answers_for_the_cell() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (_router, port, sim, agent) = behind_a_router(dir, true).await;
    let kim = router_client(dir, "operator-kim", port).await;
    let mallory = router_client(dir, "operator-mallory", port).await;
    let snapshot = |s: zenoh::Session| async move {
        let replies = s
            .get("cellwatch/m01ps0004/snapshot")
            .consolidation(zenoh::query::ConsolidationMode::None)
            .await
            .unwrap();
        let mut answers = Vec::new();
        while let Ok(r) = replies.recv_async().await {
            if let Ok(sample) = r.result() {
                answers.push(crate::util::opened_or_raw(sample.payload()));
            }
        }
        answers
    };
    // The agent is reachable through the router, for kim and for mallory.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while snapshot(kim.clone()).await.is_empty() {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the agent never answered through the router"
        );
    }
    // Mallory declares an impostor queryable, then queries: her query
    // follows the declaration on the same link, so when it is answered the
    // router has judged the declaration too.
    let impostor = mallory
        .declare_queryable("cellwatch/m01ps0004/snapshot")
        .await
        .unwrap();
    let impostor_task = tokio::spawn(async move {
        while let Ok(q) = impostor.recv_async().await {
            let _ = q.reply(q.key_expr().clone(), r#"{"forged":true}"#).await;
        }
    });
    let command_impostor = mallory
        .declare_queryable("cellwatch/m01ps0004/command")
        .await
        .unwrap();
    let command_task = tokio::spawn(async move {
        while let Ok(q) = command_impostor.recv_async().await {
            let _ = q.reply(q.key_expr().clone(), r#"{"accepted":true}"#).await;
        }
    });
    assert!(!snapshot(mallory.clone()).await.is_empty());
    let answers = snapshot(kim.clone()).await;
    assert_eq!(answers.len(), 1, "{answers:?}");
    assert!(answers[0].contains("\"cell\":\"m01ps0004\""), "{answers:?}");
    // History and commands: the agent's answers only.
    let ask = |selector: &'static str, payload: Option<&'static str>| {
        let kim = kim.clone();
        async move {
            let mut get = kim
                .get(selector)
                .consolidation(zenoh::query::ConsolidationMode::None);
            if let Some(p) = payload {
                get = get.payload(p);
            }
            let replies = get.await.unwrap();
            let mut answers = Vec::new();
            while let Ok(r) = replies.recv_async().await {
                answers.push(match r.result() {
                    Ok(s) => crate::util::opened_or_raw(s.payload()),
                    Err(e) => crate::util::opened_or_raw(e.payload()),
                });
            }
            answers
        }
    };
    let history = ask("cellwatch/m01ps0004/history?since=1h", None).await;
    assert_eq!(history.len(), 1, "{history:?}");
    assert!(history[0].contains("cellwatch.history.v1"), "{history:?}");
    let command = ask("cellwatch/m01ps0004/command", Some("{}")).await;
    assert_eq!(command.len(), 1, "{command:?}");
    assert!(command[0].contains("\"accepted\":false"), "{command:?}");
    command_task.abort();
    // Mallory publishes forged alarms all along, before and after a real fault.
    // Kim subscribes as `cellwatch alarms --follow` does: an alarm put
    // before the router told the agent of the subscription is fetched from
    // the agent's cache.
    let sub = kim
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    let forging = {
        let mallory = mallory.clone();
        tokio::spawn(async move {
            loop {
                let _ = mallory
                    .put(
                        "cellwatch/m01ps0004/alarms/ese",
                        r#"{"cell":"m01ps0004","id":"ese","forged":true}"#,
                    )
                    .await;
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
    };
    sim.set("X0.06", false).unwrap();
    let mut transitions = Vec::new();
    while !transitions.iter().any(|t: &String| t == "cleared") {
        let sample = tokio::time::timeout_at(deadline, sub.recv_async())
            .await
            .unwrap_or_else(|_| panic!("ESE raised and cleared; saw {transitions:?}"))
            .unwrap();
        let text = crate::util::opened_or_raw(sample.payload());
        assert!(
            !text.contains("forged"),
            "a forged event got through: {text}"
        );
        let a: AlarmPayload = serde_json::from_str(&text).unwrap();
        if a.id == "ese" && a.transition.as_str() == "raised" {
            sim.set("X0.06", true).unwrap();
        }
        transitions.push(a.transition.as_str().to_string());
    }
    assert!(transitions.iter().any(|t| t == "raised"), "{transitions:?}");
    forging.abort();
    impostor_task.abort();
    agent.stop().await;
    sim.stop();
}

/// With a router whose access control is off, an impostor can answer the
/// `command` queryable: the CLI believes the agent's answer only.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_cli_believes_only_the_agent() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let (_router, port, sim, agent) = behind_a_router(dir, false).await;
    crate::util::bus_pki(dir, &["operator-kim"]);
    let mallory = router_client(dir, "operator-mallory", port).await;
    let impostor = mallory
        .declare_queryable("cellwatch/m01ps0004/command")
        .await
        .unwrap();
    let answered = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let impostor_task = {
        let answered = answered.clone();
        tokio::spawn(async move {
            while let Ok(q) = impostor.recv_async().await {
                let _ = q
                    .reply(
                        q.key_expr().clone(),
                        r#"{"accepted":true,"detail":"ack no-such-alarm by kim"}"#,
                    )
                    .await;
                answered.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            }
        })
    };
    let key_file = dir.join("kim.key");
    std::fs::write(&key_file, crate::spawned::kim().to_file()).unwrap();
    let mut args: Vec<String> = [
        "ack",
        "--cell",
        "m01ps0004",
        "--alarm",
        "no-such-alarm",
        "--mode",
        "client",
        "--key-file",
    ]
    .map(String::from)
    .to_vec();
    args.push(key_file.display().to_string());
    args.extend(crate::util::bus_args(dir, "operator-kim", port));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    for _ in 0..3 {
        let run = tokio::task::spawn_blocking({
            let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
            move || crate::util::cellwatch(&args.iter().map(String::as_str).collect::<Vec<_>>())
        })
        .await
        .unwrap();
        assert_eq!(run.code, 1, "{}{}", run.stdout, run.stderr);
        assert!(run.stdout.is_empty(), "{}", run.stdout);
        // The agent's refusal is what counts; the impostor's "accepted" is
        // named as ignored when it arrived first.
        assert!(
            run.stderr
                .ends_with("error: refused: no alarm 'no-such-alarm'\n"),
            "{}",
            run.stderr
        );
        // Plain text on a pipe: no terminal colour codes.
        assert!(!run.stderr.contains('\u{1b}'), "{}", run.stderr);
    }
    // The impostor did answer, and was not believed.
    assert!(answered.load(std::sync::atomic::Ordering::SeqCst) >= 1);
    // Mallory replays every real alarm event, altered: `alarms --follow`
    // prints the agent's events only.
    let mut follow: Vec<String> = [
        "alarms",
        "--cell",
        "m01ps0004",
        "--follow",
        "--json",
        "--mode",
        "client",
    ]
    .map(String::from)
    .to_vec();
    follow.extend(crate::util::bus_args(dir, "operator-kim", port));
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(&follow)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let lines = crate::util::lines_of(&mut child);
    let copier = mallory
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .await
        .unwrap();
    let replayed = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let replaying = {
        let (mallory, replayed) = (mallory.clone(), replayed.clone());
        tokio::spawn(async move {
            while let Ok(sample) = copier.recv_async().await {
                let Ok(mut envelope) =
                    serde_json::from_slice::<serde_json::Value>(&sample.payload().to_bytes())
                else {
                    continue;
                };
                let body = envelope["body"].as_str().unwrap_or_default().to_string();
                // Not what she put herself.
                if body.contains("FORGED")
                    || body.is_empty()
                    || sample.key_expr().as_str().ends_with("/csd")
                {
                    continue;
                }
                // The agent's envelope, its text edited; and the agent's
                // envelope as it is, put on another alarm's key.
                envelope["body"] = body
                    .replace("\"message\":\"", "\"message\":\"FORGED ")
                    .into();
                let _ = mallory
                    .put(sample.key_expr().clone(), envelope.to_string())
                    .await;
                let _ = mallory
                    .put("cellwatch/m01ps0004/alarms/csd", sample.payload().clone())
                    .await;
                replayed.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            }
        })
    };
    // Two faults, raised and cleared: the second comes after mallory has
    // replayed the first's events, so her copies travel while the follower
    // prints the second's.
    let mut printed: Vec<String> = Vec::new();
    let count = |printed: &[String], t: &str| {
        printed
            .iter()
            .filter(|l| l.contains(&format!("\"transition\":\"{t}\"")) && !l.contains("FORGED"))
            .count()
    };
    // Mallory's subscription may reach the agent after the first fault on
    // a loaded machine: faults go on until she has replayed one, then one
    // more.
    let mut replayed_in = None;
    for round in 1.. {
        for (value, transition) in [(false, "raised"), (true, "cleared")] {
            sim.set("X0.06", value).unwrap();
            while count(&printed, transition) < round {
                printed.push(
                    lines
                        .recv_timeout(Duration::from_secs(30))
                        .unwrap_or_else(|_| {
                            panic!("no ESE {transition} from alarms --follow: {printed:#?}")
                        }),
                );
            }
        }
        if replayed_in.is_some_and(|r| round > r) {
            break;
        }
        let deadline = tokio::time::Instant::now() + Duration::from_secs(5);
        while replayed.load(std::sync::atomic::Ordering::SeqCst) < 2
            && tokio::time::Instant::now() < deadline
        {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        if replayed_in.is_none() && replayed.load(std::sync::atomic::Ordering::SeqCst) >= 2 {
            replayed_in = Some(round);
        }
        assert!(round < 10, "mallory never replayed in {round} faults");
    }
    assert!(replayed.load(std::sync::atomic::Ordering::SeqCst) >= 1);
    child.kill().unwrap();
    child.wait().unwrap();
    while let Ok(line) = lines.try_recv() {
        printed.push(line);
    }
    assert!(
        !printed
            .iter()
            .any(|l| l.contains("FORGED") || l.contains("\"id\":\"csd\"")),
        "{printed:#?}"
    );
    replaying.abort();
    impostor_task.abort();
    agent.stop().await;
    sim.stop();
}
