//! The cell task: one per agent, owning the engine.
//!
//! [`start`] wires the parts: the OPC UA source feeds tag events into the
//! engine; every engine event goes to the journal, to Zenoh and to the
//! metrics (and, for the demo, to an observer that prints it). The same
//! task answers the Zenoh services, so they see exactly the engine's state:
//! - `<prefix>/history?since=1h;until=...;kind=state|alarm|command;limit=N`:
//!   journal rows as a JSON array, oldest first;
//! - `<prefix>/snapshot`: tag values with quality, active alarms, and the
//!   values at the last fault;
//! - `<prefix>/command`: a signed [`crate::operator::Command`]; the reply
//!   says whether it was carried out.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use cellwatch_models::alarm::Transition;
use cellwatch_models::engine::{
    CellEngine, EngineEvent, HistoryKind, MachineState, SwitchingChecks,
};
use serde::Serialize;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use zenoh::query::Query;

use crate::clock::{now_ms, parse_time, rfc3339};
use crate::config::CellConfig;
use crate::metrics::Metrics;
use crate::operator::{Command, Gate, OperatorKeys};
use crate::payload::{transition_name, AlarmPayload, StatePayload};
use crate::sinks::journal::{self, Entry, HistoryQuery, Journal};
use crate::sinks::zenoh::ZenohSink;
use crate::sources::{opcua, SourceEvent};

/// What the agent tells an observer (the demo's console).
#[derive(Debug, Clone)]
pub enum Notice {
    /// An alarm transition, as published.
    Alarm(AlarmPayload),
    /// A machine-state change, as published.
    State(StatePayload),
    /// The PLC connection came up (true) or went down, and why.
    Connection(bool, String),
}

/// A running agent.
pub struct Agent {
    stop: watch::Sender<bool>,
    task: JoinHandle<()>,
    metrics: Arc<Metrics>,
    metrics_addr: Option<SocketAddr>,
    committed: watch::Receiver<u64>,
}

impl Agent {
    /// Where `/metrics` is served, if it is.
    pub fn metrics_addr(&self) -> Option<SocketAddr> {
        self.metrics_addr
    }

    /// The metrics.
    pub fn metrics(&self) -> &Arc<Metrics> {
        &self.metrics
    }

    /// Rows committed to the journal so far.
    pub fn committed(&self) -> watch::Receiver<u64> {
        self.committed.clone()
    }

    /// Stops the agent and waits for it.
    pub async fn stop(self) {
        let _ = self.stop.send(true);
        let _ = self.task.await;
    }

    /// Waits until the agent stops by itself (it only does on fatal errors).
    pub async fn wait(&mut self) {
        let _ = (&mut self.task).await;
    }
}

/// Starts an agent for `config`. `observer`, if given, hears every alarm and
/// state change.
///
/// # Errors
/// The journal, Zenoh, the metrics port or the operator keys cannot be set up.
pub async fn start(
    config: CellConfig,
    observer: Option<mpsc::UnboundedSender<Notice>>,
) -> Result<Agent, String> {
    for w in &config.warnings {
        tracing::warn!("{w}");
    }
    let metrics = Arc::new(Metrics::new(&config.cell));
    let journal = Journal::start(
        &config.journal.path,
        config.journal.retention,
        (*metrics).clone(),
    )
    .map_err(|e| e.to_string())?;
    let session = crate::sinks::zenoh::open(&config.zenoh).await?;
    let prefix = config.zenoh.prefix.clone();
    let declare = |name: &'static str| {
        let key = format!("{prefix}/{name}");
        let s = session.clone();
        async move {
            s.declare_queryable(key.clone())
                .await
                .map_err(|e| format!("cannot declare {key}: {e}"))
        }
    };
    let history_q = declare("history").await?;
    let snapshot_q = declare("snapshot").await?;
    let command_q = declare("command").await?;
    let sink = ZenohSink::start(session.clone(), &prefix, metrics.clone()).await?;
    let metrics_addr = match config.metrics {
        Some(addr) => {
            let listener = crate::metrics::bind(addr)
                .await
                .map_err(|e| format!("cannot serve metrics on {addr}: {e}"))?;
            let bound = listener.local_addr().ok();
            let m = metrics.clone();
            let session_alive = session.clone();
            tokio::spawn(async move {
                let _keep = session_alive;
                if let Err(e) = crate::metrics::serve(listener, m, std::future::pending()).await {
                    tracing::error!(error = %e, "metrics server stopped");
                }
            });
            bound
        }
        None => None,
    };
    let keys = match &config.secrets_file {
        Some(path) => OperatorKeys::load(path)?,
        None => OperatorKeys::default(),
    };
    let mut sets: Vec<Box<dyn cellwatch_models::engine::CheckSet>> =
        vec![Box::new(SwitchingChecks::new(config.switching.clone()))];
    for t in &config.timers {
        let checks =
            cellwatch_models::timer::checks::TimerChecks::new(&t.id, &t.model, t.severity, |n| {
                crate::config::timer_signal(&config.tags, n)
            })
            .map_err(|e| format!("checks.timers {}: {e}", t.id))?;
        for tr in &t.model.transitions {
            let labels = [format!("{}-{:03}", t.id, tr.id)];
            metrics
                .transition_window_seconds
                .with_label_values(&[labels[0].as_str(), "lo"])
                .set(tr.window_ms[0] as f64 / 1000.0);
            metrics
                .transition_window_seconds
                .with_label_values(&[labels[0].as_str(), "hi"])
                .set(tr.window_ms[1] as f64 / 1000.0);
        }
        sets.push(Box::new(checks));
    }
    let engine = CellEngine::new(
        &config.cell,
        config.engine_tags(),
        sets,
        config.state.clone(),
    )
    .map_err(|e| e.to_string())?;
    let (stop, stop_rx) = watch::channel(false);
    let (source_tx, source_rx) = mpsc::unbounded_channel();
    let source_cfg = config.clone();
    let mut source_stop = stop_rx.clone();
    tokio::spawn(async move {
        let shutdown = async move {
            let _ = source_stop.wait_for(|s| *s).await;
        };
        if let Err(e) = opcua::run(
            &source_cfg.cell,
            &source_cfg.opcua,
            &source_cfg.tags,
            source_tx,
            shutdown,
        )
        .await
        {
            tracing::error!(error = %e, "the OPC UA source cannot run");
        }
    });
    let committed = journal.committed();
    let now = now_ms();
    let cell = Cell {
        gate: Gate::new(&config.cell, keys),
        state_interval: config.state_interval,
        config,
        engine,
        sink,
        journal,
        metrics: metrics.clone(),
        observer,
        state_since: now,
        state_kind: HistoryKind::Offline,
        accounted_until: now,
        last_update: None,
        ever_connected: false,
        counted_state: "offline",
        culprits: std::collections::HashMap::new(),
    };
    let task = tokio::spawn(cell.run(source_rx, history_q, snapshot_q, command_q, stop_rx));
    Ok(Agent {
        stop,
        task,
        metrics,
        metrics_addr,
        committed,
    })
}

type Queryable = zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<Query>>;

/// How long after a timer's deadline the agent waits for an event that may
/// still be in transit before calling it late, ms.
pub const DELIVERY_ALLOWANCE_MS: u64 = 1000;

struct Cell {
    config: CellConfig,
    engine: CellEngine,
    sink: ZenohSink,
    journal: Journal,
    metrics: Arc<Metrics>,
    gate: Gate,
    observer: Option<mpsc::UnboundedSender<Notice>>,
    state_interval: Duration,
    state_since: u64,
    state_kind: HistoryKind,
    /// State time is counted into the metrics up to here.
    accounted_until: u64,
    last_update: Option<u64>,
    ever_connected: bool,
    /// The state whose time the metrics are counting.
    counted_state: &'static str,
    /// Per fault alarm: the element its culprit gauge is set for.
    culprits: std::collections::HashMap<String, Option<String>>,
}

impl Cell {
    async fn run(
        mut self,
        mut source: mpsc::UnboundedReceiver<SourceEvent>,
        history: Queryable,
        snapshot: Queryable,
        command: Queryable,
        mut stop: watch::Receiver<bool>,
    ) {
        let mut tick = tokio::time::interval(Duration::from_millis(250));
        let mut state_tick = tokio::time::interval(self.state_interval);
        loop {
            tokio::select! {
                _ = stop.changed() => if *stop.borrow() { break },
                Some(ev) = source.recv() => self.source(ev).await,
                Ok(q) = history.recv_async() => self.history(q).await,
                Ok(q) = snapshot.recv_async() => self.snapshot(q).await,
                Ok(q) = command.recv_async() => self.command(q).await,
                _ = tick.tick() => self.tick().await,
                _ = state_tick.tick() => self.publish_state(now_ms()).await,
            }
        }
    }

    async fn source(&mut self, ev: SourceEvent) {
        let now = now_ms();
        let events = match ev {
            SourceEvent::Connected => {
                if self.ever_connected {
                    self.metrics.opcua_reconnects.inc();
                }
                self.ever_connected = true;
                self.metrics.opcua_connected.set(1);
                self.notice(Notice::Connection(true, self.config.opcua.endpoint.clone()));
                self.engine.on_connection(true, now)
            }
            SourceEvent::Disconnected(why) => {
                self.metrics.opcua_connected.set(0);
                self.notice(Notice::Connection(false, why));
                self.engine.on_connection(false, now)
            }
            SourceEvent::Reading {
                tag,
                reading,
                source_time,
            } => {
                self.metrics.tag_updates.inc();
                self.last_update = Some(now);
                let before = self.engine.duplicates();
                let ev = self.engine.on_reading(tag, reading, source_time, now);
                self.metrics
                    .duplicate_updates
                    .inc_by(self.engine.duplicates() - before);
                self.metrics.check_evaluations.inc();
                ev
            }
        };
        self.metrics
            .tags_unknown
            .set(self.engine.values().iter().filter(|v| v.is_none()).count() as i64);
        self.dispatch(events).await;
    }

    async fn tick(&mut self) {
        let now = now_ms();
        // Timers judge "late" against the PLC's clock: an event that
        // happened in time but is still on its way (publishing interval,
        // network) must not be called late. Events carry their source
        // timestamps; the deadline is checked with this allowance.
        let events = self
            .engine
            .advance(now.saturating_sub(DELIVERY_ALLOWANCE_MS));
        self.dispatch(events).await;
        self.metrics.add_state_time(
            self.counted_state,
            now.saturating_sub(self.accounted_until) as f64 / 1000.0,
        );
        self.accounted_until = now;
        if let Some(t) = self.last_update {
            self.metrics
                .last_update_age
                .set(now.saturating_sub(t) as f64 / 1000.0);
        }
    }

    fn notice(&self, n: Notice) {
        if let Some(o) = &self.observer {
            let _ = o.send(n);
        }
    }

    async fn dispatch(&mut self, events: Vec<EngineEvent>) {
        for o in self.engine.take_observations() {
            self.metrics
                .transition_seconds
                .with_label_values(&[o.check.as_str()])
                .observe(o.ms as f64 / 1000.0);
        }
        for ev in events {
            match ev {
                EngineEvent::Alarm {
                    alarm,
                    transition,
                    at,
                } => {
                    let payload = AlarmPayload::new(&self.config.cell, &alarm, transition, at);
                    let json = serde_json::to_string(&payload).unwrap_or_default();
                    self.journal
                        .write(Entry::Alarm {
                            at,
                            alarm: alarm.id.clone(),
                            kind: alarm.kind.as_str().into(),
                            severity: alarm.severity.as_str().into(),
                            transition: transition_name(transition).into(),
                            payload: json.clone(),
                        })
                        .await;
                    self.sink.alarm(&alarm.id, json).await;
                    if transition == Transition::Raised {
                        self.metrics.raised(&alarm.id, alarm.kind, alarm.severity);
                    }
                    if matches!(
                        alarm.kind,
                        cellwatch_models::alarm::AlarmKind::Switching
                            | cellwatch_models::alarm::AlarmKind::Timer
                    ) {
                        let element = alarm
                            .active
                            .then(|| alarm.element().map(str::to_string))
                            .flatten();
                        let previous = self
                            .culprits
                            .insert(alarm.id.clone(), element.clone())
                            .flatten();
                        self.metrics.culprit(
                            &alarm.id,
                            alarm.severity.as_str(),
                            &alarm.fault_type,
                            element.as_deref(),
                            previous.as_deref(),
                            transition == Transition::Raised,
                        );
                    }
                    self.update_active();
                    self.notice(Notice::Alarm(payload));
                }
                EngineEvent::State { state, kind, at } => {
                    let previous = std::mem::replace(&mut self.counted_state, state.name());
                    self.metrics.state(
                        state.name(),
                        previous,
                        at.saturating_sub(self.accounted_until) as f64 / 1000.0,
                    );
                    self.accounted_until = at;
                    self.state_since = at;
                    self.state_kind = kind;
                    let (fault_type, element) = match &state {
                        MachineState::Fault {
                            fault_type,
                            element,
                        } => (Some(fault_type.clone()), element.clone()),
                        _ => (None, None),
                    };
                    self.journal
                        .write(Entry::State {
                            at,
                            kind: kind.as_str().into(),
                            state: state.name().into(),
                            fault_type,
                            element,
                        })
                        .await;
                    self.publish_state(at).await;
                }
            }
        }
    }

    fn update_active(&self) {
        let mut counts = Vec::new();
        for a in self.engine.alarms().filter(|a| a.active) {
            counts.push((a.kind, a.severity, 1));
        }
        self.metrics.set_active(&counts);
    }

    async fn publish_state(&mut self, at: u64) {
        let payload = StatePayload::new(
            &self.config.cell,
            self.engine.state(),
            self.state_kind,
            self.state_since,
            at,
        );
        self.notice(Notice::State(payload.clone()));
        self.sink
            .state(serde_json::to_string(&payload).unwrap_or_default())
            .await;
    }

    async fn history(&mut self, q: Query) {
        let params = parameters(q.parameters().as_str());
        let now = now_ms();
        let parsed = (|| -> Result<HistoryQuery, String> {
            Ok(HistoryQuery {
                since: params
                    .get("since")
                    .map(|s| parse_time(s, now))
                    .transpose()?,
                until: params
                    .get("until")
                    .map(|s| parse_time(s, now))
                    .transpose()?,
                kind: params.get("kind").cloned(),
                limit: params
                    .get("limit")
                    .map(|l| {
                        l.parse()
                            .map_err(|_| format!("limit '{l}' is not a number"))
                    })
                    .transpose()?,
            })
        })();
        // Answered from its own task: a long query must not hold up the
        // engine.
        let path = self.journal.path().to_path_buf();
        let metrics = self.metrics.clone();
        tokio::spawn(async move {
            let result = match parsed {
                Ok(query) => tokio::task::spawn_blocking(move || {
                    let conn = journal::open_read(&path).map_err(|e| e.to_string())?;
                    journal::history(&conn, &query)
                })
                .await
                .unwrap_or_else(|e| Err(e.to_string())),
                Err(e) => Err(e),
            };
            reply(
                &metrics,
                q,
                result.map(|rows| serde_json::to_string(&rows).unwrap_or_default()),
            )
            .await;
        });
    }

    async fn snapshot(&mut self, q: Query) {
        #[derive(Serialize)]
        struct TagValue<'a> {
            name: &'a str,
            address: &'a str,
            value: Option<bool>,
            quality: &'static str,
        }
        #[derive(Serialize)]
        struct LastFault<'a> {
            alarm: &'a str,
            at: String,
            values: Vec<TagValue<'a>>,
        }
        #[derive(Serialize)]
        struct Snapshot<'a> {
            schema: &'static str,
            cell: &'a str,
            at: String,
            connected: bool,
            state: &'static str,
            tags: Vec<TagValue<'a>>,
            alarms: Vec<AlarmPayload>,
            last_fault: Option<LastFault<'a>>,
        }
        let bad: std::collections::HashSet<usize> = self.engine.bad_tags().collect();
        let tags = self.engine.tags();
        let value = |i: usize, v: Option<bool>, current: bool| TagValue {
            name: &tags[i].name,
            address: tags[i].address.name(),
            value: v,
            quality: match (v, current && bad.contains(&i)) {
                (_, true) => "bad",
                (Some(_), false) => "good",
                (None, false) => "unknown",
            },
        };
        let now = now_ms();
        let snap = Snapshot {
            schema: "cellwatch.snapshot.v1",
            cell: &self.config.cell,
            at: rfc3339(now),
            connected: self.engine.connected(),
            state: self.engine.state().name(),
            tags: self
                .engine
                .values()
                .iter()
                .enumerate()
                .map(|(i, v)| value(i, *v, true))
                .collect(),
            alarms: self
                .engine
                .alarms()
                .filter(|a| a.active || !a.acknowledged)
                .map(|a| AlarmPayload::new(&self.config.cell, a, Transition::Updated, now))
                .collect(),
            last_fault: self.engine.last_fault().map(|f| LastFault {
                alarm: &f.alarm,
                at: rfc3339(f.at),
                values: f
                    .values
                    .iter()
                    .enumerate()
                    .map(|(i, v)| value(i, *v, false))
                    .collect(),
            }),
        };
        let json = serde_json::to_string(&snap).unwrap_or_default();
        self.reply(q, Ok(json)).await;
    }

    async fn command(&mut self, q: Query) {
        #[derive(Serialize)]
        struct Outcome<'a> {
            accepted: bool,
            detail: &'a str,
        }
        let now = now_ms();
        let text = q
            .payload()
            .and_then(|p| p.try_to_string().ok())
            .map(|s| s.into_owned())
            .unwrap_or_default();
        let (cmd, outcome) = match serde_json::from_str::<Command>(&text) {
            Err(e) => (None, Err(format!("not a command: {e}"))),
            Ok(cmd) => {
                let outcome = match self.gate.check(&cmd, now) {
                    Err(why) => Err(why),
                    Ok(()) => {
                        let done = match cmd.action.as_str() {
                            "ack" => self.engine.acknowledge(&cmd.alarm, &cmd.operator, now),
                            _ => self.engine.reset(&cmd.alarm, &cmd.operator, now),
                        };
                        match done {
                            Ok(events) => {
                                self.dispatch(events).await;
                                Ok(format!("{} {} by {}", cmd.action, cmd.alarm, cmd.operator))
                            }
                            Err(e) => Err(e.to_string()),
                        }
                    }
                };
                (Some(cmd), outcome)
            }
        };
        let (accepted, detail) = match &outcome {
            Ok(d) => (true, d.clone()),
            Err(e) => (false, e.clone()),
        };
        self.metrics.command(
            cmd.as_ref().map_or("other", |c| c.action.as_str()),
            if accepted { "accepted" } else { "refused" },
        );
        if !accepted {
            tracing::warn!(detail = %detail, "operator command refused");
        }
        self.journal
            .write(Entry::Command {
                at: now,
                operator: cmd
                    .as_ref()
                    .map_or_else(String::new, |c| c.operator.clone()),
                action: cmd
                    .as_ref()
                    .map_or_else(|| "invalid".into(), |c| c.action.clone()),
                alarm: cmd.as_ref().map_or_else(String::new, |c| c.alarm.clone()),
                nonce: cmd.as_ref().map_or_else(String::new, |c| c.nonce.clone()),
                accepted,
                detail: detail.clone(),
            })
            .await;
        let json = serde_json::to_string(&Outcome {
            accepted,
            detail: &detail,
        })
        .unwrap_or_default();
        self.reply(q, Ok(json)).await;
    }

    async fn reply(&self, q: Query, result: Result<String, String>) {
        reply(&self.metrics, q, result).await;
    }
}

/// Answers a query with JSON, or with an error text.
async fn reply(metrics: &Metrics, q: Query, result: Result<String, String>) {
    let key = q.key_expr().clone();
    let sent = match result {
        Ok(json) => q.reply(key, json).await,
        Err(e) => q.reply_err(e).await,
    };
    if let Err(e) = sent {
        tracing::warn!(error = %e, "reply failed");
        metrics.zenoh_publish_errors.inc();
    }
}

/// Selector parameters (`since=1h;kind=state`, `&` also accepted).
fn parameters(text: &str) -> std::collections::HashMap<String, String> {
    text.split([';', '&'])
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .collect()
}
