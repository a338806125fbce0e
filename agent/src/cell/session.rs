//! Acknowledgements from the alarm server's OPC UA sessions: the user was
//! authenticated by the session (a password over an encrypted channel),
//! not by a signature, so this entry takes only what such a user may ask
//! (an acknowledgement) and only from the channel the alarm server holds
//! (`CellLoop::acknowledging_sessions`); commands from the bus stay signed.
//! The operator's permission is the gate's; the row is journaled like a
//! signed command's, its source naming the OPC UA user.

use cellwatch_models::alarm::CommandRefused;
use cellwatch_models::engine::Step;
use tokio::sync::{mpsc, oneshot};

use super::{CellLoop, CommandOutcome, CommandRecord, Input, Stage};
use crate::operator::{Action, Command};
use crate::sinks::Settled;
use crate::step::{SessionAck, SessionAckOutcome};

impl CellLoop {
    /// Takes acknowledgements from the alarm server's sessions on `acks`.
    #[must_use]
    pub fn acknowledging_sessions(mut self, acks: mpsc::Receiver<SessionAck>) -> CellLoop {
        self.session_acks = Some(acks);
        self
    }

    /// One acknowledgement from an OPC UA session: the operator's
    /// permission checked, carried out (at the PLC first for the PLC's own
    /// alarms), journaled, and answered once durable.
    pub(super) async fn session_ack(&mut self, ack: SessionAck) {
        let now = self.clock.now_ms();
        let cmd = Command {
            action: Action::Ack,
            alarm: ack.alarm,
            tag: None,
            value: None,
            reason: None,
            operator: ack.operator,
            // The row's own: nothing can send it again.
            nonce: crate::operator::nonce(),
            issued_at: now,
            signature: String::new(),
        };
        let base = CommandRecord {
            source: format!("opcua user {}", crate::operator::clip(&ack.user, 64)),
            // The user was authenticated by the session.
            verified: true,
            ..CommandRecord::of(&cmd, &cmd.alarm, Stage::Command)
        };
        let reply = ack.reply;
        // The operator's own words, after what was done.
        let said = if ack.comment.is_empty() {
            String::new()
        } else {
            format!(": {}", ack.comment)
        };
        if let Err(refusal) = self.gate.permits(&cmd.operator, Action::Ack) {
            let detail = refusal.to_string();
            tracing::warn!(source = %base.source, %detail, "acknowledgement over OPC UA refused");
            let record = base.saying(false, &detail);
            self.dispatch(now, Input::Command(record), Step::default(), 0)
                .await;
            let settled = self.settled();
            self.start_task(async move {
                settled.await;
                let _ = reply.send(SessionAckOutcome::Denied(detail));
            });
            return;
        }
        if self.engine.is_condition(&cmd.alarm) {
            let (outcome_tx, outcome) = oneshot::channel::<CommandOutcome>();
            self.acknowledge_at_plc(base, &said, outcome_tx).await;
            // Its rows come later (the PLC's answer): waited for then.
            let sinks: Vec<Settled> = self.sinks.iter().filter_map(|s| s.settled()).collect();
            self.start_task(async move {
                if let Ok(o) = outcome.await {
                    for s in &sinks {
                        s().await;
                    }
                    let _ = reply.send(if o.accepted {
                        SessionAckOutcome::Accepted(o.detail)
                    } else {
                        SessionAckOutcome::Refused(o.detail)
                    });
                }
            });
            return;
        }
        let (outcome, step) = match self.engine.acknowledge(&cmd.alarm, &cmd.operator, now) {
            Ok(step) => (
                SessionAckOutcome::Accepted(format!("ack {} by {}{said}", cmd.alarm, cmd.operator)),
                step,
            ),
            Err(e @ CommandRefused::NothingToAcknowledge(_)) => (
                SessionAckOutcome::AlreadyAcknowledged(e.to_string()),
                Step::default(),
            ),
            Err(e) => (SessionAckOutcome::Refused(e.to_string()), Step::default()),
        };
        let (accepted, detail) = match &outcome {
            SessionAckOutcome::Accepted(d) => (true, d.as_str()),
            SessionAckOutcome::Denied(d)
            | SessionAckOutcome::AlreadyAcknowledged(d)
            | SessionAckOutcome::Refused(d) => (false, d.as_str()),
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
