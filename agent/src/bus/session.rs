//! A session on the bus: its configuration (TLS only with the plant CA,
//! whatever a Zenoh file says, unless `plain`), the agent's access control
//! (it routes for nobody), and opening a session for an agent or a client.

use zenoh::Session;

use crate::backoff::Backoff;

use crate::bus::config::{ZenohConfig, ZenohMode};

/// Why Zenoh refused.
#[derive(Debug, thiserror::Error)]
pub enum ZenohError {
    /// A configuration value zenoh does not accept.
    #[error("zenoh {key} = {value}: {reason}")]
    Config {
        /// The zenoh configuration key.
        key: String,
        /// The value given.
        value: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// The session cannot be opened (endpoints cannot be bound, ...).
    #[error("cannot open the zenoh session: {0}")]
    Open(#[source] zenoh::Error),
    /// The session would not be TLS-only with the plant CA.
    #[error("zenoh {key} = {value}: {reason}")]
    Insecure {
        /// The zenoh configuration key.
        key: String,
        /// Its value.
        value: String,
        /// Why that is refused, and what to do.
        reason: String,
    },
    /// A signing key or trust file is unusable.
    #[error(transparent)]
    Key(#[from] super::envelope::KeyFileError),
    /// A publisher, queryable or token cannot be declared.
    #[error("cannot declare {key}: {reason}")]
    Declare {
        /// The key expression.
        key: String,
        /// Zenoh's reason.
        reason: String,
    },
}

/// Builds the zenoh session configuration: the configuration file if one
/// is named, with cellwatch's settings laid over it. Whatever the file
/// says, the session listens on `c.listen` only (a client: on nothing),
/// connects to `c.connect` (the file's endpoints only when `c.connect` is
/// empty), and scouts and gossips only with `multicast_scouting`; every
/// endpoint must be TLS (or QUIC) with the plant CA and mutual
/// authentication unless `c.plain` ([`secure`]).
///
/// # Errors
/// The file cannot be read, a value zenoh does not accept, or a session
/// that would not be TLS-only.
pub fn session_config(c: &ZenohConfig) -> Result<zenoh::Config, ZenohError> {
    let mut cfg = match &c.config_file {
        Some(path) => crate::bus::config::zenoh_file(path).map_err(|e| ZenohError::Config {
            key: "config_file".into(),
            value: path.display().to_string(),
            reason: e.to_string(),
        })?,
        None => zenoh::Config::default(),
    };
    set(&mut cfg, "mode", format!("\"{}\"", c.mode.as_str()))?;
    if !c.connect.is_empty() || c.config_file.is_none() {
        set(
            &mut cfg,
            "connect/endpoints",
            serde_json::to_string(&c.connect).unwrap_or_default(),
        )?;
    }
    // Zenoh's default is a plain TCP listener on every interface: never.
    set(
        &mut cfg,
        "listen/endpoints",
        serde_json::to_string(&c.listen).unwrap_or_default(),
    )?;
    // Links only to the endpoints configured: a node met through another
    // is not connected to directly, so every path to this one goes through
    // the nodes it chose (and their access control).
    for key in ["scouting/multicast/enabled", "scouting/gossip/enabled"] {
        set(&mut cfg, key, c.multicast_scouting.to_string())?;
    }
    set(&mut cfg, "timestamping/enabled", "true".into())?;
    // Never compressed (negotiated only when both ends ask): the LZ4
    // decoder of this Zenoh release can leak memory on invalid input
    // (RUSTSEC-2026-0041, deny.toml), and alarm traffic is small.
    for key in [
        "transport/unicast/compression/enabled",
        "transport/multicast/compression/enabled",
    ] {
        set(&mut cfg, key, "false".into())?;
    }
    // A client that loses its router opens a session to the next one of
    // its list in turn: a router that is gone (a QUIC handshake nobody
    // answers) holds it for this long, not Zenoh's 10 s, unless the Zenoh
    // file says otherwise.
    if c.mode == ZenohMode::Client
        && c.connect.len() > 1
        && cfg.get_json(OPEN_TIMEOUT).ok().as_deref() == Some(ZENOH_OPEN_TIMEOUT)
    {
        set(&mut cfg, OPEN_TIMEOUT, CLIENT_OPEN_TIMEOUT_MS.to_string())?;
    }
    if let Some(tls) = &c.tls {
        for (key, file) in [
            ("tls.ca", &tls.ca),
            ("tls.cert", &tls.cert),
            ("tls.key", &tls.key),
        ] {
            if let Err(e) = std::fs::metadata(file) {
                return Err(ZenohError::Config {
                    key: key.into(),
                    value: file.display().to_string(),
                    reason: format!("{e} (certificates are made by `cellwatch pki`)"),
                });
            }
        }
        let path = |p: &std::path::Path| {
            serde_json::to_string(&p.display().to_string()).unwrap_or_default()
        };
        for (key, value) in [
            ("root_ca_certificate", path(&tls.ca)),
            ("listen_certificate", path(&tls.cert)),
            ("listen_private_key", path(&tls.key)),
            ("connect_certificate", path(&tls.cert)),
            ("connect_private_key", path(&tls.key)),
            ("enable_mtls", "true".into()),
            ("verify_name_on_connect", "true".into()),
        ] {
            set(&mut cfg, &format!("transport/link/tls/{key}"), value)?;
        }
    }
    secure(&cfg, c.plain)?;
    Ok(cfg)
}

/// Refuses a session that is not TLS-only (unless `plain`): every listen
/// and connect endpoint `quic/` or `quic/`, the plant CA given, mutual
/// authentication on, a certificate to show. `cfg` is the session's
/// configuration as it will be opened, the Zenoh file included.
///
/// # Errors
/// [`ZenohError::Insecure`], naming the Zenoh key and what to do.
pub fn secure(cfg: &zenoh::Config, plain: bool) -> Result<(), ZenohError> {
    if plain {
        return Ok(());
    }
    let insecure = |key: &str, value: String, reason: &str| ZenohError::Insecure {
        key: key.into(),
        value,
        reason: reason.into(),
    };
    let json = |key: &str| -> serde_json::Value {
        cfg.get_json(key)
            .ok()
            .and_then(|j| serde_json::from_str(&j).ok())
            .unwrap_or(serde_json::Value::Null)
    };
    let mut listening = false;
    for key in ["listen/endpoints", "connect/endpoints"] {
        // A list, or a list per mode ({router: [...], peer: [...]}).
        let value = json(key);
        let lists: Vec<&serde_json::Value> = match &value {
            serde_json::Value::Object(per_mode) => per_mode.values().collect(),
            other => vec![other],
        };
        for e in lists.into_iter().filter_map(|l| l.as_array()).flatten() {
            let e = e.as_str().unwrap_or_default();
            if key.starts_with("listen") {
                listening = true;
            }
            if let Some(mut reason) = crate::bus::config::link_problem(e) {
                if !e.starts_with("tls/") {
                    reason += "; write zenoh.plain = true (CLI: --plain) to accept a bus without encryption or authentication";
                }
                return Err(insecure(key, e.into(), &reason));
            }
        }
    }
    let tls = |name: &str| json(&format!("transport/link/tls/{name}"));
    let given = |v: serde_json::Value| v.as_str().is_some_and(|s| !s.is_empty());
    if !given(tls("root_ca_certificate")) {
        return Err(insecure(
            "transport/link/tls/root_ca_certificate",
            "none".into(),
            "no plant CA: give [zenoh.tls] (CLI: --tls-ca, --tls-cert, --tls-key), made by `cellwatch pki`",
        ));
    }
    if tls("enable_mtls") != serde_json::Value::Bool(true) {
        return Err(insecure(
            "transport/link/tls/enable_mtls",
            tls("enable_mtls").to_string(),
            "mutual TLS must be on: every node shows a certificate from the plant CA",
        ));
    }
    let own = if listening {
        ["listen_certificate", "listen_private_key"]
    } else {
        ["connect_certificate", "connect_private_key"]
    };
    for name in own {
        if !given(tls(name)) {
            return Err(insecure(
                &format!("transport/link/tls/{name}"),
                "none".into(),
                "no certificate of this node's own from the plant CA (`cellwatch pki issue`)",
            ));
        }
    }
    Ok(())
}

/// Zenoh's key for how long opening a session to one endpoint may take.
const OPEN_TIMEOUT: &str = "transport/unicast/open_timeout";

/// Its default in this Zenoh release, as `get_json` says it.
const ZENOH_OPEN_TIMEOUT: &str = "10000";

/// How long a client with several routers gives one to open a session
/// (a QUIC and TLS handshake on a plant network takes milliseconds).
pub const CLIENT_OPEN_TIMEOUT_MS: u64 = 3_000;

fn set(cfg: &mut zenoh::Config, key: &str, value: String) -> Result<(), ZenohError> {
    cfg.insert_json5(key, &value)
        .map_err(|e| ZenohError::Config {
            key: key.into(),
            value: value.clone(),
            reason: e.to_string(),
        })
}

/// The access control of an agent's own session: an agent speaks for its
/// own cell only and routes for nobody. No other session may publish,
/// delete, declare a queryable, answer or hold a liveliness token through
/// it, under any key (the advanced publishers' `@adv` keys included):
/// whatever another session puts, it never reaches anyone by way of an
/// agent, so in peer mode an agent is never a relay for an impostor.
/// Subscribing and querying are allowed; who may reach the agent at all is
/// TLS's business. Two things only come in: the plant operators list put
/// under `root` (`<root>/_plant/operators`) and the lists other agents
/// answer (`<root>/*/operators`); both are signed by the plant
/// administrator, and believed only then.
pub fn agent_access_control(root: &str) -> String {
    let all = r#"["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                 "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]"#;
    let list = serde_json::to_string(&crate::bus::keys::plant_operators(root)).unwrap_or_default();
    let held =
        serde_json::to_string(&crate::bus::keys::every_cells_operators(root)).unwrap_or_default();
    format!(
        r#"{{
  enabled: true,
  default_permission: "deny",
  rules: [
    {{ id: "the-agent-speaks", messages: {all}, flows: ["egress"], permission: "allow",
       key_exprs: ["**", "**/@adv/**"] }},
    {{ id: "others-ask", flows: ["ingress"], permission: "allow",
       messages: ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"],
       key_exprs: ["**", "**/@adv/**"] }},
    {{ id: "the-plant-operators-list", messages: ["put"], flows: ["ingress"], permission: "allow",
       key_exprs: [{list}] }},
    {{ id: "lists-held-by-agents", messages: ["reply"], flows: ["ingress"], permission: "allow",
       key_exprs: [{held}] }},
  ],
  subjects: [{{ id: "anyone" }}],
  policies: [{{ rules: ["the-agent-speaks", "others-ask", "the-plant-operators-list", "lists-held-by-agents"],
                subjects: ["anyone"] }}],
}}"#
    )
}

/// An access control that denies, on `flow` (`ingress`: what others send
/// through this session; `egress`: what it sends), every put, delete,
/// queryable, answer and liveliness token under any key (the advanced
/// publishers' `@adv` keys included), and allows everything else.
fn speaking_denied(id: &str, flow: &str) -> String {
    format!(
        r#"{{
  enabled: true,
  default_permission: "allow",
  rules: [
    {{
      id: "{id}",
      messages: ["put", "delete", "declare_queryable", "reply", "liveliness_token"],
      flows: ["{flow}"],
      permission: "deny",
      key_exprs: ["**", "**/@adv/**"],
    }},
  ],
  subjects: [{{ id: "anyone" }}],
  policies: [{{ rules: ["{id}"], subjects: ["anyone"] }}],
}}"#
    )
}

/// Opens a client's session (CLI, tests): it fails when no endpoint it
/// connects to can be reached within [`CLIENT_CONNECT_TIMEOUT_MS`] (for TLS:
/// also when the other side refuses its certificate), rather than waiting
/// silently.
///
/// # Errors
/// The configuration is refused, or nothing can be reached.
pub async fn open(c: &ZenohConfig) -> Result<Session, ZenohError> {
    open_config(client_config(c)?).await
}

/// A client's session configuration: as [`session_config`], giving up on
/// its endpoints after [`CLIENT_CONNECT_TIMEOUT_MS`].
fn client_config(c: &ZenohConfig) -> Result<zenoh::Config, ZenohError> {
    let mut cfg = session_config(c)?;
    if !c.connect.is_empty() {
        set(
            &mut cfg,
            "connect/timeout_ms",
            CLIENT_CONNECT_TIMEOUT_MS.to_string(),
        )?;
        set(&mut cfg, "connect/exit_on_failure", "true".into())?;
    }
    Ok(cfg)
}

/// How long a client tries its endpoints before giving up, ms.
pub const CLIENT_CONNECT_TIMEOUT_MS: u64 = 10_000;

/// Opens a session. A client is opened again, on a fresh runtime, until
/// [`CLIENT_CONNECT_TIMEOUT_MS`] has passed: a router that answers after
/// its [`CLIENT_OPEN_TIMEOUT_MS`] (a host starved as fifty agents start)
/// leaves the runtime a link to it all the same, and the next router of
/// the list is then refused (a client has one north-bound link), so that
/// one try fails although both routers are up.
async fn open_config(cfg: zenoh::Config) -> Result<Session, ZenohError> {
    let client = cfg.get_json("mode").ok().as_deref() == Some("\"client\"");
    let deadline =
        tokio::time::Instant::now() + std::time::Duration::from_millis(CLIENT_CONNECT_TIMEOUT_MS);
    let mut backoff = Backoff::new(
        std::time::Duration::from_millis(250),
        std::time::Duration::from_secs(2),
    );
    loop {
        match zenoh::open(cfg.clone()).await {
            Ok(session) => return Ok(session),
            Err(e) if client && tokio::time::Instant::now() + backoff.peek() < deadline => {
                let wait = backoff.next_wait();
                tracing::warn!(error = %e, "cannot open the zenoh session; trying again in {wait:?}");
                tokio::time::sleep(wait).await;
            }
            Err(e) => return Err(ZenohError::Open(e)),
        }
    }
}

/// Opens the agent's session: as [`open`], no message larger than
/// [`MAX_MESSAGE_BYTES`] is accepted from the network (Zenoh
/// drops it while reassembling), so whatever arrives, the agent's memory
/// stays bounded; and its access control ([`agent_access_control`]) lets
/// nobody else publish or answer through it.
///
/// # Errors
/// As [`open`].
pub async fn open_agent(c: &ZenohConfig) -> Result<Session, ZenohError> {
    let mut cfg = session_config(c)?;
    set(
        &mut cfg,
        "transport/link/rx/max_message_size",
        MAX_MESSAGE_BYTES.to_string(),
    )?;
    let root = crate::bus::keys::root_of(&c.prefix);
    set(&mut cfg, "access_control", agent_access_control(root))?;
    open_config(cfg).await
}

/// Opens the console's session: a client (as [`open`]) that accepts no
/// message over [`CONSOLE_MAX_MESSAGE_BYTES`] and, by its own access
/// control, sends no put, delete, answer, queryable or liveliness token:
/// it reads the bus and asks agents (forwarding operators' signed
/// commands), nothing more.
///
/// # Errors
/// As [`open`].
pub async fn open_console(c: &ZenohConfig) -> Result<Session, ZenohError> {
    let mut cfg = client_config(c)?;
    set(
        &mut cfg,
        "transport/link/rx/max_message_size",
        CONSOLE_MAX_MESSAGE_BYTES.to_string(),
    )?;
    set(
        &mut cfg,
        "access_control",
        speaking_denied("the-console-only-reads-and-asks", "egress"),
    )?;
    open_config(cfg).await
}

/// The largest message the console's session accepts: a snapshot of a
/// cell with many tags and alarms is larger than an agent's limit.
pub const CONSOLE_MAX_MESSAGE_BYTES: usize = 8 << 20;

/// The largest message the agent's Zenoh session accepts; a larger one is
/// dropped by Zenoh before it reaches the agent.
pub const MAX_MESSAGE_BYTES: usize = 1 << 20;

#[cfg(test)]
mod tests {
    use super::*;

    /// A plain client (as a test bus is) of `connect`.
    fn client(connect: &[&str]) -> ZenohConfig {
        ZenohConfig {
            mode: ZenohMode::Client,
            connect: connect.iter().map(|e| e.to_string()).collect(),
            listen: Vec::new(),
            prefix: "cellwatch/m01".into(),
            multicast_scouting: false,
            tls: None,
            config_file: None,
            plain: true,
            signing_key: None,
        }
    }

    const TWO: [&str; 2] = ["tcp/127.0.0.1:7447", "tcp/127.0.0.1:7448"];

    #[test]
    fn a_client_of_several_routers_gives_one_that_is_gone_three_seconds() {
        let two = session_config(&client(&TWO)).unwrap();
        assert_eq!(
            two.get_json(OPEN_TIMEOUT).unwrap(),
            CLIENT_OPEN_TIMEOUT_MS.to_string()
        );
        // One router: nothing to move to, Zenoh's own.
        let one = session_config(&client(&TWO[..1])).unwrap();
        assert_eq!(one.get_json(OPEN_TIMEOUT).unwrap(), ZENOH_OPEN_TIMEOUT);
        let peer = session_config(&ZenohConfig {
            mode: ZenohMode::Peer,
            ..client(&TWO)
        })
        .unwrap();
        assert_eq!(peer.get_json(OPEN_TIMEOUT).unwrap(), ZENOH_OPEN_TIMEOUT);
    }

    #[test]
    fn a_zenoh_files_own_open_timeout_is_kept() {
        let d = tempfile::tempdir().unwrap();
        let file = d.path().join("zenoh.json5");
        std::fs::write(&file, "{ transport: { unicast: { open_timeout: 5000 } } }").unwrap();
        let cfg = session_config(&ZenohConfig {
            config_file: Some(file),
            ..client(&TWO)
        })
        .unwrap();
        assert_eq!(cfg.get_json(OPEN_TIMEOUT).unwrap(), "5000");
    }
}
