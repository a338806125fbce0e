//! Zenoh: where alarms and machine state go, and where services answer.
//!
//! Keys under the cell's prefix (default `cellwatch/<cell>`):
//! - `alarms/<alarm-id>`: alarm events ([`crate::payload::AlarmPayload`]),
//!   published with zenoh-ext's advanced publisher: a cache and sample-miss
//!   detection, so a subscriber that was away recovers what it missed, and
//!   a late joiner gets recent history;
//! - `state`: the machine state ([`crate::payload::StatePayload`]) on every
//!   change and periodically, cached so a late joiner sees the current one;
//! - `history`, `snapshot`, `command`: queryables ([`services`]);
//! - `agent/<zenoh id>`: a liveliness token naming the agent's session,
//!   gone when the agent stops or dies; clients accept answers for the cell
//!   from that session only.
//!
//! [`publish::ZenohPublisher`] is the sink; [`services::Services`] answers
//! queries. Scaling to a plant is Zenoh's job: agents run in client mode
//! against `zenohd` routers; nothing here changes.

pub mod certs;
pub mod publish;
pub mod services;

use zenoh::Session;

use crate::config::{ZenohConfig, ZenohMode};

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
    Open(String),
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
/// is named, with cellwatch's settings laid over it.
///
/// # Errors
/// The file cannot be read, or a value zenoh does not accept.
pub fn session_config(c: &ZenohConfig) -> Result<zenoh::Config, ZenohError> {
    let mut cfg = match &c.config_file {
        Some(path) => zenoh::Config::from_file(path).map_err(|e| ZenohError::Config {
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
    if !c.listen.is_empty() || (c.mode != ZenohMode::Client && c.config_file.is_none()) {
        set(
            &mut cfg,
            "listen/endpoints",
            serde_json::to_string(&c.listen).unwrap_or_default(),
        )?;
    }
    set(
        &mut cfg,
        "scouting/multicast/enabled",
        c.multicast_scouting.to_string(),
    )?;
    if !c.multicast_scouting && c.config_file.is_none() {
        // Links only to the endpoints configured: a node met through
        // another is not connected to directly, so every path to this one
        // goes through the nodes it chose (and their access control).
        set(&mut cfg, "scouting/gossip/enabled", "false".into())?;
    }
    set(&mut cfg, "timestamping/enabled", "true".into())?;
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
    Ok(cfg)
}

fn set(cfg: &mut zenoh::Config, key: &str, value: String) -> Result<(), ZenohError> {
    cfg.insert_json5(key, &value)
        .map_err(|e| ZenohError::Config {
            key: key.into(),
            value: value.clone(),
            reason: e.to_string(),
        })
}

/// The access control of an agent's own session: nobody else may publish,
/// delete, declare a queryable, answer or hold a liveliness token under the
/// agent's prefix through it. Everything else (subscribing, querying) is
/// allowed; who may reach the agent at all is TLS's business.
pub fn agent_access_control(prefix: &str) -> String {
    let keys =
        serde_json::to_string(&[prefix.to_string(), format!("{prefix}/**")]).unwrap_or_default();
    format!(
        r#"{{
  enabled: true,
  default_permission: "allow",
  rules: [
    {{
      id: "only-this-agent-speaks-for-its-cell",
      messages: ["put", "delete", "declare_queryable", "reply", "liveliness_token"],
      flows: ["ingress"],
      permission: "deny",
      key_exprs: {keys},
    }},
  ],
  subjects: [{{ id: "anyone" }}],
  policies: [{{ rules: ["only-this-agent-speaks-for-its-cell"], subjects: ["anyone"] }}],
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
    let mut cfg = session_config(c)?;
    if !c.connect.is_empty() {
        set(
            &mut cfg,
            "connect/timeout_ms",
            CLIENT_CONNECT_TIMEOUT_MS.to_string(),
        )?;
        set(&mut cfg, "connect/exit_on_failure", "true".into())?;
    }
    open_config(cfg).await
}

/// How long a client tries its endpoints before giving up, ms.
pub const CLIENT_CONNECT_TIMEOUT_MS: u64 = 10_000;

async fn open_config(cfg: zenoh::Config) -> Result<Session, ZenohError> {
    zenoh::open(cfg)
        .await
        .map_err(|e| ZenohError::Open(e.to_string()))
}

/// Opens the agent's session: as [`open`], no message larger than
/// [`services::MAX_MESSAGE_BYTES`] is accepted from the network (Zenoh
/// drops it while reassembling), so whatever arrives, the agent's memory
/// stays bounded; and its access control ([`agent_access_control`]) lets
/// nobody else publish or answer under its prefix through it.
///
/// # Errors
/// As [`open`].
pub async fn open_agent(c: &ZenohConfig) -> Result<Session, ZenohError> {
    let mut cfg = session_config(c)?;
    set(
        &mut cfg,
        "transport/link/rx/max_message_size",
        services::MAX_MESSAGE_BYTES.to_string(),
    )?;
    set(&mut cfg, "access_control", agent_access_control(&c.prefix))?;
    open_config(cfg).await
}
