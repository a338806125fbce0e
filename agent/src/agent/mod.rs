//! A running agent: the parts of one cell wired together, and stopped
//! together.
//!
//! [`start`] compiles the checks, opens the journal and the Zenoh session,
//! declares the services, binds the metrics port, and spawns four owned
//! tasks: the source, the cell loop (on a thread of its own), the services
//! and the metrics server.
//! [`Agent::stop`] ends them all, joins them, and closes the Zenoh session,
//! so its liveliness token disappears and its ports are free again.
//! [`Agent::wait`] returns when the agent cannot go on by itself (its source
//! failed or its cell loop ended, a panic included), so that the process
//! ends and its supervisor starts it again.

use std::net::SocketAddr;
use std::sync::Arc;

use futures_util::FutureExt;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

use crate::bus::envelope::{check_private, AgentKey};
use crate::cell::compile;
use crate::cell::{CellLoop, JOURNAL_ALARM};
use crate::clock::Clock;
use crate::config::CellConfig;
use crate::health::{CellHealth, Health};
use crate::journal::Journal;
use crate::metrics::Metrics;
use crate::operator::{Gate, OperatorKeys};
use crate::services::alarm_server::AlarmServer;
use crate::services::plant_operators::Listener;
use crate::services::Services;
use crate::sinks::alarm_server::AlarmServerSink;
use crate::sinks::console::{ConsoleSink, Notice};
use crate::sinks::journal::JournalSink;
use crate::sinks::metrics::MetricsSink;
use crate::sinks::oee::OeeSink;
use crate::sinks::zenoh::ZenohPublisher;
use crate::sinks::Sink;
use crate::sources::{Source, SourceError, QUEUE_CAPACITY};
use crate::tags::TagConfig;

/// How many service requests may wait for the cell loop.
const REQUEST_CAPACITY: usize = 64;

mod errors;

pub use errors::{Ended, ReloadError, StartError};

/// What a caller may add to an agent.
#[derive(Default)]
pub struct Options {
    /// Hears every alarm, state change and connection change (the demo's
    /// console).
    pub observer: Option<mpsc::UnboundedSender<Notice>>,
    /// Replaces the source the configuration names (tests, replays, the
    /// cells sharing one `@` bus).
    pub source: Option<Box<dyn Source>>,
    /// Where the time comes from (the system's unless a test sets one).
    pub clock: Clock,
    /// More sinks, after the agent's own (journal, bus, metrics, console):
    /// each step goes to them last, inside the cell loop (tests that watch
    /// the steps, or make the loop fail on purpose).
    pub sinks: Vec<Box<dyn Sink>>,
    /// The health of every cell of the process (`/healthz`, `/readyz`,
    /// systemd's watchdog): this agent's cell is added to it; a health of
    /// its own if `None`.
    pub health: Option<Health>,
    /// The agent runs from a configuration file its runner can read again:
    /// an operator's signed `configure reload` is handed to the runner
    /// ([`Agent::next_event`]); refused otherwise.
    pub reads_its_file: bool,
}

/// A running agent.
pub struct Agent {
    /// Tells every task to stop.
    stop: watch::Sender<bool>,
    /// The cell loop; it closes the sinks when it ends.
    cell_loop: Option<JoinHandle<()>>,
    /// The source; its error, if it could not run.
    source: Option<JoinHandle<Result<(), SourceError>>>,
    /// Stops the source alone (a reload that starts another).
    source_stop: watch::Sender<bool>,
    /// The source was built from the configuration (not given): a reload
    /// may start another.
    own_source: bool,
    /// Says when every task must stop (new sources listen to it too).
    stopping: watch::Receiver<bool>,
    /// The Zenoh services (history, snapshot, command).
    services: Option<JoinHandle<()>>,
    /// The `/metrics` server.
    metrics_server: Option<JoinHandle<()>>,
    /// Sends the alarms to Alertmanager; ends after the cell loop.
    alertmanager: Option<JoinHandle<()>>,
    /// The Sparkplug edge node's MQTT session; ends after the cell loop
    /// (its NDEATH said).
    sparkplug: Option<JoinHandle<()>>,
    /// The OPC UA alarm server (`[alarm_server]`); ends with the agent.
    alarm_server: Option<JoinHandle<()>>,
    alarm_server_addr: Option<SocketAddr>,
    /// The alarm server's users, read again on a reload.
    alarm_server_users: Option<crate::services::alarm_server::users::Users>,
    session: zenoh::Session,
    metrics: Arc<Metrics>,
    metrics_addr: Option<SocketAddr>,
    /// Where the source listens for its PLC to connect (reverse connect).
    source_listening: Option<SocketAddr>,
    committed: watch::Receiver<u64>,
    health: (Health, Arc<CellHealth>),
    /// Configurations read again go to the cell loop here.
    reloads: mpsc::Sender<crate::cell::swap::Reload>,
    /// Operators' `configure reload`, for the runner.
    reload_asks: Option<mpsc::Receiver<crate::cell::swap::ReloadAsk>>,
    /// The running configuration's parts only a restart changes.
    fixed: [u64; 13],
    /// What `about` answers (the configuration's hash follows a reload).
    about: Arc<watch::Sender<crate::payload::AboutPayload>>,
}

/// What a reload takes by starting a source ([`crate::config::FIXED_PARTS`]).
const SOURCE_PARTS: [&str; 3] = ["the tags", "[opcua]", "[legacy]"];

/// What a running agent needs from whoever runs it ([`Agent::next_event`]).
pub enum AgentEvent {
    /// It cannot go on by itself.
    Ended(Ended),
    /// An operator asked for its configuration file to be read again:
    /// read it, [`Agent::reload`] it, and answer.
    ReloadAsked(crate::cell::swap::ReloadAsk),
}

/// A configuration taken by a running agent.
#[derive(Debug)]
pub struct Reloaded {
    /// Alarms carried over to the new checks.
    pub carried: usize,
    /// What changed but only a restart takes (the running values go on).
    pub needs_restart: Vec<&'static str>,
}

impl Agent {
    /// Where `/metrics` is served, if it is.
    pub fn metrics_addr(&self) -> Option<SocketAddr> {
        self.metrics_addr
    }

    /// Where the OPC UA alarm server listens, if there is one.
    pub fn alarm_server_addr(&self) -> Option<SocketAddr> {
        self.alarm_server_addr
    }

    /// Where the source listens for the PLC's server to connect to the
    /// agent (`opcua.reverse_listen`; with port 0, the port the system
    /// gave), if it was bound at start.
    pub fn source_listening(&self) -> Option<SocketAddr> {
        self.source_listening
    }

    /// Where the agent's Zenoh session listens, as locators
    /// (`quic/127.0.0.1:7447`): with port 0 in `zenoh.listen`, the port the
    /// system chose.
    pub async fn zenoh_locators(&self) -> Vec<String> {
        self.session
            .info()
            .locators()
            .await
            .iter()
            .map(ToString::to_string)
            .collect()
    }

    /// The metrics.
    pub fn metrics(&self) -> &Arc<Metrics> {
        &self.metrics
    }

    /// Rows committed to the journal so far.
    pub fn committed(&self) -> watch::Receiver<u64> {
        self.committed.clone()
    }

    /// Takes `config`, read again, while running: its checks, limits,
    /// delays, timers, charts, state rules, production counting and
    /// longest shelf replace the running ones in the cell loop, which
    /// carries over every alarm (acknowledged, shelved or out of service
    /// as it was), the machine state and the tags' values
    /// (`cell/reload.rs`). Changed tags or source settings start a source
    /// of their own, which the loop reads from the new engine on; the old
    /// one is stopped (not for a source given to the agent, such as a
    /// shared `@` bus's). What only a restart changes (the journal, the
    /// bus, the metrics and Alertmanager settings, the operators file,
    /// the state interval) is named in [`Reloaded::needs_restart`], the
    /// running values going on; a changed cell id is refused.
    ///
    /// # Errors
    /// See [`ReloadError`]; the running configuration goes on.
    pub async fn reload(&mut self, config: &CellConfig) -> Result<Reloaded, ReloadError> {
        let fixed = config.fixed_parts();
        let changed: Vec<&'static str> = crate::config::FIXED_PARTS
            .iter()
            .zip(fixed.iter().zip(self.fixed))
            .filter(|(_, (new, old))| **new != *old)
            .map(|(name, _)| *name)
            .collect();
        if changed.contains(&"cell.id") {
            return Err(ReloadError::Restart("cell.id".into()));
        }
        // The tags and the source's settings are taken by a source of
        // their own, started beside the running one.
        let by_source = |p: &&str| SOURCE_PARTS.contains(p);
        let new_source = changed.iter().any(by_source);
        if new_source && !self.own_source {
            return Err(ReloadError::Restart(
                "the tags or the source's settings, on a source shared by several cells,".into(),
            ));
        }
        let engine = compile::engine(config)?;
        // The operators and the alarm server's users, read again: a key
        // revoked, an operator's permissions changed, a user added.
        let (keys, held) = crate::services::plant_operators::operators(config.operators_setup())
            .map_err(|e| ReloadError::File(e.to_string()))?;
        let users = match (&self.alarm_server_users, &config.alarm_server) {
            (Some(_), Some(c)) => Some(
                crate::services::alarm_server::users::Users::load(&c.users_file)
                    .map_err(|e| ReloadError::File(e.to_string()))?,
            ),
            _ => None,
        };
        let started = new_source.then(|| self.start_source(config));
        let (done, taken) = tokio::sync::oneshot::channel();
        let (source, task) = match started {
            Some((new, task, stop)) => (Some(new), Some((task, stop))),
            None => (None, None),
        };
        let reload = crate::cell::swap::Reload {
            engine,
            forcing: crate::cell::forcing::Forcing::of(config),
            timers: crate::cell::timers::Timers::of(config),
            max_shelve: config.max_shelve,
            keys,
            keys_version: held.as_ref().map(|h| h.version()),
            source,
            done,
        };
        let outcome = match self.reloads.send(reload).await {
            Err(_) => Err(ReloadError::Refused("the cell loop has ended".into())),
            Ok(()) => taken
                .await
                .map_err(|_| ReloadError::Refused("the cell loop has ended".into()))
                .and_then(|r| r.map_err(ReloadError::Busy)),
        };
        match (outcome, task) {
            (Err(e), Some((task, stop))) => {
                let _ = stop.send(true);
                let _ = task.await;
                Err(e)
            }
            (Err(e), None) => Err(e),
            (Ok(carried), task) => {
                if let (Some(running), Some(users)) = (&self.alarm_server_users, users) {
                    running.replace_with(users);
                }
                if let Some((task, stop)) = task {
                    // The loop reads the new source: the old one goes.
                    let old_stop = std::mem::replace(&mut self.source_stop, stop);
                    let old = self.source.replace(task);
                    let _ = old_stop.send(true);
                    if let Some(old) = old {
                        if tokio::time::timeout(std::time::Duration::from_secs(10), old)
                            .await
                            .is_err()
                        {
                            tracing::warn!("the replaced source took more than 10 s to stop");
                        }
                    }
                }
                // What was taken is what runs now.
                let hash = config.source_sha256.clone();
                self.about.send_modify(|a| a.config_sha256 = hash);
                for (i, part) in crate::config::FIXED_PARTS.iter().enumerate() {
                    if SOURCE_PARTS.contains(part) {
                        self.fixed[i] = fixed[i];
                    }
                }
                Ok(Reloaded {
                    carried,
                    needs_restart: changed.into_iter().filter(|p| !by_source(p)).collect(),
                })
            }
        }
    }

    /// A source for `config`, started; the loop takes its events once it
    /// takes the reload.
    fn start_source(
        &self,
        config: &CellConfig,
    ) -> (
        crate::cell::swap::NewSource,
        JoinHandle<Result<(), SourceError>>,
        watch::Sender<bool>,
    ) {
        let mut source = source_for(config, config.tags.clone());
        source.count_requests(self.metrics.opcua_requests.clone());
        let writer = source.writer();
        let allowance = source.delivery_allowance();
        tracing::info!(cell = %config.cell, source = %source.describe(), "starting a source for the configuration read again");
        let (tx, events) = mpsc::channel(QUEUE_CAPACITY);
        let (stop, stopped) = watch::channel(false);
        let task =
            tokio::spawn(source.run(tx, either_stops(self.stopping.clone(), stopped).boxed()));
        (
            crate::cell::swap::NewSource {
                events,
                writer,
                allowance,
            },
            task,
            stop,
        )
    }

    /// Stops every task, waits for each, and closes the Zenoh session.
    ///
    /// # Panics
    /// A task panicked: its panic goes on once everything else has
    /// stopped, so that a bug is never taken for a clean stop.
    pub async fn stop(mut self) {
        self.health.0.remove(&self.health.1);
        let _ = self.stop.send(true);
        let mut panic = None;
        for task in [
            self.cell_loop.take(),
            self.alertmanager.take(),
            self.sparkplug.take(),
            self.alarm_server.take(),
            self.services.take(),
            self.metrics_server.take(),
        ]
        .into_iter()
        .flatten()
        {
            if let Err(e) = task.await {
                if e.is_panic() && panic.is_none() {
                    panic = Some(e.into_panic());
                }
            }
        }
        if let Some(source) = self.source.take() {
            let _ = source.await;
        }
        if let Err(e) = self.session.close().await {
            tracing::warn!(error = %e, "closing the zenoh session failed");
        }
        if let Some(panic) = panic {
            std::panic::resume_unwind(panic);
        }
    }

    /// Waits until the agent needs its runner: it cannot go on
    /// ([`Agent::wait`]), or an operator asked for its file to be read
    /// again.
    pub async fn next_event(&mut self) -> AgentEvent {
        let Agent {
            source,
            cell_loop,
            reload_asks,
            ..
        } = self;
        let asks = async {
            match reload_asks.as_mut() {
                Some(rx) => match rx.recv().await {
                    Some(ask) => ask,
                    None => std::future::pending().await,
                },
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            ask = asks => AgentEvent::ReloadAsked(ask),
            ended = wait_for(source, cell_loop) => AgentEvent::Ended(ended),
        }
    }

    /// Waits until the agent cannot go on by itself: its source could not
    /// run or ended, or its cell loop ended (a panic: the loop has closed
    /// its sinks, its rows are committed and its liveliness token is
    /// gone). [`Agent::stop`] still stops the rest; a panic reported here
    /// is not raised again there. Pending forever once it has said.
    pub async fn wait(&mut self) -> Ended {
        let Agent {
            source, cell_loop, ..
        } = self;
        wait_for(source, cell_loop).await
    }
}

/// See [`Agent::wait`].
async fn wait_for(
    source: &mut Option<JoinHandle<Result<(), SourceError>>>,
    cell_loop: &mut Option<JoinHandle<()>>,
) -> Ended {
    {
        let from_source = async {
            match source.as_mut() {
                Some(task) => task.await,
                None => std::future::pending().await,
            }
        };
        let from_loop = async {
            match cell_loop.as_mut() {
                Some(task) => task.await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            result = from_source => {
                *source = None;
                match result {
                    Ok(Err(e)) => Ended::Source(e),
                    _ => Ended::SourceStopped,
                }
            }
            result = from_loop => {
                *cell_loop = None;
                match result {
                    Err(e) if e.is_panic() => Ended::LoopPanicked(panic_message(&*e.into_panic())),
                    _ => Ended::LoopStopped,
                }
            }
        }
    }
}

/// What a panic said, if it said it in text.
fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    match (panic.downcast_ref::<&str>(), panic.downcast_ref::<String>()) {
        (Some(s), _) => (*s).to_string(),
        (_, Some(s)) => s.clone(),
        _ => "a panic without a message".into(),
    }
}

/// Starts an agent for `config`; `observer`, if given, hears every alarm
/// and state change.
///
/// # Errors
/// See [`StartError`].
pub async fn start(
    config: CellConfig,
    observer: Option<mpsc::UnboundedSender<Notice>>,
) -> Result<Agent, StartError> {
    start_with(
        config,
        Options {
            observer,
            ..Options::default()
        },
    )
    .await
}

/// Starts an agent for `config` with `options`.
///
/// # Errors
/// See [`StartError`].
pub async fn start_with(mut config: CellConfig, options: Options) -> Result<Agent, StartError> {
    for w in &config.warnings {
        tracing::warn!("{w}");
    }
    let mut engine = compile::engine(&config)?;
    // Before the tags go to the source.
    let fixed = config.fixed_parts();
    let (keys, held) = crate::services::plant_operators::operators(config.operators_setup())?;
    let keys_version = held.as_ref().map(|h| h.version());
    let metrics = Arc::new(Metrics::new(&config.cell));
    let journal = Journal::start(
        &config.journal.path,
        &config.journal.keep,
        (*metrics).clone(),
    )?;
    let committed = journal.committed();
    let journal_health = journal.health();
    let health = options.health.clone().unwrap_or_default();
    let cell_health = health.add(&config.cell);
    cell_health.journal(journal.health());
    let clock = options.clock.clone();
    let restored = crate::cell::restore::load(&config, clock.now_ms(), |id| {
        engine.can_raise(id) || id == JOURNAL_ALARM
    })?;
    let signing = signing_key(&config)?;
    let key = signing.clone();
    metrics.sample_signing(Arc::new(move || key.signing()));
    let session = crate::bus::open_agent(&config.zenoh).await?;
    cell_health.bus(session.clone(), config.zenoh.connect.clone());
    let prefix = config.zenoh.prefix.clone();
    let (requests_tx, requests_rx) = mpsc::channel(REQUEST_CAPACITY);
    let services = Services::declare(
        &session,
        &prefix,
        signing.clone(),
        &journal,
        config.kpi,
        requests_tx,
        metrics.clone(),
    )
    .await?;
    let (about, about_rx) = watch::channel(crate::services::about::about(
        &config.cell,
        &config.source_sha256,
        config.zenoh.tls.as_ref().map(|t| t.cert.as_path()),
        &signing,
    ));
    let about = Arc::new(about);
    let listener =
        Listener::declare(&session, config.operators_setup(), held, about.clone()).await?;
    let services = services.telling(about_rx).taking_operators(listener);
    let publisher = ZenohPublisher::start(session.clone(), &prefix, signing, metrics.clone())
        .await?
        .anchoring(journal.command_chain());
    let (stop, stop_rx) = watch::channel(false);
    let stopped = |mut rx: watch::Receiver<bool>| async move {
        let _ = rx.wait_for(|s| *s).await;
    };
    let (metrics_server, metrics_addr) = match config.metrics {
        Some(addr) => {
            let listener = crate::metrics::bind(addr)
                .await
                .map_err(|source| StartError::Metrics { addr, source })?;
            let bound = listener.local_addr().ok();
            let m = metrics.clone();
            let h = health.clone();
            let shutdown = stopped(stop_rx.clone());
            let task = tokio::spawn(async move {
                if let Err(e) = crate::metrics::serve(listener, m, h, shutdown).await {
                    tracing::error!(error = %e, "metrics server stopped");
                }
            });
            (Some(task), bound)
        }
        None => (None, None),
    };
    let mut sinks: Vec<Box<dyn Sink>> = vec![
        Box::new(JournalSink::new(journal)),
        Box::new(publisher),
        Box::new(MetricsSink::new(
            metrics.clone(),
            config.metrics_setup(),
            clock.now_ms(),
        )),
    ];
    let oee = match &config.oee {
        Some(c) => {
            let sink = OeeSink::start(c, &metrics, &config.journal.path, clock.now_ms())?;
            let watch = sink.watch();
            sinks.push(Box::new(sink));
            Some(watch)
        }
        None => None,
    };
    let alertmanager = match &config.alertmanager {
        Some(am) => {
            let (sink, pusher) =
                crate::sinks::alertmanager::start(&config.cell, am, metrics.clone())?;
            sinks.push(Box::new(sink));
            Some(tokio::spawn(pusher.run()))
        }
        None => None,
    };
    let sparkplug = match &config.sparkplug {
        Some(c) => {
            let (sink, session) = crate::sinks::sparkplug::start(
                &config.sparkplug_cell(),
                c,
                &engine.catalogue(),
                oee.clone(),
                metrics.clone(),
            )?;
            sinks.push(Box::new(sink));
            Some(tokio::spawn(session.run()))
        }
        None => None,
    };
    let (alarm_server, session_commands) = match &config.alarm_server {
        Some(c) => {
            let (tx, rx) = mpsc::channel(crate::services::alarm_server::ACK_QUEUE);
            let server = AlarmServer::start(&config.cell, c, tx, stopped(stop_rx.clone())).await?;
            metrics.sample_alarm_server_sessions(server.sessions());
            sinks.push(Box::new(AlarmServerSink::new(server.feed())));
            (Some(server), Some(rx))
        }
        None => (None, None),
    };
    if let Some(observer) = options.observer {
        sinks.push(Box::new(ConsoleSink::new(observer)));
    }
    sinks.extend(options.sinks);
    let forcing = crate::cell::forcing::Forcing::of(&config);
    let timing = crate::cell::timers::Timers::of(&config);
    let own_source = options.source.is_none();
    let mut source = match options.source {
        Some(source) => source,
        None => {
            let tags = std::mem::take(&mut config.tags);
            source_for(&config, tags)
        }
    };
    source.count_requests(metrics.opcua_requests.clone());
    let writer = source.writer();
    let allowance = source.delivery_allowance();
    let source_listening = source.listening();
    tracing::info!(cell = %config.cell, source = %source.describe(), "starting");
    let (source_tx, source_rx) = mpsc::channel(QUEUE_CAPACITY);
    let (source_stop, source_stopped) = watch::channel(false);
    let source = tokio::spawn(source.run(
        source_tx,
        either_stops(stop_rx.clone(), source_stopped).boxed(),
    ));
    let mut gate = Gate::new(&config.cell, OperatorKeys::default());
    gate.reloaded(keys, keys_version);
    if let (Some(server), Some(c)) = (&alarm_server, &config.alarm_server) {
        for why in server.users().cannot_acknowledge(&gate) {
            tracing::warn!(cell = %config.cell, file = %c.users_file.display(), "alarm server: {why}");
        }
    }
    for (at, nonce) in restored.nonces {
        gate.remember(at, nonce);
    }
    let answers = crate::cell::answers::Answers::restored(restored.outcomes);
    let state = restored.state.as_ref().map(|(_, at, kind)| (*at, *kind));
    let step = engine.restore(
        restored.alarms,
        restored.state.map(|(s, _, _)| s),
        clock.now_ms(),
    );
    let (reloads, reload_rx) = mpsc::channel(1);
    let (asks_tx, reload_asks) = if options.reads_its_file {
        let (tx, rx) = mpsc::channel(4);
        (Some(tx), Some(rx))
    } else {
        (None, None)
    };
    let cell_loop = CellLoop::new(&config.cell, engine, gate, sinks, config.state_interval)
        .timed_by(clock)
        .allowing(allowance)
        .shelving_at_most(config.max_shelve)
        .restored(step, state)
        .watching_journal(journal_health)
        .writing_to(writer)
        .answering_again(answers)
        .forcing(forcing)
        .timing(timing)
        .reporting_to(cell_health.clone())
        .reloading(reload_rx);
    let cell_loop = match asks_tx {
        Some(tx) => cell_loop.asking_reloads(tx),
        None => cell_loop,
    };
    let cell_loop = match oee {
        Some(oee) => cell_loop.showing_oee(oee),
        None => cell_loop,
    };
    let cell_loop = match session_commands {
        Some(rx) => cell_loop.acknowledging_sessions(rx),
        None => cell_loop,
    };
    let cell_loop = cell_loop
        .spawn(source_rx, requests_rx, stopped(stop_rx.clone()))
        .map_err(StartError::Loop)?;
    let services = tokio::spawn(services.run(stopped(stop_rx.clone())));
    Ok(Agent {
        stop,
        cell_loop: Some(cell_loop),
        source: Some(source),
        source_stop,
        own_source,
        stopping: stop_rx,
        services: Some(services),
        metrics_server,
        alertmanager,
        sparkplug,
        alarm_server_addr: alarm_server.as_ref().map(AlarmServer::addr),
        alarm_server_users: alarm_server.as_ref().map(|s| s.users().clone()),
        alarm_server: alarm_server.map(AlarmServer::task),
        session,
        metrics,
        metrics_addr,
        source_listening,
        committed,
        health: (health, cell_health),
        reloads,
        reload_asks,
        fixed,
        about,
    })
}

/// Completes when either says stop: the agent's stop, or the source's own
/// (a reload that replaces it).
async fn either_stops(mut agent: watch::Receiver<bool>, mut source: watch::Receiver<bool>) {
    tokio::select! {
        _ = agent.wait_for(|s| *s) => {}
        _ = source.wait_for(|s| *s) => {}
    }
}

/// The agent's signing key (made now if its file does not exist), after
/// refusing a bus TLS key that others may read.
fn signing_key(config: &CellConfig) -> Result<Arc<AgentKey>, StartError> {
    if let Some(tls) = &config.zenoh.tls {
        check_private(&tls.key)?;
    }
    let path = config
        .zenoh
        .signing_key
        .clone()
        .unwrap_or_else(|| std::path::PathBuf::from(format!("{}.agent.key", config.cell)));
    let (key, made) = AgentKey::load_or_create(&path, &config.cell)?;
    if made {
        tracing::warn!(
            cell = %config.cell,
            file = %path.display(),
            "made this agent's signing key; add its public key to the plant trust file: {}",
            key.trust_entry().trim_end().replace('\n', " ")
        );
    }
    tracing::info!(cell = %config.cell, public_key = %key.public_hex(), "signing the bus with the agent's key");
    Ok(Arc::new(key))
}

/// The source a cell configuration asks for; `tags` are the
/// configuration's, handed over, not copied (on a 100,000-tag cell a copy
/// is 14 MB plus three strings a tag): the `@` source keeps them, the OPC UA
/// source only what it reads of them.
fn source_for(config: &CellConfig, tags: Vec<TagConfig>) -> Box<dyn Source> {
    match (&config.opcua, &config.legacy) {
        (_, Some(bus)) => Box::new(crate::sources::at_bus::AtBusSource::new(bus.clone(), tags)),
        (Some(ua), None) => Box::new(crate::sources::opcua::OpcUaSource::new(
            &config.cell,
            ua.clone(),
            tags,
            config
                .sfc
                .iter()
                .flat_map(|s| s.force_switch.into_iter().chain(s.stop_switch)),
        )),
        // A validated configuration has one; one built by hand (a test's)
        // without either reads nothing.
        #[cfg(any(test, feature = "test-kit"))]
        (None, None) => Box::new(crate::sources::scripted::ScriptedSource::new().0),
        #[cfg(not(any(test, feature = "test-kit")))]
        (None, None) => unreachable!("a validated configuration names [opcua] or [legacy]"),
    }
}
