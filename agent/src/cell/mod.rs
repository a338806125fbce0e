//! The cell loop: one per agent, owning the engine.
//!
//! [`CellLoop::run`] takes three inputs — source events, requests from the
//! services (snapshot, operator commands) and the passing of time — and
//! turns each into one [`CellStep`]: what came in, the engine's
//! [`EngineStep`], and the payloads to publish.
//! The step goes to every sink in order (journal, Zenoh, metrics, console),
//! then to each sink's `after` (the journal's rows queued for its writer);
//! nothing in the loop knows about Zenoh, SQLite or Prometheus.
//!
//! - [`compile`]: builds the engine from a configuration (used by `run`
//!   and by `validate`, so a configuration that validates starts).
//! - [`restore`]: what a restarted agent takes back from its journal.

pub(crate) mod answers;
mod commands;
pub mod compile;
pub(crate) mod force;
pub(crate) mod forcing;
mod gaps;
pub(crate) mod own_alarms;
mod plc;
mod refused;
mod reload;
pub(crate) mod restore;
mod session;
mod snapshot;
pub(crate) mod swap;
pub(crate) mod timers;

use std::future::Future;
use std::time::Duration;

use cellwatch_models::engine::{CellEngine, EngineStep, HistoryKind};
use tokio::sync::{mpsc, oneshot, watch};

pub use crate::step::{
    CellStep, CommandOutcome, CommandRecord, Input, PublishedAlarm, Request, Stage,
    RECORD_FIELD_BYTES,
};
pub use refused::CommandError;

use crate::clock::Clock;
use crate::operator::refusals::Refusals;
use crate::operator::Gate;
use crate::payload::{AlarmPayload, RecordingPayload, StatePayload};
use crate::sinks::{Settled, Sink};
use crate::sources::{SourceEvent, WriteSender};

/// The longest the loop sleeps without looking at the time. Deadlines wake
/// it when they fall due (the engine's, a forced transition's, the end of
/// a minute of refusals to summarise) and a test's clock when it is set;
/// this bounds how far a system clock stepped forward runs ahead unseen,
/// and is how often, while nothing happens, a tick brings the figures that
/// follow the time up to date (the metrics' time in each state, alarm rates
/// and age of the last update; the OEE, computed at most once a second).
pub const MAX_SLEEP: Duration = crate::health::MAX_SLEEP;

/// The agent's own alarm for a journal that cannot write.
pub const JOURNAL_ALARM: &str = "journal";

/// The loop's state: the engine, the operator gate and the sinks.
pub struct CellLoop {
    cell: String,
    engine: CellEngine,
    gate: Gate,
    /// Every step goes to each, in order.
    sinks: Vec<Box<dyn Sink>>,
    state_interval: Duration,
    /// When the current machine state was entered, and by which change.
    state_since: u64,
    state_kind: HistoryKind,
    /// What was restored from the journal, dispatched first by `run`.
    restored: Option<EngineStep>,
    /// When the values being handled were received (see [`CellStep`]).
    received: Option<std::time::Instant>,
    /// `Some(why)` while the journal cannot write: the `journal` alarm.
    journal_health: Option<watch::Receiver<Option<String>>>,
    /// Where writes to the PLC go, if the source can write.
    writer: Option<WriteSender>,
    /// Writes carried out (or not) by the source, back to be journaled
    /// and answered.
    written_tx: mpsc::Sender<Written>,
    written_rx: mpsc::Receiver<Written>,
    clock: Clock,
    /// The longest shelf.
    max_shelve: Duration,
    /// The charts' switches and the force under way.
    forcing: forcing::Forcing,
    /// The timed transitions' recent measurements.
    timers: timers::Timers,
    /// Refusals before a signature was verified, counted per source and
    /// reason for the journal's summaries (bounded).
    refusals: Refusals,
    /// Changes lost for good (gaps), warned of at most once a minute.
    gaps: crate::clock::Every,
    /// Recent verified commands' outcomes, for a client that sends one
    /// again (its answer lost, the agent restarted).
    answers: answers::Answers,
    /// How long after a deadline the loop waits for a change that happened
    /// in time at the PLC but is still on its way (the source's publishing
    /// interval), ms.
    allowance: u64,
    /// Where the tasks the loop starts (answers waiting for the journal,
    /// writes waiting for the PLC) run: the runtime that started a loop on
    /// its own thread ([`CellLoop::spawn`]), so they outlive the loop;
    /// `None`: the loop's own.
    tasks: Option<tokio::runtime::Handle>,
    /// Told of every round of the loop and of the source's connection
    /// (`/healthz`, `/readyz`, systemd's watchdog).
    health: Option<std::sync::Arc<crate::health::CellHealth>>,
    /// Configurations read again, to take over (`None`: none will come).
    reloads: Option<mpsc::Receiver<swap::Reload>>,
    /// Where an operator's `configure reload` goes (`None`: the agent
    /// was not started from a file, and it is refused).
    reload_asks: Option<mpsc::Sender<swap::ReloadAsk>>,
    /// Acknowledgements from the alarm server's sessions (`session.rs`).
    session_commands: Option<mpsc::Receiver<crate::step::SessionCommand>>,
    /// The current shift's OEE, for the snapshot (`snapshot.rs`).
    oee: Option<crate::step::OeeWatch>,
}

/// A write's outcome on its way back into the loop.
struct Written {
    record: CommandRecord,
    reply: oneshot::Sender<CommandOutcome>,
    /// What follows the write.
    then: Then,
}

impl Written {
    /// The `result` row of `record` for `done` (what the PLC, or whoever
    /// carried the command out, said; or why not), to be answered on
    /// `reply` once journaled.
    fn answer(
        record: CommandRecord,
        done: Result<String, CommandError>,
        reply: oneshot::Sender<CommandOutcome>,
    ) -> Written {
        let (accepted, detail) = match done {
            Ok(d) => (true, d),
            Err(d) => (false, d.to_string()),
        };
        Written {
            record: CommandRecord {
                stage: Stage::Result,
                ..record.saying(accepted, &detail)
            },
            reply,
            then: Then::Answer,
        }
    }
}

/// What woke the loop (see `CellLoop::serve`).
enum Woke {
    /// The source's next event (`None`: it closed), and how many more wait.
    Source(Option<SourceEvent>, usize),
    /// The services' next request (`None`: they closed).
    Request(Option<Request>),
    Written(Written),
    Session(crate::step::SessionCommand),
    /// The journal's health changed.
    Journal(Option<String>),
    Reload(Box<swap::Reload>),
    /// A deadline, [`MAX_SLEEP`], or a test's clock moved.
    Time,
    /// The periodic state is due.
    Beat,
}

/// What the loop does once a write is done.
enum Then {
    /// Answer the operator (a value written).
    Answer,
    /// Wait for the forced transition's target steps (if the pulse went
    /// through).
    Force,
    /// Record the stop's result and answer.
    Stop,
    /// Acknowledge the PLC's alarm in cellwatch too (if the PLC took it),
    /// with the operator's comment, then answer.
    Acknowledge(Option<String>),
}

pub use crate::config::DEFAULT_MAX_SHELVE;

/// How long a write may take on the PLC's side before the operator is
/// told it failed.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(30);

impl CellLoop {
    /// A loop for `cell` over `engine`, letting commands through `gate` and
    /// handing steps to `sinks`.
    pub fn new(
        cell: &str,
        engine: CellEngine,
        gate: Gate,
        sinks: Vec<Box<dyn Sink>>,
        state_interval: Duration,
    ) -> CellLoop {
        let (written_tx, written_rx) = mpsc::channel(2 * crate::sources::WRITE_CAPACITY);
        CellLoop {
            cell: cell.into(),
            engine,
            gate,
            sinks,
            state_interval,
            state_since: crate::clock::now_ms(),
            clock: Clock::system(),
            max_shelve: DEFAULT_MAX_SHELVE,
            state_kind: HistoryKind::Offline,
            restored: None,
            received: None,
            journal_health: None,
            writer: None,
            written_tx,
            written_rx,
            forcing: forcing::Forcing::default(),
            timers: timers::Timers::default(),
            refusals: Refusals::default(),
            gaps: crate::clock::Every::new(Duration::from_secs(60)),
            answers: answers::Answers::default(),
            allowance: 0,
            tasks: None,
            health: None,
            reloads: None,
            reload_asks: None,
            session_commands: None,
            oee: None,
        }
    }

    /// Runs the loop ([`CellLoop::run`]) on a thread of its own: a
    /// publish's values reach the engine as soon as the source hands them
    /// over, never queued behind the source's or the services' tasks on a
    /// shared worker. The tasks the loop starts run on the calling runtime.
    ///
    /// The thread's runtime is multi-threaded with a single worker
    /// (`cell-loop`), the loop a task on it: Zenoh blocks in place when a
    /// publisher or a token is dropped, which a current-thread runtime
    /// refuses with a panic; and the worker that fires the loop's timers
    /// runs it, with no second thread to wake per tick (BENCHMARKS.md,
    /// "The floor"). The returned task ends with the loop and carries its
    /// panic, if it had one.
    ///
    /// # Errors
    /// The runtime or the thread cannot be started.
    pub fn spawn(
        mut self,
        source: mpsc::Receiver<SourceEvent>,
        requests: mpsc::Receiver<Request>,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> std::io::Result<tokio::task::JoinHandle<()>> {
        self.tasks = Some(tokio::runtime::Handle::current());
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("cell-loop")
            .enable_all()
            .build()?;
        let (done, ended) = oneshot::channel();
        std::thread::Builder::new()
            .name("cell-loop-owner".into())
            .spawn(move || {
                let run = std::panic::AssertUnwindSafe(|| {
                    let task = runtime.spawn(self.run(source, requests, shutdown));
                    if let Err(e) = runtime.block_on(task) {
                        if e.is_panic() {
                            std::panic::resume_unwind(e.into_panic());
                        }
                    }
                });
                let _ = done.send(std::panic::catch_unwind(run));
            })?;
        Ok(tokio::spawn(async move {
            if let Ok(Err(panic)) = ended.await {
                std::panic::resume_unwind(panic);
            }
        }))
    }

    /// Starts `task` where the loop's tasks run (see `tasks`).
    fn start_task(&self, task: impl Future<Output = ()> + Send + 'static) {
        match &self.tasks {
            Some(runtime) => drop(runtime.spawn(task)),
            None => drop(tokio::spawn(task)),
        }
    }

    /// Forces transitions and presses stop switches of these charts.
    #[must_use]
    pub fn forcing(mut self, forcing: forcing::Forcing) -> CellLoop {
        self.forcing = forcing;
        self
    }

    /// Keeps the recent measurements of these timed transitions.
    #[must_use]
    pub fn timing(mut self, timers: timers::Timers) -> CellLoop {
        self.timers = timers;
        self
    }

    /// Tells `health` of every round of the loop (a stuck loop stops
    /// going round) and of the source's connection.
    #[must_use]
    pub fn reporting_to(mut self, health: std::sync::Arc<crate::health::CellHealth>) -> CellLoop {
        self.health = Some(health);
        self
    }

    /// Takes over from each configuration read again that comes on
    /// `reloads` (`reload.rs`).
    #[must_use]
    pub fn reloading(mut self, reloads: mpsc::Receiver<swap::Reload>) -> CellLoop {
        self.reloads = Some(reloads);
        self
    }

    /// Hands an operator's `configure reload` to `asks` (the process that
    /// runs the agent from its file).
    #[must_use]
    pub fn asking_reloads(mut self, asks: mpsc::Sender<swap::ReloadAsk>) -> CellLoop {
        self.reload_asks = Some(asks);
        self
    }

    /// Judges deadlines `allowance` after they fall due: a change the PLC
    /// saw in time may take that long to arrive (the source's publishing
    /// interval).
    #[must_use]
    pub fn allowing(mut self, allowance: Duration) -> CellLoop {
        self.allowance = allowance.as_millis() as u64;
        self
    }

    /// Reads the time from `clock` (a test's virtual time) instead of the
    /// system's.
    #[must_use]
    pub fn timed_by(mut self, clock: Clock) -> CellLoop {
        self.state_since = clock.now_ms();
        self.clock = clock;
        self
    }

    /// Shelves last at most `max` (ISA-18.2: a shelf is for a while).
    #[must_use]
    pub fn shelving_at_most(mut self, max: Duration) -> CellLoop {
        self.max_shelve = max;
        self
    }

    /// Operators' writes (signed, permission `write`) go to `writer`, the
    /// source's; without one, every write is refused.
    #[must_use]
    pub fn writing_to(mut self, writer: Option<WriteSender>) -> CellLoop {
        self.writer = writer;
        self
    }

    /// Answers a command sent again with its original outcome, from
    /// `answers` (restored from the journal) on.
    #[must_use]
    pub fn answering_again(mut self, answers: answers::Answers) -> CellLoop {
        self.answers = answers;
        self
    }

    /// Raises the `journal` alarm while `health` says the journal cannot
    /// write, and clears it when it can.
    #[must_use]
    pub fn watching_journal(mut self, health: watch::Receiver<Option<String>>) -> CellLoop {
        self.journal_health = Some(health);
        self
    }

    /// Starts from what the journal kept: the engine's restore `step`
    /// (republished once, each alarm as `restored`) and the machine state
    /// entered at `since` by a change of `kind`.
    #[must_use]
    pub fn restored(mut self, step: EngineStep, state: Option<(u64, HistoryKind)>) -> CellLoop {
        if let Some((since, kind)) = state {
            self.state_since = since;
            self.state_kind = kind;
        }
        self.restored = Some(step);
        self
    }

    /// Runs until `shutdown` completes (or every input is closed), then
    /// closes the sinks.
    ///
    /// # Panics
    /// A step panicked (in the engine or a sink): the sinks are closed
    /// first (the journal commits what it was given, the liveliness token
    /// is undeclared), then the panic goes on.
    pub async fn run(
        mut self,
        source: mpsc::Receiver<SourceEvent>,
        requests: mpsc::Receiver<Request>,
        shutdown: impl Future<Output = ()>,
    ) {
        use futures_util::FutureExt;
        let served = std::panic::AssertUnwindSafe(self.serve(source, requests, shutdown))
            .catch_unwind()
            .await;
        if let Some(health) = &self.health {
            health.ended();
        }
        for sink in self.sinks {
            sink.close().await;
        }
        if let Err(panic) = served {
            std::panic::resume_unwind(panic);
        }
    }

    /// The loop itself: every input until `shutdown`.
    async fn serve(
        &mut self,
        mut source: mpsc::Receiver<SourceEvent>,
        mut requests: mpsc::Receiver<Request>,
        shutdown: impl Future<Output = ()>,
    ) {
        tokio::pin!(shutdown);
        let wake = tokio::time::sleep(MAX_SLEEP);
        tokio::pin!(wake);
        let mut moves = self.clock.moves();
        let mut beat = tokio::time::interval(self.state_interval);
        beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        if let Some(step) = self.restored.take() {
            let now = self.clock.now_ms();
            self.dispatch(now, Input::Restored, step, 0).await;
            // A journal alarm from before the restart follows the
            // journal's health now, which no change may report for long.
            let restored_journal = self
                .engine
                .alarms()
                .any(|a| a.id == JOURNAL_ALARM && a.active);
            if let (true, Some(health)) = (restored_journal, &mut self.journal_health) {
                let problem = health.borrow_and_update().clone();
                self.system(JOURNAL_ALARM, problem).await;
            }
        }
        let mut source_open = true;
        let mut requests_open = true;
        loop {
            if let Some(health) = &self.health {
                health.waiting();
            }
            // Wake when the next deadline (plus the allowance) falls due.
            wake.as_mut().reset(self.next_wake());
            let woke = tokio::select! {
                biased;
                _ = &mut shutdown => break,
                ev = source.recv(), if source_open => Woke::Source(ev, source.len()),
                r = requests.recv(), if requests_open => Woke::Request(r),
                Some(w) = self.written_rx.recv() => Woke::Written(w),
                Some(a) = crate::step::next_session_command(&mut self.session_commands) => Woke::Session(a),
                problem = journal_changed(&mut self.journal_health) => Woke::Journal(problem),
                r = swap::next(&mut self.reloads) => Woke::Reload(Box::new(r)),
                () = &mut wake => Woke::Time,
                () = moves.moved() => Woke::Time,
                _ = beat.tick() => Woke::Beat,
            };
            if let Some(health) = &self.health {
                health.working();
            }
            match woke {
                Woke::Source(Some(ev), depth) => self.source(ev, depth).await,
                Woke::Source(None, _) => source_open = false,
                Woke::Request(Some(r)) => self.request(r).await,
                Woke::Request(None) => requests_open = false,
                Woke::Written(w) => self.written(w).await,
                Woke::Session(a) => self.session_command(a).await,
                Woke::Journal(problem) => self.system(JOURNAL_ALARM, problem).await,
                Woke::Reload(r) => {
                    if let Some(mut r) = self.acceptable(*r) {
                        if let Some(new) = r.source.take() {
                            // The old source's events not yet taken are
                            // dropped with its channel: the new engine has
                            // the values, the new source sends its own.
                            source = new.events;
                            source_open = true;
                            self.writer = new.writer;
                            self.allowance = new.allowance.as_millis() as u64;
                        }
                        self.reload(r).await;
                    }
                }
                Woke::Time => self.tick().await,
                Woke::Beat => self.beat().await,
            }
        }
        // The recordings under way and the refusals counted this minute:
        // journaled before the sinks close.
        let now = self.clock.now_ms();
        let ended = self.engine.end_recordings(now);
        self.dispatch(now, Input::Tick, ended, 0).await;
        let rest = self.refusals.flush();
        self.summaries(rest, now).await;
    }

    /// When the loop must next look at the time: the engine's next
    /// deadline judged `allowance` later, a forced transition's deadline,
    /// the end of a minute with refusals to summarise, and at the latest
    /// [`MAX_SLEEP`] from now.
    fn next_wake(&self) -> tokio::time::Instant {
        let now = self.clock.now_ms();
        let engine = self
            .engine
            .next_deadline()
            .map(|d| d.saturating_add(self.allowance));
        let deadlines = [
            engine,
            self.forcing.deadline(),
            self.refusals.next_deadline(),
        ];
        let after = deadlines
            .into_iter()
            .flatten()
            .min()
            .map_or(MAX_SLEEP, |at| {
                Duration::from_millis(at.saturating_sub(now)).min(MAX_SLEEP)
            });
        tokio::time::Instant::now() + after
    }

    async fn source(&mut self, ev: SourceEvent, queue_depth: usize) {
        let now = self.clock.now_ms();
        if let (Some(health), SourceEvent::Connected(detail) | SourceEvent::Disconnected(detail)) =
            (&self.health, &ev)
        {
            health.source(matches!(ev, SourceEvent::Connected(_)), detail);
        }
        let (input, step) = match ev {
            SourceEvent::Connected(endpoint) => (
                Input::Connection {
                    up: true,
                    detail: endpoint,
                },
                self.engine.on_connection(true, now),
            ),
            SourceEvent::Disconnected(why) => (
                Input::Connection {
                    up: false,
                    detail: why,
                },
                self.engine.on_connection(false, now),
            ),
            SourceEvent::Readings(readings) => {
                self.forcing.seen_in(&readings);
                // One step for the publish, cut after each reading that
                // changes an alarm: the alarm goes out before the changes
                // behind it are looked at.
                let mut rest = &readings.readings[..];
                loop {
                    let (step, used) = self.engine.on_readings_to_alarm(rest, now);
                    rest = &rest[used..];
                    self.received = Some(readings.received);
                    self.dispatch(now, Input::Readings, step, queue_depth).await;
                    if rest.is_empty() {
                        break;
                    }
                }
                self.follow_force(now).await;
                return;
            }
            SourceEvent::Problem { id, problem } => (
                Input::System,
                self.engine.on_system(&id, problem.as_deref(), now),
            ),
            SourceEvent::Conditions(events) => {
                for c in events {
                    let step = self.engine.on_condition(c, now);
                    self.dispatch(now, Input::Readings, step, queue_depth).await;
                }
                return;
            }
            SourceEvent::ConditionsHeld { prefix, held } => (
                Input::Readings,
                self.engine.on_conditions_held(&prefix, &held, now),
            ),
            SourceEvent::Resumed => (Input::Readings, self.engine.on_resumed(now)),
            SourceEvent::Gap { tags, values, why } => {
                (Input::Readings, self.lost(tags.as_deref(), values, &why))
            }
        };
        self.dispatch(now, input, step, queue_depth).await;
    }

    async fn system(&mut self, id: &str, problem: Option<String>) {
        let now = self.clock.now_ms();
        let step = self.engine.on_system(id, problem.as_deref(), now);
        self.dispatch(now, Input::System, step, 0).await;
    }

    async fn tick(&mut self) {
        let now = self.clock.now_ms();
        // Timers judge "late" against the PLC's clock: an event that
        // happened in time but is still on its way (publishing interval)
        // must not be called late.
        let step = self.engine.advance(now.saturating_sub(self.allowance));
        self.dispatch(now, Input::Tick, step, 0).await;
        self.force_overdue(now).await;
        let ended = self.refusals.ended(now);
        self.summaries(ended, now).await;
    }

    async fn beat(&mut self) {
        let now = self.clock.now_ms();
        let state = Some(self.state_payload(now));
        self.deliver(CellStep {
            at: now,
            input: Input::StateBeat,
            engine: EngineStep::default(),
            alarms: Vec::new(),
            state,
            queue_depth: 0,
            received: None,
            positions: Vec::new(),
            recordings: Vec::new(),
        })
        .await;
    }

    async fn request(&mut self, r: Request) {
        match r {
            Request::Snapshot(reply) => {
                let snapshot = self.snapshot();
                let settled = self.settled();
                self.start_task(async move {
                    settled.await;
                    let _ = reply.send(snapshot);
                });
            }
            Request::Command {
                source,
                command,
                reply,
            } => {
                // The outcome may come later (a forced transition's pulse
                // and read-back); it is sent once its rows are durable.
                let (outcome_tx, outcome) = oneshot::channel();
                let sent = command.as_ref().ok().cloned();
                self.command(source, command, outcome_tx).await;
                let sinks: Vec<Settled> = self.sinks.iter().filter_map(|s| s.settled()).collect();
                let answers = self.answers.clone();
                self.start_task(async move {
                    if let Ok(outcome) = outcome.await {
                        for s in &sinks {
                            s().await;
                        }
                        // Kept for a retry of the same command (only a
                        // verified one was begun).
                        if let Some(cmd) = &sent {
                            answers.finish(cmd, &outcome);
                        }
                        let _ = reply.send(outcome);
                    }
                });
            }
            Request::Operators(taken) => self.take_operators(taken).await,
        }
    }

    /// A future that completes once every step dispatched so far is
    /// durable in every sink that keeps steps.
    fn settled(&self) -> impl Future<Output = ()> + Send + 'static {
        let waits: Vec<_> = self
            .sinks
            .iter()
            .filter_map(|s| s.settled())
            .map(|s| s())
            .collect();
        async move {
            for w in waits {
                w.await;
            }
        }
    }

    /// Builds the payloads for `step` and hands it to the sinks.
    async fn dispatch(&mut self, now: u64, input: Input, step: EngineStep, queue_depth: usize) {
        let alarms = step
            .alarms()
            .map(|(alarm, transition, at)| {
                let payload = AlarmPayload::new(&self.cell, alarm, transition, at);
                let json = serde_json::to_string(&payload).unwrap_or_default();
                PublishedAlarm { payload, json }
            })
            .collect();
        let mut state = None;
        if let Some((_, kind, at)) = step.states().last() {
            self.state_since = at;
            self.state_kind = kind;
            state = Some(self.state_payload(at));
        } else if step.order.is_some() {
            state = Some(self.state_payload(now));
        }
        self.timers.observe(now, &step.observations);
        // Where each transition measured now stands in its window.
        let positions = if step.observations.is_empty() {
            Vec::new()
        } else {
            let mut all = self.engine.window_positions();
            all.retain(|p| step.observations.iter().any(|o| o.check == p.check));
            all
        };
        let received = self.received.take();
        let recordings = step.recordings.iter();
        let recordings = recordings
            .map(|r| RecordingPayload::json(&self.cell, r))
            .collect();
        self.deliver(CellStep {
            recordings,
            at: now,
            input,
            engine: step,
            alarms,
            state,
            queue_depth,
            received,
            positions,
        })
        .await;
    }

    async fn deliver(&mut self, step: CellStep) {
        for sink in &mut self.sinks {
            sink.handle(&step).await;
        }
        for sink in &mut self.sinks {
            sink.after().await;
        }
    }

    fn state_payload(&self, at: u64) -> StatePayload {
        StatePayload::new(
            &self.cell,
            self.engine.state(),
            self.state_kind,
            (self.state_since, at),
            self.engine.order(),
        )
    }
}

/// The journal's next health change; pending forever once there is no
/// journal to watch.
async fn journal_changed(health: &mut Option<watch::Receiver<Option<String>>>) -> Option<String> {
    let Some(rx) = health else {
        return std::future::pending().await;
    };
    if rx.changed().await.is_err() {
        *health = None;
        return std::future::pending().await;
    }
    let problem = rx.borrow_and_update().clone();
    problem
}
