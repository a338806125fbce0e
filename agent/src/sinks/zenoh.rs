//! Zenoh: where alarms and machine state go, and where services answer.
//!
//! Keys under the cell's prefix (default `cellwatch/<cell>`):
//! - `alarms/<alarm-id>`: alarm events ([`crate::payload::AlarmPayload`]),
//!   published with zenoh-ext's advanced publisher: a cache and sample-miss
//!   detection, so a subscriber that was away recovers what it missed, and
//!   a late joiner gets recent history;
//! - `state`: the machine state ([`crate::payload::StatePayload`]) on every
//!   change and periodically, cached so a late joiner sees the current one;
//! - `history`, `snapshot`, `command`: queryables (see [`crate::cell`]);
//! - `agent`: a liveliness token, gone when the agent dies.
//!
//! Scaling to a plant is Zenoh's job: agents run in client mode against
//! `zenohd` routers; nothing here changes.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::Mutex;
use zenoh::liveliness::LivelinessToken;
use zenoh::Session;
use zenoh_ext::{AdvancedPublisher, AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};

use crate::config::{ZenohConfig, ZenohMode};
use crate::metrics::Metrics;

/// How many alarm events of each alarm a publisher keeps for recovery.
const ALARM_CACHE: usize = 256;

/// Builds the zenoh session configuration.
///
/// # Errors
/// An endpoint zenoh does not accept.
pub fn session_config(c: &ZenohConfig) -> Result<zenoh::Config, String> {
    let mut cfg = zenoh::Config::default();
    let set = |cfg: &mut zenoh::Config, key: &str, value: String| {
        cfg.insert_json5(key, &value)
            .map_err(|e| format!("zenoh {key} = {value}: {e}"))
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
pub async fn open(c: &ZenohConfig) -> Result<Session, String> {
    let cfg = session_config(c)?;
    zenoh::open(cfg)
        .await
        .map_err(|e| format!("cannot open the zenoh session: {e}"))
}

/// The publishing side of one agent.
pub struct ZenohSink {
    session: Session,
    prefix: String,
    /// One advanced publisher per alarm id, declared on first use.
    alarms: Mutex<HashMap<String, Arc<AdvancedPublisher<'static>>>>,
    state: AdvancedPublisher<'static>,
    _agent: LivelinessToken,
    metrics: Arc<Metrics>,
}

impl ZenohSink {
    /// Declares the state publisher and the liveliness token.
    ///
    /// # Errors
    /// Zenoh refuses a declaration.
    pub async fn start(
        session: Session,
        prefix: &str,
        metrics: Arc<Metrics>,
    ) -> Result<ZenohSink, String> {
        let state = session
            .declare_publisher(format!("{prefix}/state"))
            .cache(CacheConfig::default().max_samples(1))
            .publisher_detection()
            .await
            .map_err(|e| format!("cannot declare {prefix}/state: {e}"))?;
        let agent = session
            .liveliness()
            .declare_token(format!("{prefix}/agent"))
            .await
            .map_err(|e| format!("cannot declare {prefix}/agent: {e}"))?;
        Ok(ZenohSink {
            session,
            prefix: prefix.into(),
            alarms: Mutex::new(HashMap::new()),
            state,
            _agent: agent,
            metrics,
        })
    }

    /// The session, for queryables.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// The key prefix.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// Publishes an alarm event on `alarms/<id>`.
    pub async fn alarm(&self, id: &str, json: String) {
        let publisher = {
            let mut map = self.alarms.lock().await;
            match map.get(id) {
                Some(p) => p.clone(),
                None => {
                    let declared = self
                        .session
                        .declare_publisher(format!("{}/alarms/{id}", self.prefix))
                        .cache(CacheConfig::default().max_samples(ALARM_CACHE))
                        .sample_miss_detection(
                            MissDetectionConfig::default().heartbeat(Duration::from_millis(500)),
                        )
                        .publisher_detection()
                        .await;
                    match declared {
                        Ok(p) => {
                            let p = Arc::new(p);
                            map.insert(id.to_string(), p.clone());
                            p
                        }
                        Err(e) => {
                            tracing::error!(alarm = id, error = %e, "cannot declare the alarm publisher");
                            self.metrics.zenoh_publish_errors.inc();
                            return;
                        }
                    }
                }
            }
        };
        if let Err(e) = publisher.put(json).await {
            tracing::error!(alarm = id, error = %e, "alarm publication failed");
            self.metrics.zenoh_publish_errors.inc();
        }
    }

    /// Publishes the machine state on `state`.
    pub async fn state(&self, json: String) {
        if let Err(e) = self.state.put(json).await {
            tracing::error!(error = %e, "state publication failed");
            self.metrics.zenoh_publish_errors.inc();
        }
    }
}
