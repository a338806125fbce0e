//! The PLC's own alarms in the cell loop: an operator's acknowledgement of
//! one is the PLC's first. Its request row is journaled and committed, the
//! source calls the condition's `Acknowledge` method (with the operator in
//! its comment), and only when the PLC has taken it is the alarm
//! acknowledged in cellwatch, by that operator; a refusal is the
//! command's, with the PLC's reason. An acknowledgement made at the PLC
//! (an HMI's) comes back as the condition's event.

use tokio::sync::oneshot;

use super::{CellLoop, CommandOutcome, CommandRecord, Input, Stage, Then, Written, WRITE_TIMEOUT};
use crate::sources::Write;
use cellwatch_models::engine::EngineStep;

impl CellLoop {
    /// Carries out an authorised acknowledgement of PLC alarm
    /// `record.alarm`; answered once the PLC has said and it is journaled.
    /// The operator's `comment` follows the request's row and the comment
    /// the PLC is given, and is kept with the alarm.
    pub(super) async fn acknowledge_at_plc(
        &mut self,
        record: CommandRecord,
        comment: Option<&str>,
        reply: oneshot::Sender<CommandOutcome>,
    ) {
        let now = self.clock.now_ms();
        let said = comment.map_or_else(String::new, |c| format!(": {c}"));
        let alarm = record.alarm.clone();
        let refused = match self.engine.alarms().find(|a| a.id == alarm) {
            None => Some(format!("unknown alarm '{alarm}'")),
            Some(a) if a.acknowledged => Some(format!("{alarm} is already acknowledged")),
            Some(_) if self.writer.is_none() => Some("this cell's source takes no writes".into()),
            Some(_) => None,
        };
        if let Some(why) = refused {
            let record = CommandRecord {
                verified: true,
                ..record.saying(false, &why)
            };
            let outcome = CommandOutcome::new(false, why);
            self.dispatch(now, Input::Command(record), EngineStep::default(), 0)
                .await;
            let _ = reply.send(outcome);
            return;
        }
        let request = CommandRecord {
            stage: Stage::Request,
            verified: true,
            ..record.clone().saying(
                true,
                &format!(
                    "acknowledge {alarm} at the PLC, asked by {}{said}",
                    record.operator
                ),
            )
        };
        self.dispatch(now, Input::Command(request), EngineStep::default(), 0)
            .await;
        let to_plc = format!("acknowledged in cellwatch by {}{said}", record.operator);
        let written = self.write_when_journaled(
            None,
            Write::Acknowledge {
                alarm,
                comment: to_plc,
            },
            WRITE_TIMEOUT,
        );
        let comment = comment.map(str::to_string);
        let back = self.written_tx.clone();
        let record = CommandRecord {
            verified: true,
            ..record
        };
        self.start_task(async move {
            let w = Written {
                then: Then::Acknowledge(comment),
                ..Written::answer(record, written.await, reply)
            };
            let _ = back.send(w).await;
        });
    }

    /// The PLC took the acknowledgement: the alarm is acknowledged in
    /// cellwatch by the operator (unless the PLC's event said so first).
    pub(super) async fn acknowledged_at_plc(
        &mut self,
        record: &CommandRecord,
        comment: Option<&str>,
    ) {
        let now = self.clock.now_ms();
        if let Ok(step) = self
            .engine
            .acknowledge(&record.alarm, &record.operator, comment, now)
        {
            self.dispatch(now, Input::Readings, step, 0).await;
        }
    }
}
