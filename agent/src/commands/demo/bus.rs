//! The demo's bus as its clients see it: one plant CA for every agent, the
//! console and the CLI, each agent's signing key in the trust file.

use std::path::{Path, PathBuf};

use super::super::Failure;
use crate::agent;
use crate::config::CellConfig;

/// The demo's bus as a client sees it: every agent's endpoints and its
/// trust-file entry, gathered as the cells join ([`DemoBus::join`]) and
/// written for the CLI ([`DemoBus::write`]).
pub(super) struct DemoBus {
    /// The demo's state directory.
    pub(super) state: PathBuf,
    endpoints: Vec<String>,
    pub(super) trust: crate::bus::envelope::Trust,
    entries: String,
}

impl DemoBus {
    pub(super) fn new(state: &Path) -> DemoBus {
        DemoBus {
            state: state.to_path_buf(),
            endpoints: Vec::new(),
            trust: Default::default(),
            entries: String::new(),
        }
    }

    /// Puts `c` on the demo's bus: its certificate from the demo's CA (in
    /// `state/pki-bus`, made on first use) and its signing key
    /// (`state/<cell>.agent.key`), whose public key the trust file gets.
    pub(super) fn join(&mut self, c: &mut CellConfig) -> Result<(), Failure> {
        use crate::bus::envelope::AgentKey;
        let state = self.state.as_path();
        c.zenoh.tls = Some(bus_tls(state, &format!("agent-{}", c.cell))?);
        let key_path = state.join(format!("{}.agent.key", c.cell));
        let (key, _) = AgentKey::load_or_create(&key_path, &c.cell)
            .map_err(|e| Failure::Runtime(e.to_string()))?;
        c.zenoh.signing_key = Some(key_path);
        self.entries += &key.trust_entry();
        self.trust = crate::bus::envelope::Trust::parse("the demo's trust", &self.entries)
            .map_err(|e| Failure::Runtime(e.to_string()))?;
        Ok(())
    }

    /// Notes where a started agent's session listens, for the CLI.
    pub(super) async fn listening(&mut self, agent: &agent::Agent) {
        self.endpoints.extend(
            agent
                .zenoh_locators()
                .await
                .iter()
                .map(|e| e.replace("0.0.0.0", "127.0.0.1")),
        );
    }

    /// Starts the web console on the demo's bus (its own certificate,
    /// every agent's endpoint, the trust file, the operators file), on
    /// loopback.
    pub(super) async fn console(
        &self,
        listen: std::net::SocketAddr,
        operators: &Path,
    ) -> Result<crate::console::Console, Failure> {
        if !listen.ip().is_loopback() {
            return Err(Failure::Input(format!(
                "--console {listen}: the demo serves its console on loopback only (plain HTTP)"
            )));
        }
        let cfg = crate::console::ConsoleConfig {
            listen,
            tls: None,
            bus: crate::config::ZenohConfig {
                mode: crate::config::ZenohMode::Peer,
                connect: self.endpoints.clone(),
                listen: Vec::new(),
                prefix: String::new(),
                multicast_scouting: false,
                tls: Some(bus_tls(&self.state, "console")?),
                config_file: None,
                plain: false,
                signing_key: None,
            },
            trust: self.state.join("trust.toml"),
            root: crate::config::DEFAULT_ROOT.into(),
            operators_file: Some(operators.to_path_buf()),
            areas: std::collections::BTreeMap::new(),
            max_alarms: crate::console::config::DEFAULT_MAX_ALARMS,
            session: crate::console::config::DEFAULT_SESSION,
            names: Vec::new(),
            readers: None,
            deployed: None,
        };
        crate::console::Console::start(&cfg)
            .await
            .map_err(|e| Failure::Runtime(format!("the console: {e}")))
    }

    /// Writes the CLI's files into `state`: `client.json5` (every agent's
    /// endpoint, the CA, operator `demo`'s certificate) and `trust.toml`
    /// (every agent's public key). Returns their paths.
    pub(super) fn write(&self) -> Result<(PathBuf, PathBuf), Failure> {
        let state = self.state.as_path();
        let operator = bus_tls(state, "operator-demo")?;
        let file = |p: &Path| p.display().to_string();
        let config = serde_json::json!({
            "connect": { "endpoints": self.endpoints },
            "transport": { "link": { "tls": {
                "root_ca_certificate": file(&operator.ca),
                "connect_certificate": file(&operator.cert),
                "connect_private_key": file(&operator.key),
                "enable_mtls": true,
            } } },
        });
        let text = format!(
            "// Zenoh client configuration for the demo's bus (cellwatch alarms|history|ack --zenoh-config THIS).\n{}\n",
            serde_json::to_string_pretty(&config).unwrap_or_default()
        );
        let path = state.join("client.json5");
        std::fs::write(&path, text)
            .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", path.display())))?;
        let trust = state.join("trust.toml");
        std::fs::write(
            &trust,
            format!(
                "# The demo's plant trust file: each cell's agent's public key (cellwatch --trust THIS).\n{}",
                self.entries
            ),
        )
        .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", trust.display())))?;
        Ok((path, trust))
    }
}

/// `name`'s certificate from the demo's CA, made on first use.
pub(super) fn bus_tls(state: &Path, name: &str) -> Result<crate::config::ZenohTls, Failure> {
    use crate::bus::certs;
    let pki = state.join("pki-bus");
    certs::make_ca(&pki, "cellwatch demo CA").map_err(Failure::runtime)?;
    let (cert, key) = certs::cert_files(&pki, name);
    if !cert.exists() {
        certs::issue(&pki, name, &["localhost".into(), "127.0.0.1".into()])
            .map_err(Failure::runtime)?;
    }
    Ok(crate::config::ZenohTls {
        ca: certs::ca_files(&pki).0,
        cert,
        key,
    })
}
