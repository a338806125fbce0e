//! Acknowledgements and shelves from the alarm server's OPC UA sessions:
//! the user was authenticated by the session (a password over an
//! encrypted channel), not by a signature, so this entry takes only what
//! such a user may ask (`ack`, `shelve`, `unshelve`) and only from the
//! channel the alarm server holds (`CellLoop::acknowledging_sessions`);
//! commands from the bus stay signed. The operator's permission is the
//! gate's; the row is journaled like a signed command's, its source naming
//! the OPC UA user.

use cellwatch_models::alarm::CommandRefused;
use cellwatch_models::engine::EngineStep;
use tokio::sync::{mpsc, oneshot};

use super::{CellLoop, CommandOutcome, CommandRecord, Input, Stage};
use crate::operator::{Action, Command};
use crate::sinks::Settled;
use crate::step::{SessionCommand, SessionOutcome};

impl CellLoop {
    /// Takes acknowledgements and shelves from the alarm server's sessions
    /// on `commands`.
    #[must_use]
    pub fn acknowledging_sessions(mut self, commands: mpsc::Receiver<SessionCommand>) -> CellLoop {
        self.session_commands = Some(commands);
        self
    }

    /// One command from an OPC UA session: the operator's permission
    /// checked, carried out (an acknowledgement of the PLC's own alarm at
    /// the PLC first), journaled, and answered once durable.
    pub(super) async fn session_command(&mut self, asked: SessionCommand) {
        let now = self.clock.now_ms();
        let SessionCommand {
            user,
            operator,
            action,
            alarm,
            value,
            comment,
            reply,
        } = asked;
        // A shelf or a removal from service needs a reason: the operator's
        // comment, or where it came from.
        let reason = match action {
            Action::Shelve => Some("shelved"),
            Action::OutOfService => Some("disabled"),
            _ => None,
        }
        .map(|done| {
            if comment.is_empty() {
                format!("{done} over OPC UA by {}", crate::operator::clip(&user, 64))
            } else {
                comment.clone()
            }
        });
        let cmd = Command {
            action,
            alarm,
            tag: None,
            value,
            reason,
            operator,
            // The row's own: nothing can send it again.
            nonce: crate::operator::nonce(),
            issued_at: now,
            signature: String::new(),
        };
        let base = CommandRecord {
            source: format!("opcua user {}", crate::operator::clip(&user, 64)),
            // The user was authenticated by the session.
            verified: true,
            ..CommandRecord::of(&cmd, &cmd.alarm, Stage::Command)
        };
        // The operator's own words, after what was done.
        let said = if comment.is_empty() {
            String::new()
        } else {
            format!(": {comment}")
        };
        if let Err(refusal) = self.gate.permits(&cmd.operator, cmd.action) {
            let detail = refusal.to_string();
            tracing::warn!(source = %base.source, %detail, "a command over OPC UA refused");
            let record = base.saying(false, &detail);
            self.dispatch(now, Input::Command(record), EngineStep::default(), 0)
                .await;
            let settled = self.settled();
            self.start_task(async move {
                settled.await;
                let _ = reply.send(SessionOutcome::Denied(detail));
            });
            return;
        }
        if cmd.action == Action::Ack && self.engine.is_condition(&cmd.alarm) {
            let (outcome_tx, outcome) = oneshot::channel::<CommandOutcome>();
            let comment = (!comment.is_empty()).then_some(comment.as_str());
            self.acknowledge_at_plc(base, comment, outcome_tx).await;
            // Its rows come later (the PLC's answer): waited for then.
            let sinks: Vec<Settled> = self.sinks.iter().filter_map(|s| s.settled()).collect();
            self.start_task(async move {
                if let Ok(o) = outcome.await {
                    for s in &sinks {
                        s().await;
                    }
                    let _ = reply.send(if o.accepted {
                        SessionOutcome::Accepted(o.detail)
                    } else {
                        SessionOutcome::Refused(o.detail)
                    });
                }
            });
            return;
        }
        let done = match cmd.action {
            Action::Ack => self
                .engine
                .acknowledge(
                    &cmd.alarm,
                    &cmd.operator,
                    (!comment.is_empty()).then_some(comment.as_str()),
                    now,
                )
                .map_err(outcome_of),
            Action::Shelve => self
                .shelf(&cmd, now)
                .map_err(|e| SessionOutcome::OutOfRange(e.to_string()))
                .and_then(|until| {
                    let reason = cmd.reason.as_deref().unwrap_or_default();
                    self.engine
                        .shelve(&cmd.alarm, &cmd.operator, reason, until, now)
                        .map_err(outcome_of)
                }),
            Action::Unshelve => self.engine.unshelve(&cmd.alarm, now).map_err(outcome_of),
            Action::OutOfService => self
                .engine
                .take_out_of_service(
                    &cmd.alarm,
                    &cmd.operator,
                    cmd.reason.as_deref().unwrap_or_default(),
                    now,
                )
                .map_err(outcome_of),
            Action::InService => self
                .engine
                .return_to_service(&cmd.alarm, now)
                .map_err(outcome_of),
            other => Err(SessionOutcome::Refused(format!(
                "{other} is not taken over OPC UA"
            ))),
        };
        let (outcome, step) = match done {
            Ok(step) => (
                SessionOutcome::Accepted(format!(
                    "{} {} by {}{said}",
                    cmd.action, cmd.alarm, cmd.operator
                )),
                step,
            ),
            Err(o) => (o, EngineStep::default()),
        };
        let (accepted, detail) = match &outcome {
            SessionOutcome::Accepted(d) => (true, d.as_str()),
            SessionOutcome::Denied(d)
            | SessionOutcome::WrongState(d)
            | SessionOutcome::OutOfRange(d)
            | SessionOutcome::Refused(d) => (false, d.as_str()),
        };
        let record = base.saying(accepted, detail);
        self.dispatch(now, Input::Command(record), step, 0).await;
        let settled = self.settled();
        self.start_task(async move {
            settled.await;
            let _ = reply.send(outcome);
        });
    }
}

/// What the engine's refusal is to an OPC UA client: the alarm not in a
/// state the method applies to, or refused.
fn outcome_of(e: CommandRefused) -> SessionOutcome {
    match e {
        CommandRefused::NothingToAcknowledge(_) => SessionOutcome::WrongState(e.to_string()),
        CommandRefused::Shelving {
            what: "unshelved", ..
        }
        | CommandRefused::Service { .. } => SessionOutcome::WrongState(e.to_string()),
        _ => SessionOutcome::Refused(e.to_string()),
    }
}
