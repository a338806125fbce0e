//! A configuration read again while the agent runs (SIGHUP, `cellwatch
//! run`): the engine built from it takes over from the running one in the
//! loop, between two inputs — alarms with their acknowledgements, shelves
//! and removals, the machine state, the connection and every tag's value
//! carried over ([`CellEngine::take_over`]); the charts' switches, the
//! timed transitions and the longest shelf replaced. The source, the
//! journal, the bus session and the sinks go on untouched: nothing is
//! lost, and history has no gap.

use cellwatch_models::engine::EngineStep;
use tokio::sync::{mpsc, oneshot};

use super::swap::{Reload, ReloadAsk, ReloadBusy};
use super::{CellLoop, CommandError, CommandOutcome, CommandRecord, Input, Stage, Written};
use crate::operator::Command;

/// How long an operator's `configure reload` may take (reading and
/// compiling the file, the loop taking it over).
const RELOAD_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(60);

impl CellLoop {
    /// `reload`, unless the loop cannot take one now (a forced transition
    /// or stop under way: its switch and target belong to the running
    /// charts), which is said to its sender.
    pub(super) fn acceptable(&self, reload: Reload) -> Option<Reload> {
        if self.forcing.pending.is_some() {
            let _ = reload.done.send(Err(ReloadBusy));
            return None;
        }
        Some(reload)
    }

    /// Reloads the loop from `reload` (see the module); its source, if it
    /// brings one, has been taken by the caller.
    pub(super) async fn reload(&mut self, reload: Reload) {
        let Reload {
            mut engine,
            mut forcing,
            timers,
            max_shelve,
            keys,
            keys_version,
            source: _,
            done,
        } = reload;
        forcing.pending = None;
        let now = self.clock.now_ms();
        // The recordings under way end with the engine that keeps them.
        let ended = self.engine.end_recordings(now);
        self.dispatch(now, Input::Reloaded, ended, 0).await;
        let carried = self.engine.carry_over();
        let alarms = carried.alarms.len();
        let steps = engine.take_over(carried, now);
        self.engine = engine;
        self.forcing = forcing;
        self.timers = timers;
        self.max_shelve = max_shelve;
        self.gate.reloaded(keys, keys_version);
        for step in steps {
            self.dispatch(now, Input::Reloaded, step, 0).await;
        }
        let _ = done.send(Ok(alarms));
    }
}

impl CellLoop {
    /// Judges commands by a newer plant operators list's operators from
    /// now on, and journals it as the plant's `configure` (what changed).
    pub(super) async fn take_operators(&mut self, taken: crate::step::OperatorsTaken) {
        let now = self.clock.now_ms();
        let said = crate::operator::plant::changes(self.gate.keys(), &taken.keys);
        self.gate.from_plant(taken.keys, taken.version);
        let detail = format!(
            "plant operators list v{} taken: {}",
            taken.version,
            if said.is_empty() {
                "no change for this cell"
            } else {
                &said
            }
        );
        tracing::info!(cell = %self.cell, "{detail}");
        let record = CommandRecord {
            operator: "plant".into(),
            action: Some(crate::operator::Action::Configure),
            alarm: String::new(),
            nonce: String::new(),
            digest: None,
            accepted: true,
            verified: true,
            detail,
            stage: Stage::Command,
            source: "plant".into(),
            count: 1,
        };
        self.dispatch(now, Input::Command(record), EngineStep::default(), 0)
            .await;
        let settled = self.settled();
        self.start_task(async move {
            settled.await;
            let _ = taken.reply.send(said);
        });
    }
}

impl CellLoop {
    /// Where an authorised `configure` command goes: `value` must be
    /// `reload`, and the agent must run from a file.
    pub(super) fn configure(&self, cmd: &Command) -> Result<mpsc::Sender<ReloadAsk>, CommandError> {
        if !cmd.alarm.is_empty() || cmd.tag.is_some() {
            return Err(CommandError::ConfigureNamesMore);
        }
        if cmd.value.as_deref() != Some("reload") {
            return Err(CommandError::ConfigureValue);
        }
        self.reload_asks
            .clone()
            .ok_or(CommandError::NoConfigurationFile)
    }

    /// Carries out an authorised `configure reload`: its request row (with
    /// the nonce) journaled and committed first, then the file read again
    /// by the process that runs the agent, and handed to this loop (the
    /// loop goes on meanwhile); what came of it comes back as a
    /// [`Written`], journaled as the result, and only then answered.
    pub(super) async fn reload_asked(
        &mut self,
        record: CommandRecord,
        asks: mpsc::Sender<ReloadAsk>,
        reply: oneshot::Sender<CommandOutcome>,
    ) {
        let now = self.clock.now_ms();
        let request = CommandRecord {
            stage: Stage::Request,
            ..record
                .clone()
                .saying(true, &format!("reload asked by {}", record.operator))
        };
        self.dispatch(now, Input::Command(request), EngineStep::default(), 0)
            .await;
        let settled = self.settled();
        let back = self.written_tx.clone();
        self.start_task(async move {
            settled.await;
            let (answer, outcome) = oneshot::channel();
            let asked = asks.send(ReloadAsk { reply: answer }).await.is_ok();
            let done = match (asked, tokio::time::timeout(RELOAD_TIMEOUT, outcome).await) {
                (false, _) | (true, Ok(Err(_))) => Err(CommandError::Stopping),
                (true, Ok(Ok(done))) => done.map_err(CommandError::from),
                (true, Err(_)) => Err(CommandError::NoReloadOutcome(RELOAD_TIMEOUT)),
            };
            let _ = back.send(Written::answer(record, done, reply)).await;
        });
    }
}
