//! The contract between the cell loop and its sinks: one input and
//! everything it caused ([`CellStep`]). The cell loop makes steps; the
//! journal, the bus, the metrics and the console consume them. Both sides
//! import this module; it imports neither.

use cellwatch_models::engine::EngineStep;
use cellwatch_models::oee::{Figures, ShiftWindow};
use tokio::sync::{oneshot, watch};

use crate::operator::{clip, Action, Command, NotACommand};
use crate::payload::{AlarmPayload, SnapshotPayload, StatePayload};

/// What came into the loop.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    /// The PLC connection came up (`up`) or went down; to what, or why.
    Connection {
        /// Up or down.
        up: bool,
        /// The endpoint, or why it went down.
        detail: String,
    },
    /// Values from the PLC (the engine step says how many).
    Readings,
    /// Time passed: timers were advanced.
    Tick,
    /// The periodic state publication (no change).
    StateBeat,
    /// The alarms and machine state taken back from the journal at start.
    Restored,
    /// The configuration was read again: the new engine took over the
    /// running one's alarms, state and values.
    Reloaded,
    /// A condition of the agent itself changed (the journal's health).
    System,
    /// An operator command, carried out or refused.
    Command(CommandRecord),
}

/// An operator command as journaled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CommandRecord {
    /// Who signed it (as claimed, for refused ones).
    pub operator: String,
    /// What was asked; `None` if the request did not parse.
    pub action: Option<Action>,
    /// The alarm it names.
    pub alarm: String,
    /// The request's nonce.
    pub nonce: String,
    /// Whether it was carried out.
    pub accepted: bool,
    /// Whether its signature was verified (its nonce is used up).
    pub verified: bool,
    /// What it did, or why it was refused.
    pub detail: String,
    /// Which part of the command this row records.
    pub stage: Stage,
    /// Where the query came from, as it says ([`refusals::UNKNOWN_SOURCE`]
    /// when it does not); kept for refusals before a signature is verified.
    pub source: String,
    /// How many refusals the row stands for ([`Stage::Refused`]); 1 for
    /// every other row.
    pub count: u64,
    /// The command's [`Command::digest`] (hex), in every row of a command;
    /// `None` in a refusal that names no command.
    pub digest: Option<String>,
}

impl CommandRecord {
    /// A request refused before it names anyone (not a command, or a
    /// minute's count of refusals from `source`): no operator, no nonce.
    pub(crate) fn refused(detail: String, source: String, count: u64) -> CommandRecord {
        CommandRecord {
            operator: String::new(),
            action: None,
            alarm: String::new(),
            nonce: String::new(),
            accepted: false,
            verified: false,
            detail,
            stage: Stage::Refused,
            source,
            count,
            digest: None,
        }
    }

    /// A row of `cmd` (its sender's fields cut to [`RECORD_FIELD_BYTES`]),
    /// naming `target` (the alarm, tag, transition or chart).
    pub(crate) fn of(cmd: &Command, target: &str, stage: Stage) -> CommandRecord {
        let field = |s: &str| clip(s, RECORD_FIELD_BYTES);
        CommandRecord {
            operator: field(&cmd.operator),
            action: Some(cmd.action),
            alarm: field(target),
            nonce: field(&cmd.nonce),
            accepted: false,
            verified: false,
            detail: String::new(),
            stage,
            source: String::new(),
            count: 1,
            digest: Some(hex::encode(cmd.digest())),
        }
    }

    /// The same row saying `detail` (cut to four times
    /// [`RECORD_FIELD_BYTES`]).
    pub(crate) fn saying(self, accepted: bool, detail: &str) -> CommandRecord {
        CommandRecord {
            accepted,
            detail: clip(detail, 4 * RECORD_FIELD_BYTES),
            ..self
        }
    }
}

/// A row of a command in the journal: a plain command is one row; a
/// forced transition or a stop is its request, each check, the write and
/// the result, in that order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// A command in one row (ack, reset, shelve, write, …).
    Command,
    /// What was asked.
    Request,
    /// One check and its outcome.
    Check,
    /// The write to the PLC and what it answered.
    Write,
    /// How it ended.
    Result,
    /// Refused before a known operator's signature was verified: the first
    /// of its source and reason in a minute, or how many more came
    /// ([`CommandRecord::count`], [`refusals`]).
    Refused,
}

impl Stage {
    /// Its name in the journal.
    pub fn as_str(self) -> &'static str {
        match self {
            Stage::Command => "command",
            Stage::Request => "request",
            Stage::Check => "check",
            Stage::Write => "write",
            Stage::Result => "result",
            Stage::Refused => "refused",
        }
    }

    /// Whether the row ends its command (counted once in the metrics;
    /// refusals summarised are counted one by one as refused requests).
    pub fn is_final(self) -> bool {
        matches!(self, Stage::Command | Stage::Result)
    }
}

/// What of a sender's fields is journaled and logged, at most.
pub const RECORD_FIELD_BYTES: usize = 128;

/// An alarm transition ready to publish: the payload and its JSON.
#[derive(Debug, Clone, PartialEq)]
pub struct PublishedAlarm {
    /// The payload.
    pub payload: AlarmPayload,
    /// The same, as JSON (journaled and published byte for byte).
    pub json: String,
}

/// One input and everything it caused: what every sink is given.
#[derive(Debug, Clone, PartialEq)]
pub struct CellStep {
    /// When the loop handled it, ms since the epoch.
    pub at: u64,
    /// What came in.
    pub input: Input,
    /// What the engine did.
    pub engine: EngineStep,
    /// The engine's alarm transitions as payloads, in the same order.
    pub alarms: Vec<PublishedAlarm>,
    /// The machine state to publish, when it changed (or on a beat).
    pub state: Option<StatePayload>,
    /// Source events waiting in the queue after this one.
    pub queue_depth: usize,
    /// When the source received the values this step handles: the start
    /// of the agent's own latency (`cellwatch_alarm_latency_seconds`).
    pub received: Option<std::time::Instant>,
    /// Where the transitions measured in this step stand in their learned
    /// windows (drift tracking), one entry each.
    pub positions: Vec<cellwatch_models::engine::WindowPosition>,
    /// The engine's finished flight recordings as JSON
    /// ([`crate::payload::RecordingPayload`]), in the same order.
    pub recordings: Vec<String>,
}

impl CellStep {
    /// Whether the step carries something worth a journal row.
    pub fn has_rows(&self) -> bool {
        !self.alarms.is_empty()
            || !self.recordings.is_empty()
            || self.engine.states().next().is_some()
            || !self.engine.parts.is_empty()
            || matches!(self.input, Input::Command(_))
    }
}

/// What an operator's command came to, as the agent answers it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CommandOutcome {
    /// Whether it was carried out (never for a command sent again: see
    /// `replayed`).
    pub accepted: bool,
    /// What it did, or why not.
    pub detail: String,
    /// The command answered: [`command_digest`] of the payload exactly as
    /// the query carried it (set by the services, which read it). A client
    /// believes only an answer naming its own payload.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<String>,
    /// The same signed command was sent before (its answer lost, or
    /// someone sent it again): this one is not carried out, and this is
    /// what the first came to.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replayed: Option<FirstOutcome>,
    /// Why it was refused before a known operator's signature was
    /// verified (`cellwatch_requests_refused_total`'s reason); not sent.
    #[serde(skip)]
    pub refused: Option<&'static str>,
}

/// What the first sending of a command sent again came to.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FirstOutcome {
    /// Whether it was carried out.
    pub accepted: bool,
    /// What it did, or why not.
    pub detail: String,
}

impl CommandOutcome {
    /// The outcome `detail`, accepted or not.
    pub fn new(accepted: bool, detail: impl Into<String>) -> CommandOutcome {
        CommandOutcome {
            accepted,
            detail: detail.into(),
            command: None,
            replayed: None,
            refused: None,
        }
    }

    /// The answer to the same signed command sent again, this outcome
    /// being its first's: not accepted, saying "replayed", the first
    /// outcome beside.
    pub fn replayed(&self) -> CommandOutcome {
        let first = self.replayed.clone().unwrap_or(FirstOutcome {
            accepted: self.accepted,
            detail: self.detail.clone(),
        });
        // "Not accepted", not "refused": a first sending whose outcome the
        // journal never got (the agent stopped) was not refused either.
        let then = if first.accepted {
            "accepted"
        } else {
            "not accepted"
        };
        CommandOutcome {
            replayed: Some(first.clone()),
            ..CommandOutcome::new(
                false,
                format!(
                    "replayed command: sent before ({then}: {}); not carried out again",
                    first.detail
                ),
            )
        }
    }

    /// The same outcome, answering the payload whose digest is `command`.
    pub fn answering(self, command: String) -> CommandOutcome {
        CommandOutcome {
            command: Some(command),
            ..self
        }
    }
}

/// The digest that binds an answer to its command: SHA-256, hex, of the
/// command's payload exactly as sent (the JSON text, signature included),
/// given in pieces as it arrived.
pub fn command_digest<'a>(pieces: impl IntoIterator<Item = &'a [u8]>) -> String {
    use sha2::Digest;
    let mut hash = sha2::Sha256::new();
    for piece in pieces {
        hash.update(piece);
    }
    hex::encode(hash.finalize())
}

/// A request from the services to the loop, answered on its channel.
// A command is the large one; one per query, moved once through a bounded
// channel: not worth a box.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub enum Request {
    /// The cell as the engine sees it now.
    Snapshot(oneshot::Sender<SnapshotPayload>),
    /// An operator command (or why the request is not one).
    Command {
        /// Who sent it, as the query says (see [`refusals`]).
        source: String,
        /// The parsed command, or why the request is not one.
        command: Result<Command, NotACommand>,
        /// Where the outcome goes.
        reply: oneshot::Sender<CommandOutcome>,
    },
    /// A newer plant operators list, verified: the operators commands are
    /// judged by from now on.
    Operators(OperatorsTaken),
}

/// The operators of a plant operators list for this cell, to be taken by
/// the loop (between two commands) and journaled.
#[derive(Debug)]
pub struct OperatorsTaken {
    /// The list's version.
    pub version: u64,
    /// Its operators for this cell.
    pub keys: crate::operator::OperatorKeys,
    /// Told once the loop judges by them, with what changed in words.
    pub reply: oneshot::Sender<String>,
}

/// An acknowledgement or a shelf asked by an OPC UA session of the alarm
/// server: the session's user was authenticated by the server and maps to
/// `operator`; the cell loop checks the operator's permission for
/// `action`, carries it out and journals it like a signed command. It
/// comes on a channel of its own that only the alarm server holds, never
/// from the bus.
#[derive(Debug)]
pub struct SessionCommand {
    /// The OPC UA user of the session.
    pub user: String,
    /// The operator the user acts as (the alarm server's users file).
    pub operator: String,
    /// `ack`, `shelve`, `unshelve`, `out-of-service` or `in-service`.
    pub action: crate::operator::Action,
    /// The alarm it names.
    pub alarm: String,
    /// A shelf's length (`1800000ms`), or `once`; none for the others.
    pub value: Option<String>,
    /// The method's `Comment`, clipped and escaped; may be empty.
    pub comment: String,
    /// Where the outcome goes, once journaled.
    pub reply: oneshot::Sender<SessionOutcome>,
}

/// What a [`SessionCommand`] came to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SessionOutcome {
    /// Carried out: what it did.
    Accepted(String),
    /// The operator may not do it (or is not known): why.
    Denied(String),
    /// The alarm is not in a state it applies to (nothing to acknowledge,
    /// not shelved): why.
    WrongState(String),
    /// A value out of the cell's range (a shelf longer than
    /// `commands.max_shelve`): why.
    OutOfRange(String),
    /// Refused for another reason (no such alarm, the PLC refused): why.
    Refused(String),
}

/// The next [`SessionCommand`] on `acks`; never, when there is no alarm
/// server (`None`) or it has stopped.
pub async fn next_session_command(
    acks: &mut Option<tokio::sync::mpsc::Receiver<SessionCommand>>,
) -> Option<SessionCommand> {
    match acks {
        Some(rx) => match rx.recv().await {
            Some(a) => Some(a),
            None => {
                *acks = None;
                None
            }
        },
        None => std::future::pending().await,
    }
}

/// The current shift's figures (or the last shift's, between shifts), as
/// computed at `at`.
#[derive(Debug, Clone, PartialEq)]
pub struct OeeNow {
    /// The shift.
    pub shift: ShiftWindow,
    /// Its figures up to `at`.
    pub figures: Figures,
    /// When they were computed, ms since the epoch.
    pub at: u64,
}

/// What watchers of the OEE (the snapshot, the Sparkplug B node) hold: `None` until the first tick in a
/// shift.
pub type OeeWatch = watch::Receiver<Option<OeeNow>>;
