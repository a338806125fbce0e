//! Operators' commands in the cell loop: through the gate, carried out or
//! refused, journaled and answered. Acknowledge, reset, shelve, out of
//! service and writes are here; forced transitions and the stop switch in
//! `force.rs`. Refusals before a signature was verified are counted per
//! source and reason and journaled as summaries (`summaries`).

use std::future::Future;
use std::time::Duration;

use cellwatch_models::engine::EngineStep;
use tokio::sync::oneshot;

use super::answers;
use super::{
    CellLoop, CommandError, CommandOutcome, CommandRecord, Input, Stage, Written,
    RECORD_FIELD_BYTES, WRITE_TIMEOUT,
};
use crate::operator::refusals;
use crate::operator::{clip, Action, Command, NotACommand, Refusal};
use crate::sources::{Write, WriteRequest};

/// A field `cmd`'s action does not take (`tag`, `value`, or `reason`: an
/// acknowledgement's comment, a shelf's or a removal's reason), if it has
/// one.
fn stray_field(cmd: &Command) -> Option<&'static str> {
    if cmd.action != Action::Write && cmd.tag.is_some() {
        return Some("tag");
    }
    if !matches!(
        cmd.action,
        Action::Write | Action::Shelve | Action::Configure
    ) && cmd.value.is_some()
    {
        return Some("value");
    }
    if !matches!(
        cmd.action,
        Action::Ack | Action::Shelve | Action::OutOfService
    ) && cmd.reason.is_some()
    {
        return Some("reason");
    }
    None
}

impl CellLoop {
    /// Until when a `shelve` command shelves (`None`: one-shot), or why
    /// it may not.
    pub(super) fn shelf(&self, cmd: &Command, now: u64) -> Result<Option<u64>, CommandError> {
        if cmd.reason.as_deref().unwrap_or("").trim().is_empty() {
            return Err(CommandError::ShelfNeedsReason);
        }
        match cmd.value.as_deref() {
            Some("once") => Ok(None),
            Some(text) => {
                let d = humantime::parse_duration(text)
                    .map_err(|_| CommandError::ShelfDuration(text.into()))?;
                if d.is_zero() || d > self.max_shelve {
                    return Err(CommandError::ShelfTooLong {
                        asked: text.into(),
                        max: self.max_shelve,
                    });
                }
                Ok(Some(now.saturating_add(
                    d.as_millis().try_into().unwrap_or(u64::MAX),
                )))
            }
            None => Err(CommandError::ShelfNeedsDuration),
        }
    }

    /// An operator's command: through the gate, then carried out (or
    /// refused), journaled and answered on `reply`.
    pub(super) async fn command(
        &mut self,
        source: String,
        command: Result<Command, NotACommand>,
        mut reply: oneshot::Sender<CommandOutcome>,
    ) {
        let now = self.clock.now_ms();
        let cmd = match command {
            Err(not) => {
                let record = CommandRecord::refused(
                    format!("not a command: {}", not.reason),
                    String::new(),
                    1,
                );
                // Counted by the services, which parse it.
                let outcome = CommandOutcome::new(false, record.detail.clone());
                return self
                    .unauthenticated(&source, not.kind, record, outcome, reply, now)
                    .await;
            }
            Ok(cmd) => cmd,
        };
        let target = match cmd.action {
            Action::Write => cmd.tag.as_deref().unwrap_or(""),
            Action::Force | Action::Stop | Action::Configure => cmd.value.as_deref().unwrap_or(""),
            _ => &cmd.alarm,
        };
        let base = CommandRecord::of(&cmd, target, Stage::Command);
        let checked = self.gate.check(&cmd, now);
        // The same signed command again (its answer lost, or the agent
        // restarted): said to be a replay, with its original outcome.
        if let Err(Refusal::Replay) = &checked {
            match self.answers.retry(&cmd, reply) {
                answers::Retry::Now(_) => {
                    tracing::info!(operator = %cmd.operator, action = %cmd.action, "a command sent again: answered as a replay with its first outcome");
                    return;
                }
                answers::Retry::Later => return,
                answers::Retry::Unknown(r) => reply = r,
            }
        }
        if checked.is_ok() {
            self.answers.begin(&cmd, now);
        }
        if let Err(refusal) = &checked {
            if let Some(reason) = refusal.unauthenticated() {
                let detail = refusal.to_string();
                let record = CommandRecord {
                    stage: Stage::Refused,
                    ..base.saying(false, &detail)
                };
                let outcome = CommandOutcome {
                    refused: Some(reason),
                    ..CommandOutcome::new(false, detail)
                };
                return self
                    .unauthenticated(&source, reason, record, outcome, reply, now)
                    .await;
            }
        }
        if matches!(cmd.action, Action::Force | Action::Stop) {
            let checked = checked.map_err(CommandError::from);
            return self.switch_command(cmd, checked, reply, now).await;
        }
        let verified = checked.is_ok();
        // An acknowledgement's comment, the operator's own words after what
        // was done (as an acknowledgement over OPC UA has it).
        let comment = match cmd.reason.as_deref().map(str::trim) {
            Some(comment) if cmd.action == Action::Ack && !comment.is_empty() => {
                Some(clip(comment, RECORD_FIELD_BYTES))
            }
            _ => None,
        };
        let said = comment
            .as_ref()
            .map_or_else(String::new, |c| format!(": {c}"));
        let done = match checked {
            Err(refusal) => Err(CommandError::Gate(refusal)),
            Ok(()) if stray_field(&cmd).is_some() => Err(CommandError::StrayField {
                action: cmd.action,
                field: stray_field(&cmd).unwrap_or_default(),
            }),
            Ok(()) if cmd.action == Action::Ack && self.engine.is_condition(&cmd.alarm) => {
                return self
                    .acknowledge_at_plc(base, comment.as_deref(), reply)
                    .await;
            }
            Ok(()) => match cmd.action {
                Action::Ack => self
                    .engine
                    .acknowledge(&cmd.alarm, &cmd.operator, comment.as_deref(), now)
                    .map_err(CommandError::from),
                Action::Reset => self
                    .engine
                    .reset(&cmd.alarm, &cmd.operator, now)
                    .map_err(CommandError::from),
                Action::Shelve => self.shelf(&cmd, now).and_then(|until| {
                    self.engine
                        .shelve(
                            &cmd.alarm,
                            &cmd.operator,
                            &clip(cmd.reason.as_deref().unwrap_or(""), RECORD_FIELD_BYTES),
                            until,
                            now,
                        )
                        .map_err(CommandError::from)
                }),
                Action::Unshelve => self
                    .engine
                    .unshelve(&cmd.alarm, now)
                    .map_err(CommandError::from),
                Action::OutOfService => match cmd.reason.as_deref().map(str::trim) {
                    None | Some("") => Err(CommandError::OutOfServiceNeedsReason),
                    Some(reason) => self
                        .engine
                        .take_out_of_service(
                            &cmd.alarm,
                            &cmd.operator,
                            &clip(reason, RECORD_FIELD_BYTES),
                            now,
                        )
                        .map_err(CommandError::from),
                },
                Action::InService => self
                    .engine
                    .return_to_service(&cmd.alarm, now)
                    .map_err(CommandError::from),
                // Taken by `switch_command` above.
                Action::Force | Action::Stop => Err(CommandError::NotHandledHere(cmd.action)),
                Action::Configure => match self.configure(&cmd) {
                    Err(why) => Err(why),
                    Ok(asks) => {
                        let record = CommandRecord {
                            verified: true,
                            ..base
                        };
                        return self.reload_asked(record, asks, reply).await;
                    }
                },
                Action::Write => match self.write(&cmd) {
                    Err(why) => Err(why),
                    Ok((tag, value)) => {
                        let record = CommandRecord {
                            verified: true,
                            ..base
                        };
                        return self.write_value(record, tag, value, reply).await;
                    }
                },
            },
        };
        let (accepted, detail, step) = match done {
            Ok(step) => (
                true,
                format!("{} {} by {}{said}", cmd.action, cmd.alarm, cmd.operator),
                step,
            ),
            Err(why) => (false, why.to_string(), EngineStep::default()),
        };
        let record = CommandRecord {
            verified,
            ..base.saying(accepted, &detail)
        };
        if !record.accepted {
            tracing::warn!(detail = %record.detail, "operator command refused");
        }
        let outcome = CommandOutcome::new(record.accepted, record.detail.clone());
        self.dispatch(now, Input::Command(record), step, 0).await;
        let _ = reply.send(outcome);
    }

    /// A command refused before a known operator's signature was verified:
    /// journaled as a row of its own only when it is the first of its
    /// source and reason this minute, otherwise counted for the minute's
    /// summary ([`refusals`]); the journal grows by at most two rows per
    /// source, reason and minute whatever arrives.
    pub(super) async fn unauthenticated(
        &mut self,
        source: &str,
        reason: &'static str,
        record: CommandRecord,
        outcome: CommandOutcome,
        reply: oneshot::Sender<CommandOutcome>,
        now: u64,
    ) {
        let noted = self.refusals.note(source, reason, now);
        self.summaries(noted.ended, now).await;
        if noted.first {
            tracing::warn!(source = %noted.source, reason, detail = %record.detail, "command refused before its signature was verified (more from this source this minute are only counted)");
            let record = CommandRecord {
                source: noted.source,
                ..record
            };
            self.dispatch(now, Input::Command(record), EngineStep::default(), 0)
                .await;
        }
        let _ = reply.send(outcome);
    }

    /// Journals the summaries of refusals of windows that have ended.
    pub(super) async fn summaries(&mut self, ended: Vec<refusals::Summary>, now: u64) {
        for s in ended {
            let record = CommandRecord::refused(s.detail(), s.source, s.count);
            self.dispatch(now, Input::Command(record), EngineStep::default(), 0)
                .await;
        }
    }

    /// What an authorised write writes: the tag's index and the value; or
    /// why it is refused here (never sent) when the tag is unknown, the
    /// command carries no value, or the source cannot write.
    pub(super) fn write(&mut self, cmd: &Command) -> Result<(usize, String), CommandError> {
        if !cmd.alarm.is_empty() {
            return Err(CommandError::WriteNamesAlarm);
        }
        let (Some(tag), Some(value)) = (&cmd.tag, &cmd.value) else {
            return Err(CommandError::WriteIncomplete);
        };
        let Some(index) = self
            .engine
            .tag_index(&cellwatch_models::signal::Signal::new(tag))
        else {
            return Err(CommandError::NoTag(clip(tag, RECORD_FIELD_BYTES)));
        };
        if self.writer.is_none() {
            return Err(CommandError::NoWrites);
        }
        Ok((index, value.clone()))
    }

    /// Carries out an authorised write: its request row (with the nonce)
    /// journaled and committed first, then the value handed to the source;
    /// the PLC's answer comes back as a [`Written`] (the loop goes on
    /// meanwhile), journaled as the result, and only then answered.
    pub(super) async fn write_value(
        &mut self,
        record: CommandRecord,
        tag: usize,
        value: String,
        reply: oneshot::Sender<CommandOutcome>,
    ) {
        let now = self.clock.now_ms();
        let request = CommandRecord {
            stage: Stage::Request,
            ..record.clone().saying(
                true,
                &format!(
                    "write {} to {} asked by {}",
                    clip(&value, RECORD_FIELD_BYTES),
                    record.alarm,
                    record.operator
                ),
            )
        };
        self.dispatch(now, Input::Command(request), EngineStep::default(), 0)
            .await;
        let written = self.write_when_journaled(Some(tag), Write::Value(value), WRITE_TIMEOUT);
        let back = self.written_tx.clone();
        self.start_task(async move {
            let _ = back
                .send(Written::answer(record, written.await, reply))
                .await;
        });
    }

    /// Hands `what` for tag `tag` to the source once every row dispatched
    /// so far (the command's nonce among them) is committed, so that a
    /// crash between the write and its journal row cannot make the same
    /// signed command new again; resolves to what the PLC answered, within
    /// `limit`. Not written while the journal cannot write.
    pub(super) fn write_when_journaled(
        &self,
        tag: Option<usize>,
        what: Write,
        limit: Duration,
    ) -> impl Future<Output = Result<String, CommandError>> + Send + 'static {
        let settled = self.settled();
        let health = self.journal_health.clone();
        let writer = self.writer.clone();
        async move {
            settled.await;
            if let Some(why) = health.as_ref().and_then(|h| h.borrow().clone()) {
                return Err(CommandError::JournalDown(why));
            }
            let Some(writer) = writer else {
                return Err(CommandError::NoWrites);
            };
            let (reply, pending) = oneshot::channel();
            writer
                .try_send(WriteRequest { tag, what, reply })
                .map_err(|_| CommandError::WritesBusy)?;
            match tokio::time::timeout(limit, pending).await {
                // What the source said, whatever type it says it in.
                Ok(Ok(r)) => r.map_err(|said| CommandError::NotWritten(said.to_string())),
                Ok(Err(_)) => Err(CommandError::SourceStopped),
                Err(_) => Err(CommandError::NoPlcAnswer(limit)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::stray_field;
    use crate::operator::{Action, Command};

    fn command(action: Action, tag: bool, value: bool, reason: bool) -> Command {
        Command {
            action,
            alarm: "ese".into(),
            tag: tag.then(|| "D100".into()),
            value: value.then(|| "30m".into()),
            reason: reason.then(|| "tool changed".into()),
            operator: "kim".into(),
            nonce: crate::operator::nonce(),
            issued_at: 0,
            signature: String::new(),
        }
    }

    #[test]
    fn an_acknowledgement_takes_a_comment_and_a_reset_none() {
        assert_eq!(stray_field(&command(Action::Ack, false, false, true)), None);
        assert_eq!(
            stray_field(&command(Action::Ack, false, true, false)),
            Some("value")
        );
        assert_eq!(
            stray_field(&command(Action::Reset, false, false, true)),
            Some("reason")
        );
        assert_eq!(
            stray_field(&command(Action::Shelve, false, true, true)),
            None
        );
        assert_eq!(
            stray_field(&command(Action::Unshelve, false, false, true)),
            Some("reason")
        );
        assert_eq!(
            stray_field(&command(Action::Write, true, true, false)),
            None
        );
        assert_eq!(
            stray_field(&command(Action::Write, true, true, true)),
            Some("reason")
        );
        assert_eq!(
            stray_field(&command(Action::Ack, true, false, false)),
            Some("tag")
        );
    }
}
