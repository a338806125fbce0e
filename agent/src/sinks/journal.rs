//! The journal as a sink: alarm transitions, state changes, parts and
//! operator commands become rows, staged before the next sink (Zenoh) sees
//! the step and queued in order for the writer thread once every sink has
//! it ([`Sink::after`]); answers to clients wait for them to be committed
//! ([`Sink::settled`]).

use futures_util::future::BoxFuture;
use futures_util::FutureExt;

use crate::journal::{Entry, Journal};
use crate::sinks::{Settled, Sink};
use crate::step::{CellStep, Input};
use std::sync::Arc;

/// Writes each step's rows and waits for their commit.
pub(crate) struct JournalSink {
    journal: Journal,
    /// The last step's rows and its number ([`Journal::stage`]), queued
    /// by `after`.
    staged: Option<(Vec<Entry>, u64)>,
}

impl JournalSink {
    /// A sink writing to `journal`.
    pub(crate) fn new(journal: Journal) -> JournalSink {
        JournalSink {
            journal,
            staged: None,
        }
    }

    /// Queues the staged rows, if any.
    async fn queue_staged(&mut self) {
        if let Some((rows, step)) = self.staged.take() {
            if let Err(e) = self.journal.queue_staged(rows, step).await {
                tracing::debug!(error = %e, "journal rows not queued");
            }
        }
    }
}

/// The rows of `step`.
pub(crate) fn entries(step: &CellStep) -> Vec<Entry> {
    let mut rows = Vec::new();
    for ((alarm, transition, at), published) in step.engine.alarms().zip(&step.alarms) {
        rows.push(Entry::Alarm {
            at,
            alarm: alarm.id.clone(),
            kind: alarm.kind.as_str().into(),
            severity: alarm.severity.as_str().into(),
            transition: transition.as_str().into(),
            payload: published.json.clone(),
            open: alarm.state() != cellwatch_models::alarm::AlarmState::Normal
                || alarm.shelved.is_some()
                || alarm.out_of_service.is_some(),
        });
    }
    for (state, kind, at) in step.engine.states() {
        let (fault_type, element) = match state {
            cellwatch_models::engine::MachineState::Fault {
                fault_type,
                element,
            } => (Some(fault_type.clone()), element.clone()),
            _ => (None, None),
        };
        rows.push(Entry::State {
            at,
            kind: kind.as_str().into(),
            state: state.name().into(),
            fault_type,
            element,
        });
    }
    for (mode, entered, at) in step.engine.modes() {
        rows.push(Entry::Mode {
            at,
            mode: mode.to_string(),
            entered,
        });
    }
    for &(at, count) in &step.engine.parts {
        rows.push(Entry::Part { at, count });
    }
    for &(at, count) in &step.engine.rejects {
        rows.push(Entry::Reject { at, count });
    }
    for (r, json) in step.engine.recordings.iter().zip(&step.recordings) {
        rows.push(Entry::Recording {
            at: r.raised_at,
            alarm: r.alarm.clone(),
            payload: json.clone(),
        });
    }
    if let Some(o) = &step.engine.order {
        rows.push(Entry::Order {
            at: step.at,
            item: o.item.clone(),
            target: o.target,
        });
    }
    if let Input::Command(c) = &step.input {
        rows.push(Entry::Command {
            at: step.at,
            operator: c.operator.clone(),
            action: c.action.map_or("invalid", |a| a.as_str()).into(),
            alarm: c.alarm.clone(),
            nonce: c.nonce.clone(),
            accepted: c.accepted,
            verified: c.verified,
            detail: c.detail.clone(),
            stage: c.stage.as_str().into(),
            source: c.source.clone(),
            count: c.count,
            digest: c.digest.clone(),
        });
    }
    rows
}

impl Sink for JournalSink {
    fn name(&self) -> &'static str {
        "journal"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        async move {
            // A step not followed by `after` (never, in the loop) still
            // has its rows queued first.
            self.queue_staged().await;
            let rows = entries(step);
            if rows.is_empty() {
                return;
            }
            // Staged now, queued once the bus has the step (`after`), not
            // waited for: the writer thread is not woken on the alarm's
            // path, and commits the rows within its batch. Whatever answers
            // a client (history, snapshot, a command's outcome) waits for
            // the journal first (`settled`, which waits for staged rows
            // too), so no one is shown what a crash would forget. A journal
            // that cannot write keeps the rows in its bounded queue and
            // retries (the cell loop raises the `journal` alarm).
            let step = self.journal.stage(rows.len());
            self.staged = Some((rows, step));
        }
        .boxed()
    }

    fn after(&mut self) -> BoxFuture<'_, ()> {
        self.queue_staged().boxed()
    }

    fn settled(&self) -> Option<Settled> {
        let barrier = self.journal.barrier();
        Some(Arc::new(move || {
            let b = barrier.clone();
            async move { b.settled().await }.boxed()
        }))
    }

    fn close(mut self: Box<Self>) -> BoxFuture<'static, ()> {
        async move {
            self.queue_staged().await;
            self.journal.close().await;
        }
        .boxed()
    }
}
