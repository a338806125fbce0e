//! Publication on the bus: alarm events, machine state and alarms' flight
//! recordings, each sealed in a signed envelope
//! ([`crate::bus::envelope`]), and the agent's liveliness
//! token. This is the Zenoh sink of the cell loop.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use zenoh::liveliness::LivelinessToken;
use zenoh::Session;
use zenoh_ext::{AdvancedPublisher, AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};

use crate::bus::envelope::{AgentKey, Kind};
use crate::bus::keys::CellKeys;
use crate::bus::ZenohError;
use crate::metrics::Metrics;
use crate::sinks::Sink;
use crate::step::CellStep;

/// How many alarm events of each alarm a publisher keeps for recovery.
const ALARM_CACHE: usize = 256;

/// The publishing side of one agent.
pub struct ZenohPublisher {
    session: Session,
    keys: CellKeys,
    /// One advanced publisher per alarm id, declared on first use.
    alarms: HashMap<String, Arc<AdvancedPublisher<'static>>>,
    state: AdvancedPublisher<'static>,
    /// Present while the agent runs; undeclared by [`Sink::close`].
    agent: LivelinessToken,
    /// Seals every payload put.
    key: Arc<AgentKey>,
    metrics: Arc<Metrics>,
}

impl ZenohPublisher {
    /// Declares the state publisher and the liveliness token.
    ///
    /// # Errors
    /// Zenoh refuses a declaration.
    pub async fn start(
        session: Session,
        prefix: &str,
        key: Arc<AgentKey>,
        metrics: Arc<Metrics>,
    ) -> Result<ZenohPublisher, ZenohError> {
        let declare_error = |key: String| {
            move |e: zenoh::Error| ZenohError::Declare {
                key,
                reason: e.to_string(),
            }
        };
        let keys = CellKeys::new(prefix);
        let state = session
            .declare_publisher(keys.state())
            .cache(CacheConfig::default().max_samples(1))
            .publisher_detection()
            .await
            .map_err(declare_error(keys.state()))?;
        // The token names the session: clients accept answers for the cell
        // from this Zenoh id only.
        let token = keys.agent_token(session.zid());
        let agent = session
            .liveliness()
            .declare_token(token.clone())
            .await
            .map_err(declare_error(token))?;
        Ok(ZenohPublisher {
            session,
            keys,
            alarms: HashMap::new(),
            state,
            agent,
            key,
            metrics,
        })
    }

    /// The session, for queryables.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// The key prefix.
    pub fn prefix(&self) -> &str {
        self.keys.prefix()
    }

    /// Publishes an alarm event on `alarms/<id>`.
    pub async fn alarm(&mut self, id: &str, json: String) {
        let publisher = {
            let map = &mut self.alarms;
            match map.get(id) {
                Some(p) => p.clone(),
                None => {
                    let declared = self
                        .session
                        .declare_publisher(self.keys.alarm(id))
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
        let sealed = self.key.seal(
            Kind::Put,
            &self.keys.alarm(id),
            "",
            crate::clock::now_ms(),
            json,
        );
        if let Err(e) = publisher.put(sealed).await {
            tracing::error!(alarm = id, error = %e, "alarm publication failed");
            self.metrics.zenoh_publish_errors.inc();
        }
    }

    /// Publishes an alarm's flight recording on `recordings/<id>`: once,
    /// not kept for late joiners (the history service has it).
    pub async fn recording(&self, id: &str, json: String) {
        let key = self.keys.recording(id);
        let sealed = self
            .key
            .seal(Kind::Put, &key, "", crate::clock::now_ms(), json);
        if let Err(e) = self.session.put(&key, sealed).await {
            tracing::error!(alarm = id, error = %e, "recording publication failed");
            self.metrics.zenoh_publish_errors.inc();
        }
    }

    /// Publishes the machine state on `state`.
    pub async fn state(&self, json: String) {
        let sealed = self.key.seal(
            Kind::Put,
            &self.keys.state(),
            "",
            crate::clock::now_ms(),
            json,
        );
        if let Err(e) = self.state.put(sealed).await {
            tracing::error!(error = %e, "state publication failed");
            self.metrics.zenoh_publish_errors.inc();
        }
    }
}

impl Sink for ZenohPublisher {
    fn name(&self) -> &'static str {
        "zenoh"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        async move {
            for a in &step.alarms {
                self.alarm(&a.payload.id, a.json.clone()).await;
            }
            if let Some(s) = &step.state {
                self.state(serde_json::to_string(s).unwrap_or_default())
                    .await;
            }
            for (r, json) in step.engine.recordings.iter().zip(&step.recordings) {
                self.recording(&r.alarm, json.clone()).await;
            }
        }
        .boxed()
    }

    fn close(self: Box<Self>) -> BoxFuture<'static, ()> {
        async move {
            let ZenohPublisher {
                agent,
                alarms,
                state,
                ..
            } = *self;
            if let Err(e) = agent.undeclare().await {
                tracing::warn!(error = %e, "cannot undeclare the liveliness token");
            }
            drop(alarms);
            drop(state);
        }
        .boxed()
    }
}
