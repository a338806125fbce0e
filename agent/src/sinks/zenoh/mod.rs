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
//! - `agent`: a liveliness token, gone when the agent stops or dies.
//!
//! [`publish::ZenohPublisher`] is the sink; [`services::Services`] answers
//! queries. Scaling to a plant is Zenoh's job: agents run in client mode
//! against `zenohd` routers; nothing here changes.

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

/// Builds the zenoh session configuration.
///
/// # Errors
/// An endpoint zenoh does not accept.
pub fn session_config(c: &ZenohConfig) -> Result<zenoh::Config, ZenohError> {
    let mut cfg = zenoh::Config::default();
    let set = |cfg: &mut zenoh::Config, key: &str, value: String| {
        cfg.insert_json5(key, &value)
            .map_err(|e| ZenohError::Config {
                key: key.into(),
                value: value.clone(),
                reason: e.to_string(),
            })
    };
    set(&mut cfg, "mode", format!("\"{}\"", c.mode.as_str()))?;
    set(
        &mut cfg,
        "connect/endpoints",
        serde_json::to_string(&c.connect).unwrap_or_default(),
    )?;
    if !c.listen.is_empty() || c.mode != ZenohMode::Client {
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
    set(&mut cfg, "timestamping/enabled", "true".into())?;
    Ok(cfg)
}

/// Opens a zenoh session.
///
/// # Errors
/// The configuration is refused or the endpoints cannot be bound.
pub async fn open(c: &ZenohConfig) -> Result<Session, ZenohError> {
    open_config(session_config(c)?).await
}

async fn open_config(cfg: zenoh::Config) -> Result<Session, ZenohError> {
    zenoh::open(cfg)
        .await
        .map_err(|e| ZenohError::Open(e.to_string()))
}

/// Opens the agent's session: as [`open`], and no message larger than
/// [`services::MAX_MESSAGE_BYTES`] is accepted from the network (Zenoh
/// drops it while reassembling), so whatever arrives, the agent's memory
/// stays bounded.
///
/// # Errors
/// As [`open`].
pub async fn open_agent(c: &ZenohConfig) -> Result<Session, ZenohError> {
    let mut cfg = session_config(c)?;
    let key = "transport/link/rx/max_message_size";
    let value = services::MAX_MESSAGE_BYTES.to_string();
    cfg.insert_json5(key, &value)
        .map_err(|e| ZenohError::Config {
            key: key.into(),
            value,
            reason: e.to_string(),
        })?;
    open_config(cfg).await
}
