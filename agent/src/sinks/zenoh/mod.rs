//! Publication on the bus: alarm events, machine state and alarms' flight
//! recordings, sealed in signed envelopes ([`crate::bus::envelope`]) —
//! what one step puts under one signature — and the agent's liveliness
//! token. This is the Zenoh sink of the cell loop. What fails on the bus
//! is logged and counted through its events (`events.rs`).

mod events;

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use zenoh::liveliness::LivelinessToken;
use zenoh::Session;
use zenoh_ext::{AdvancedPublisher, AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};

use crate::bus::envelope::{AgentKey, MAX_GROUP};
use crate::bus::keys::CellKeys;
use crate::bus::ZenohError;
use crate::metrics::Metrics;
use crate::sinks::Sink;
use crate::step::CellStep;
use events::ZenohEvent;

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
    /// The end of the journal's command chain, as committed: carried in
    /// every state put.
    command_chain: Option<tokio::sync::watch::Receiver<crate::journal::chain::Link>>,
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
            command_chain: None,
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

    /// The publisher of `alarms/<id>`, declared on first use; `None`: Zenoh
    /// refused it (logged and counted).
    async fn alarm_publisher(&mut self, id: &str) -> Option<Arc<AdvancedPublisher<'static>>> {
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
                        Err(error) => {
                            let (alarm, error) = (id, &error);
                            ZenohEvent::PublisherRefused { alarm, error }.emit(&self.metrics);
                            return None;
                        }
                    }
                }
            }
        };
        Some(publisher)
    }

    /// Carries `chain`, the journal's command chain as committed, in every
    /// state put: its head signed on the bus, off the agent's disk.
    pub fn anchoring(
        self,
        chain: tokio::sync::watch::Receiver<crate::journal::chain::Link>,
    ) -> Self {
        ZenohPublisher {
            command_chain: Some(chain),
            ..self
        }
    }

    /// Puts what `step` publishes: its alarm events on `alarms/<id>`, the
    /// machine state on `state`, the flight recordings that ended on
    /// `recordings/<id>` (once, not kept for late joiners: the history
    /// service has them) — sealed together, one signature for the step
    /// (each envelope written as it is put).
    async fn publish(&mut self, step: &CellStep) {
        let mut to: Vec<(Put, String, &str)> = Vec::new();
        for a in &step.alarms {
            if let Some(p) = self.alarm_publisher(&a.payload.id).await {
                to.push((
                    Put::Alarm(&a.payload.id, p),
                    self.keys.alarm(&a.payload.id),
                    &a.json,
                ));
            }
        }
        let state = step.state.as_ref().map(|s| {
            let head = self
                .command_chain
                .as_ref()
                .map(|c| Box::new(c.borrow().announced()));
            let s = crate::payload::StatePayload {
                command_chain: head,
                ..s.clone()
            };
            serde_json::to_string(&s).unwrap_or_default()
        });
        if let Some(json) = &state {
            to.push((Put::State, self.keys.state(), json));
        }
        for (r, json) in step.engine.recordings.iter().zip(&step.recordings) {
            to.push((
                Put::Recording(&r.alarm),
                self.keys.recording(&r.alarm),
                json,
            ));
        }
        let at = crate::clock::now_ms();
        for chunk in to.chunks(MAX_GROUP) {
            let puts: Vec<(&str, &str)> = chunk.iter().map(|(_, k, b)| (k.as_str(), *b)).collect();
            let sealed = self.key.seal_puts(at, &puts);
            for (i, (put, key, body)) in chunk.iter().enumerate() {
                let envelope = sealed.envelope(i, key, body);
                let (what, result) = match put {
                    Put::Alarm(id, publisher) => (*id, publisher.put(envelope).await),
                    Put::State => ("state", self.state.put(envelope).await),
                    Put::Recording(id) => (*id, self.session.put(key, envelope).await),
                };
                if let Err(error) = result {
                    let error = &error;
                    ZenohEvent::PutFailed { key, what, error }.emit(&self.metrics);
                }
            }
        }
    }
}

/// Where one of a step's sealed payloads goes.
enum Put<'a> {
    /// An alarm event, on its alarm's publisher.
    Alarm(&'a str, Arc<AdvancedPublisher<'static>>),
    /// The machine state, on the state publisher.
    State,
    /// A flight recording, put once on the session.
    Recording(&'a str),
}

impl Sink for ZenohPublisher {
    fn name(&self) -> &'static str {
        "zenoh"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        self.publish(step).boxed()
    }

    fn close(self: Box<Self>) -> BoxFuture<'static, ()> {
        async move {
            let ZenohPublisher {
                agent,
                alarms,
                state,
                metrics,
                ..
            } = *self;
            if let Err(error) = agent.undeclare().await {
                ZenohEvent::TokenNotUndeclared { error: &error }.emit(&metrics);
            }
            drop(alarms);
            drop(state);
        }
        .boxed()
    }
}
