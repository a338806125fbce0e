//! Why an operator's command was not carried out on this cell
//! ([`CommandError`]): what the operator is answered and the journal
//! records, word for word.

use std::time::Duration;

use cellwatch_models::alarm::CommandRefused;

use super::swap::NotReloaded;
use crate::operator::{Action, Refusal};

/// Why an operator's command was not carried out on this cell.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// Refused at the gate (signature, permission, replay, …).
    #[error(transparent)]
    Gate(#[from] Refusal),
    /// The command carries a field its action does not take.
    #[error("{action} takes no {field}")]
    StrayField {
        /// The command's action.
        action: Action,
        /// The field it does not take (`tag`, `value`, `reason`).
        field: &'static str,
    },
    /// The engine refused it (no such alarm, not active, …).
    #[error(transparent)]
    Engine(#[from] CommandRefused),
    /// A shelf without a reason.
    #[error("a shelf needs a reason")]
    ShelfNeedsReason,
    /// A shelf whose duration does not read.
    #[error("shelve for '{0}': give a duration (30m, 2h) or once")]
    ShelfDuration(String),
    /// A shelf longer than the cell allows (or of no time at all).
    #[error("shelve for {asked}: at most {} on this cell", humantime::format_duration(*.max))]
    ShelfTooLong {
        /// The duration asked, as written.
        asked: String,
        /// The cell's longest shelf.
        max: Duration,
    },
    /// A shelf with no duration.
    #[error("shelve needs a duration (30m, 2h) or once")]
    ShelfNeedsDuration,
    /// A removal from service without a reason.
    #[error("out-of-service needs a reason (--reason)")]
    OutOfServiceNeedsReason,
    /// An action another part of the loop carries out.
    #[error("{0} is not handled here")]
    NotHandledHere(Action),
    /// A force or stop naming more than its chart or transition.
    #[error("{0} names a chart or transition only (no alarm, tag or reason)")]
    SwitchNamesMore(Action),
    /// A `configure` naming an alarm or a tag.
    #[error("configure names no alarm or tag")]
    ConfigureNamesMore,
    /// A `configure` whose value is not `reload`.
    #[error("configure: the only value is reload (read the configuration file again)")]
    ConfigureValue,
    /// A `configure reload` to an agent not run from a file.
    #[error("this agent was not started from a configuration file: nothing to read again")]
    NoConfigurationFile,
    /// A write naming an alarm.
    #[error("a write names a tag, not an alarm")]
    WriteNamesAlarm,
    /// A write without a tag or a value.
    #[error("a write needs a tag and a value")]
    WriteIncomplete,
    /// A write to a tag the cell does not have (its name, clipped).
    #[error("no tag {0}")]
    NoTag(String),
    /// The cell's source cannot write.
    #[error("this cell's source takes no writes")]
    NoWrites,
    /// The journal cannot write (why), and a write waits for its command
    /// to be on disk.
    #[error(
        "not written: the journal cannot write ({0}), and a write waits until its command is on disk"
    )]
    JournalDown(String),
    /// The source's queue of writes is full.
    #[error("busy: other writes are waiting for the PLC")]
    WritesBusy,
    /// The source stopped before it wrote.
    #[error("the source stopped before writing")]
    SourceStopped,
    /// The PLC did not answer a write in time.
    #[error("no answer from the PLC within {} s", .0.as_secs())]
    NoPlcAnswer(Duration),
    /// What the source said of a write it could not carry out.
    #[error("{0}")]
    NotWritten(String),
    /// The agent is stopping.
    #[error("the agent is stopping")]
    Stopping,
    /// A reload asked for had no outcome in time.
    #[error("no outcome within {} s", .0.as_secs())]
    NoReloadOutcome(Duration),
    /// The configuration read again was not taken.
    #[error(transparent)]
    NotReloaded(#[from] NotReloaded),
    /// A force whose target is not `CHART.TRANSITION`.
    #[error("'{0}' is not CHART.TRANSITION (F1.t3)")]
    NotATransition(String),
    /// Another force is under way.
    #[error("{transition} forced by {operator} is still under way")]
    ForceUnderWay {
        /// The transition being forced.
        transition: String,
        /// Who forced it.
        operator: String,
    },
    /// A check of a force that does not hold.
    #[error("{check}: {detail}")]
    CheckFailed {
        /// The check.
        check: &'static str,
        /// What it found.
        detail: String,
    },
    /// A chart the cell does not have.
    #[error("no chart '{0}' on this cell")]
    NoChart(String),
    /// A stop on a chart without a stop switch.
    #[error("chart {0} has no stop switch (checks.sfc stop_switch)")]
    NoStopSwitch(String),
}
