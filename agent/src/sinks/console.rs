//! The demo's console: alarms, state changes and connection changes, as
//! notices for whoever prints them.

use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use tokio::sync::mpsc;

use super::Sink;
use crate::payload::{AlarmPayload, StatePayload};
use crate::step::{CellStep, Input};

/// What the agent tells an observer (the demo's console).
#[derive(Debug, Clone)]
pub enum Notice {
    /// An alarm transition, as published.
    Alarm(Box<AlarmPayload>),
    /// A machine-state change (or the periodic state), as published.
    State(StatePayload),
    /// The PLC connection came up (true) or went down, and why.
    Connection(bool, String),
}

/// Turns steps into notices.
pub(crate) struct ConsoleSink {
    /// The printer's inbox; a local, in-process reader.
    tx: mpsc::UnboundedSender<Notice>,
}

impl ConsoleSink {
    /// A sink that sends notices on `tx`.
    pub(crate) fn new(tx: mpsc::UnboundedSender<Notice>) -> ConsoleSink {
        ConsoleSink { tx }
    }
}

impl Sink for ConsoleSink {
    fn name(&self) -> &'static str {
        "console"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        if let Input::Connection { up, detail } = &step.input {
            let _ = self.tx.send(Notice::Connection(*up, detail.clone()));
        }
        for a in &step.alarms {
            let _ = self.tx.send(Notice::Alarm(Box::new(a.payload.clone())));
        }
        if let Some(s) = &step.state {
            let _ = self.tx.send(Notice::State(s.clone()));
        }
        async {}.boxed()
    }
}
