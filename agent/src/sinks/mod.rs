//! Where the cell's steps go.
//!
//! The cell loop hands every [`CellStep`] to its sinks, in order: the
//! journal first (its rows staged), then Zenoh, the metrics and, in the
//! demo, the console; then each sink's [`Sink::after`] (the journal queues
//! the staged rows for its writer thread there, off the alarm's path).
//! Answers to clients (snapshots, command outcomes, history) wait for every
//! sink to be [`Sink::settled`]: nothing is shown that a crash would
//! forget. A sink sees each step once and never reads the engine.
//!
//! - [`journal`]: the SQLite journal (rows, history queries, reports).
//! - [`zenoh`]: publication on the bus, and the query services.
//! - [`console`]: the demo's printed view.
//! - [`alertmanager`]: alarms to people through Prometheus Alertmanager
//!   (a task of its own sends them, off the loop).
//! - [`sparkplug`]: the cell as a Sparkplug B edge node on an MQTT broker
//!   (a task of its own holds the session).
//! - [`alarm_server`]: alarms to SCADA clients through the agent's OPC UA
//!   alarm server (Alarms & Conditions).
//! - the metrics ([`crate::sinks::metrics::MetricsSink`]): Prometheus.
//! - [`RecordingSink`]: keeps every step, for tests; the smallest example
//!   of a sink.
//!
//! To add a sink: implement [`Sink`] and push it in [`crate::agent::start`].

pub(crate) mod alarm_server;
pub(crate) mod alertmanager;
pub(crate) mod console;
pub(crate) mod journal;
pub(crate) mod metrics;
pub(crate) mod oee;
pub(crate) mod sparkplug;
pub mod zenoh;

use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use tokio::sync::mpsc;

use crate::step::CellStep;

/// Waits for a sink's steps so far to be durable (see [`Sink::settled`]).
pub type Settled = std::sync::Arc<dyn Fn() -> BoxFuture<'static, ()> + Send + Sync>;

/// A consumer of the cell's steps.
pub trait Sink: Send {
    /// The sink's name, for logs.
    fn name(&self) -> &'static str;

    /// Takes one step. A sink that fails logs and counts its failure; it
    /// never stops the loop.
    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()>;

    /// Work for the step just handled that need not delay its alarm:
    /// called once every sink has handled the step, before the next one.
    fn after(&mut self) -> BoxFuture<'_, ()> {
        async {}.boxed()
    }

    /// For a durable sink: a function whose future completes once every
    /// step handed to the sink before the call is durable. The loop sends
    /// its answers to clients after it.
    fn settled(&self) -> Option<Settled> {
        None
    }

    /// The loop is stopping: release what the sink holds (declarations,
    /// files). Called once, after the last step.
    fn close(self: Box<Self>) -> BoxFuture<'static, ()> {
        async {}.boxed()
    }
}

/// Sends a copy of every step on a channel: tests read it to see exactly
/// what the loop did.
pub struct RecordingSink {
    /// Where the copies go; unbounded because a test reads them all.
    tx: mpsc::UnboundedSender<CellStep>,
}

impl RecordingSink {
    /// A recording sink and the receiver of its copies.
    pub fn new() -> (RecordingSink, mpsc::UnboundedReceiver<CellStep>) {
        let (tx, rx) = mpsc::unbounded_channel();
        (RecordingSink { tx }, rx)
    }
}

impl Sink for RecordingSink {
    fn name(&self) -> &'static str {
        "recording"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        let _ = self.tx.send(step.clone());
        async {}.boxed()
    }
}
