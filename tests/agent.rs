//! The agent with real parts: the simulated CNC over OPC UA (Basic256Sha256,
//! SignAndEncrypt), Zenoh on loopback, a SQLite file, an HTTP scrape.

mod acks;
mod alarms;
mod bus_access;
mod service;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use cellwatch::agent::{self, Agent};
use cellwatch::archive::router::PlantRouter;
use cellwatch::config::{self, CellConfig};
use cellwatch::payload::AlarmPayload;
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};

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
        Fixture::start_with_namespace(None, setup, change).await
    }

    /// [`Fixture::start_with_sim`], the simulated CNC's server with a
    /// namespace of URI `extra` besides its own (registered before it).
    pub(crate) async fn start_with_namespace(
        extra: Option<&str>,
        setup: impl FnOnce(&SimulatedCnc),
        change: impl FnOnce(&mut CellConfig),
    ) -> Fixture {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path().to_path_buf();
        let sim_opts = SimOptions {
            listen: "127.0.0.1:0".parse().unwrap(),
            pki_dir: dir.join("sim-pki"),
            insecure: false,
            decoy: extra.map(str::to_string),
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
