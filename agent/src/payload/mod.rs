//! The JSON payloads cellwatch publishes on Zenoh and stores in its
//! journal. Each carries a `schema` name so that subscribers can tell
//! versions apart.

use cellwatch_models::alarm::{
    Alarm, AlarmKind, AlarmState, Consequence, DesignedSuppression, Removal, Severity, Shelf,
    Transition,
};
use cellwatch_models::engine::{HistoryKind, MachineState, Order, StateName};
use cellwatch_models::explain::Culprit;
use serde::{Deserialize, Serialize};

use crate::clock::rfc3339;

/// Schema name of alarm events.
pub const ALARM_SCHEMA: &str = "cellwatch.alarm.v1";
/// Schema name of machine-state messages.
pub const STATE_SCHEMA: &str = "cellwatch.state.v1";

/// A culprit as published.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CulpritPayload {
    /// Address (`X0.06`).
    pub address: String,
    /// Value at the fault.
    pub value: bool,
    /// Value that would clear it.
    pub expected: bool,
    /// I/O-list comment.
    pub comment: Option<String>,
    /// Changed just before the fault.
    pub trigger: bool,
    /// For a comparison (`address` its text): the variable compared, its
    /// number and what it needs, `rSpindleSpeed = 1650.0 (needs >= 1800)`;
    /// absent for a contact.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compared: Option<String>,
}

impl From<&Culprit> for CulpritPayload {
    fn from(c: &Culprit) -> Self {
        CulpritPayload {
            address: c.address.to_string(),
            value: c.value,
            expected: c.expected,
            comment: c.comment.clone(),
            trigger: c.trigger,
            compared: c
                .compared
                .as_ref()
                .map(|k| format!("{} = {} (needs {})", k.variable, k.value, k.needs)),
        }
    }
}

impl CulpritPayload {
    /// One line for people: `X0.06 = 0 (expected 1): Y Over Travel Limit SW (B)   <- trigger`;
    /// a comparison `rSpindleSpeed = 1650.0 (needs >= 1800): Spindle speed`.
    pub fn line(&self) -> String {
        let comment = self
            .comment
            .as_deref()
            .map(|c| format!(": {c}"))
            .unwrap_or_default();
        let trigger = if self.trigger { "   <- trigger" } else { "" };
        match &self.compared {
            Some(compared) => format!("{compared}{comment}{trigger}"),
            None => format!(
                "{} = {} (expected {}){comment}{trigger}",
                self.address,
                u8::from(self.value),
                u8::from(self.expected)
            ),
        }
    }
}

/// `<prefix>/alarms/<alarm-id>`: one alarm transition.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct AlarmPayload {
    /// [`ALARM_SCHEMA`].
    pub schema: String,
    /// Cell id.
    pub cell: String,
    /// Stable alarm id.
    pub id: String,
    /// `switching`, `timer`, `drift`, `limit`, `step`, `tag_quality`,
    /// `communication`, `system`, `plc` (the PLC's own).
    pub kind: AlarmKind,
    /// `low` .. `critical`.
    pub severity: Severity,
    /// ISA-18.2 state: `active_unacknowledged`, `active_acknowledged`,
    /// `cleared_unacknowledged`, `normal`.
    pub state: AlarmState,
    /// What just happened: `raised`, `cleared`, `acknowledged`, `updated`.
    pub transition: Transition,
    /// When this transition happened (RFC 3339).
    pub at: String,
    /// When the current occurrence was raised.
    pub raised_at: String,
    /// When it cleared, if it has.
    pub cleared_at: Option<String>,
    /// Who acknowledged it.
    pub acked_by: Option<String>,
    /// What they said acknowledging it (their comment); absent in payloads
    /// from before comments were carried.
    #[serde(default)]
    pub ack_comment: Option<String>,
    /// Stays active until an operator resets it.
    #[serde(default)]
    pub latched: bool,
    /// Fault type (`ESE`).
    pub fault_type: String,
    /// Step block at which the fault formed.
    pub fault_step: Option<usize>,
    /// Contacts responsible, triggers first.
    pub culprits: Vec<CulpritPayload>,
    /// One line for people.
    pub message: String,
    /// Shelved by an operator: by whom, why, until when. A shelved alarm
    /// is not to be shown to operators as active.
    #[serde(default)]
    pub shelved: Option<ShelfPayload>,
    /// Out of service: by whom, why, since when. An alarm out of service
    /// is not raised whatever its condition.
    #[serde(default)]
    pub out_of_service: Option<RemovalPayload>,
    /// Raised as the consequence of another active alarm: its cause, the
    /// first-out of the cascade, and whether it is suppressed (journaled
    /// and shown, not annunciated). `null`: a first-out.
    #[serde(default)]
    pub consequence: Option<ConsequencePayload>,
    /// Suppressed by design: the machine mode in which it means nothing
    /// (`[[state.modes]]`), since when. Evaluated and journaled, never
    /// announced; `null`: not suppressed by design.
    #[serde(default)]
    pub suppressed_by_design: Option<DesignedPayload>,
    /// Its rationalisation from the cell's master alarm database
    /// (`alarms.database`): what the operator does and how long they have;
    /// `null` when the database has no row for it.
    #[serde(default)]
    pub guidance: Option<GuidancePayload>,
}

/// The machine mode that suppresses an alarm by design, in its payload.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DesignedPayload {
    /// The mode's id (`setup`).
    pub mode: String,
    /// Since when (RFC 3339).
    pub since: String,
}

impl AlarmPayload {
    /// The payload of `alarm` after `transition` at `at` (ms).
    pub fn new(cell: &str, alarm: &Alarm, transition: Transition, at: u64) -> Self {
        let shelved = alarm.shelved.as_ref().map(|s| ShelfPayload {
            by: s.by.clone(),
            reason: s.reason.clone(),
            at: rfc3339(s.at),
            until: s.until.map(rfc3339),
        });
        let out_of_service = alarm.out_of_service.as_ref().map(|r| RemovalPayload {
            by: r.by.clone(),
            reason: r.reason.clone(),
            at: rfc3339(r.at),
        });
        AlarmPayload {
            shelved,
            out_of_service,
            guidance: alarm.guidance.as_deref().map(|g| GuidancePayload {
                class: g.class.clone(),
                consequence_of_inaction: g.consequence_of_inaction.clone(),
                corrective_action: g.corrective_action.clone(),
                response_time: g.response_time_ms.map(|ms| {
                    humantime::format_duration(std::time::Duration::from_millis(ms)).to_string()
                }),
            }),
            suppressed_by_design: alarm.designed.as_ref().map(|d| DesignedPayload {
                mode: d.mode.clone(),
                since: rfc3339(d.since),
            }),
            consequence: alarm.consequence.as_ref().map(|c| ConsequencePayload {
                cause: c.cause.clone(),
                first_out: c.first_out.clone(),
                suppressed: c.suppressed,
                through: c
                    .through
                    .iter()
                    .map(|(s, v)| ThroughPayload {
                        signal: s.to_string(),
                        value: *v,
                    })
                    .collect(),
            }),
            schema: ALARM_SCHEMA.into(),
            cell: cell.into(),
            id: alarm.id.clone(),
            kind: alarm.kind,
            severity: alarm.severity,
            state: alarm.state(),
            transition,
            at: rfc3339(at),
            raised_at: rfc3339(alarm.raised_at),
            cleared_at: alarm.cleared_at.map(rfc3339),
            acked_by: alarm.acked_by.clone(),
            ack_comment: alarm.ack_comment.clone(),
            latched: alarm.latched,
            fault_type: alarm.fault_type.clone(),
            fault_step: alarm.fault_step,
            culprits: alarm.culprits.iter().map(CulpritPayload::from).collect(),
            message: alarm.message.clone(),
        }
    }
}

impl AlarmPayload {
    /// The alarm this payload describes, as the engine keeps it: how a
    /// journaled alarm is restored. `None` if a time does not parse.
    pub fn to_alarm(&self) -> Option<Alarm> {
        let ms = |t: &str| {
            humantime::parse_rfc3339_weak(t)
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map(|d| d.as_millis() as u64)
        };
        let cleared_at = match &self.cleared_at {
            Some(t) => Some(ms(t)?),
            None => None,
        };
        Some(Alarm {
            id: self.id.clone(),
            kind: self.kind,
            severity: self.severity,
            fault_type: self.fault_type.clone(),
            active: matches!(
                self.state,
                AlarmState::ActiveUnacknowledged | AlarmState::ActiveAcknowledged
            ),
            acknowledged: matches!(
                self.state,
                AlarmState::ActiveAcknowledged | AlarmState::Normal
            ),
            latched: self.latched,
            raised_at: ms(&self.raised_at)?,
            cleared_at,
            acked_by: self.acked_by.clone(),
            ack_comment: self.ack_comment.clone(),
            fault_step: self.fault_step,
            culprits: self
                .culprits
                .iter()
                .map(|c| Culprit {
                    address: cellwatch_models::signal::Signal::new(&c.address),
                    value: c.value,
                    expected: c.expected,
                    comment: c.comment.clone(),
                    trigger: c.trigger,
                    compared: c.compared.as_deref().and_then(compared),
                })
                .collect(),
            message: self.message.clone(),
            shelved: match &self.shelved {
                Some(s) => Some(Box::new(Shelf {
                    by: s.by.clone(),
                    reason: s.reason.clone(),
                    at: ms(&s.at)?,
                    until: match &s.until {
                        Some(t) => Some(ms(t)?),
                        None => None,
                    },
                })),
                None => None,
            },
            out_of_service: match &self.out_of_service {
                Some(r) => Some(Box::new(Removal {
                    by: r.by.clone(),
                    reason: r.reason.clone(),
                    at: ms(&r.at)?,
                })),
                None => None,
            },
            consequence: self.consequence.as_ref().map(|c| {
                Box::new(Consequence {
                    cause: c.cause.clone(),
                    first_out: c.first_out.clone(),
                    suppressed: c.suppressed,
                    through: c
                        .through
                        .iter()
                        .map(|t| (cellwatch_models::signal::Signal::new(&t.signal), t.value))
                        .collect(),
                })
            }),
            guidance: self.guidance.as_ref().map(|g| {
                std::sync::Arc::new(cellwatch_models::madb::Guidance {
                    class: g.class.clone(),
                    consequence_of_inaction: g.consequence_of_inaction.clone(),
                    corrective_action: g.corrective_action.clone(),
                    response_time_ms: g
                        .response_time
                        .as_deref()
                        .and_then(|t| humantime::parse_duration(t).ok())
                        .map(|d| d.as_millis() as u64),
                })
            }),
            designed: match &self.suppressed_by_design {
                Some(d) => Some(Box::new(DesignedSuppression {
                    mode: d.mode.clone(),
                    since: ms(&d.since)?,
                })),
                None => None,
            },
        })
    }
}

/// Who took an alarm out of service, in its payload.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RemovalPayload {
    /// The operator.
    pub by: String,
    /// Why.
    pub reason: String,
    /// Since when (RFC 3339).
    pub at: String,
}

/// An alarm's shelf in its payload.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShelfPayload {
    /// The operator who shelved it.
    pub by: String,
    /// Why.
    pub reason: String,
    /// When (RFC 3339).
    pub at: String,
    /// Until when (RFC 3339); `null`: one-shot, until the alarm clears.
    pub until: Option<String>,
}

/// `<prefix>/state`: the machine state.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StatePayload {
    /// [`STATE_SCHEMA`].
    pub schema: String,
    /// Cell id.
    pub cell: String,
    /// `running`, `idle`, `fault`, `offline`.
    pub state: StateName,
    /// History row kind of the last change: `normal`, `fault`, `recovery`, `offline`.
    pub kind: HistoryKind,
    /// Fault type, in `fault`.
    pub fault_type: Option<String>,
    /// Faulty element, in `fault` when known.
    pub element: Option<String>,
    /// Since when (RFC 3339).
    pub since: String,
    /// When this message was sent.
    pub at: String,
    /// The item (mould, product) code being made, when the cell has one
    /// (`production.item`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub item: Option<String>,
    /// The target quantity, when the cell has one (`production.target`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<u64>,
    /// The end of the journal's command chain when this was put (set by
    /// the Zenoh sink; boxed: most copies of the state never carry it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command_chain: Option<Box<CommandChain>>,
}

/// The end of the journal's command-row hash chain, as committed: signed
/// on the bus, so that rows cut off the journal's end are found
/// (`cellwatch audit verify --against-bus`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CommandChain {
    /// The last chained row's position (0: none yet).
    pub position: i64,
    /// Its sequence number in the journal.
    pub seq: i64,
    /// Its hash (hex SHA-256; 64 zeros before the first row).
    pub hash: String,
}

impl StatePayload {
    /// The payload for `state`, entered at `since` by a change of `kind`,
    /// while making `order`.
    pub fn new(
        cell: &str,
        state: &MachineState,
        kind: HistoryKind,
        (since, at): (u64, u64),
        order: &Order,
    ) -> Self {
        let (fault_type, element) = match state {
            MachineState::Fault {
                fault_type,
                element,
            } => (Some(fault_type.clone()), element.clone()),
            _ => (None, None),
        };
        StatePayload {
            schema: STATE_SCHEMA.into(),
            cell: cell.into(),
            state: state.state_name(),
            kind,
            fault_type,
            element,
            since: rfc3339(since),
            at: rfc3339(at),
            item: order.item.clone(),
            target: order.target,
            command_chain: None,
        }
    }
}

/// Schema name of snapshots.
pub const SNAPSHOT_SCHEMA: &str = "cellwatch.snapshot.v1";

/// Schema name of flight recordings.
pub const RECORDING_SCHEMA: &str = "cellwatch.recording.v1";

/// `<prefix>/recordings/<alarm-id>`: an alarm's flight recording, the
/// signals its check reads from `recorder.before` before its raise to
/// `recorder.after` after it ([`Recording`]'s fields beside these).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingPayload {
    /// [`RECORDING_SCHEMA`].
    pub schema: String,
    /// Cell id.
    pub cell: String,
    /// The recording.
    #[serde(flatten)]
    pub recording: cellwatch_models::engine::Recording,
}

impl RecordingPayload {
    /// The payload of `recording`, as JSON (journaled and published byte
    /// for byte).
    pub fn json(cell: &str, recording: &cellwatch_models::engine::Recording) -> String {
        #[derive(Serialize)]
        struct Out<'a> {
            schema: &'static str,
            cell: &'a str,
            #[serde(flatten)]
            recording: &'a cellwatch_models::engine::Recording,
        }
        serde_json::to_string(&Out {
            schema: RECORDING_SCHEMA,
            cell,
            recording,
        })
        .unwrap_or_default()
    }
}

/// Quality of a tag's value in a snapshot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    /// A good value.
    Good,
    /// The server says the value is bad or uncertain.
    Bad,
    /// No value (not yet received, or the connection is down).
    Unknown,
}

/// A tag's value in a snapshot.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TagValue {
    /// Plant name.
    pub name: String,
    /// PLC address.
    pub address: String,
    /// The value, if known: `true`/`false` for contacts, a number, or a
    /// string.
    pub value: Option<serde_json::Value>,
    /// Its quality.
    pub quality: Quality,
}

/// The values at the last fault.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LastFault {
    /// The alarm raised.
    pub alarm: String,
    /// When (RFC 3339).
    pub at: String,
    /// Every tag's value then.
    pub values: Vec<TagValue>,
}

/// `<prefix>/snapshot`: the cell as the engine sees it now.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SnapshotPayload {
    /// [`SNAPSHOT_SCHEMA`].
    pub schema: String,
    /// Cell id.
    pub cell: String,
    /// When (RFC 3339).
    pub at: String,
    /// Whether the PLC connection is up.
    pub connected: bool,
    /// The machine state.
    pub state: StateName,
    /// Every tag with its value and quality.
    pub tags: Vec<TagValue>,
    /// Alarms active or not yet acknowledged.
    pub alarms: Vec<AlarmPayload>,
    /// The values at the last fault.
    pub last_fault: Option<LastFault>,
    /// The cell's supervised charts (paper 004), as a console draws them;
    /// their steps' flags and conditions' operands are among `tags`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub charts: Vec<ChartPayload>,
    /// The cell's timed transitions (paper 001): each window and the last
    /// measurements.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub timers: Vec<TimerPayload>,
    /// The current shift's OEE (or the last one's, between shifts), when
    /// the cell has `[oee]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub oee: Option<OeePayload>,
}

/// A timed transition in the snapshot.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TimerPayload {
    /// Its alarm id (`line-007`).
    pub alarm: String,
    /// What it measures (`+WR2B_DONE after +WR2A_START`).
    pub label: String,
    /// Its window, ms: earlier is early, later is late.
    pub window_ms: [u64; 2],
    /// The learned duration, ms.
    pub delta_ms: u64,
    /// Its last measured durations, oldest first (at most 10).
    pub recent: Vec<MeasurementPayload>,
}

/// One measured duration of a timed transition.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MeasurementPayload {
    /// When it ended (RFC 3339).
    pub at: String,
    /// How long, ms.
    pub ms: u64,
}

/// A supervised chart in the snapshot: its steps and transitions, each
/// transition's condition and the contacts it reads.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChartPayload {
    /// The `[[checks.sfc]]` id.
    pub check: String,
    /// The chart's name (`F1`).
    pub name: String,
    /// Its initial step.
    pub initial: Option<String>,
    /// Its steps, in the chart's order.
    pub steps: Vec<StepPayload>,
    /// Its transitions.
    pub transitions: Vec<TransitionPayload>,
}

/// A step of a chart.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StepPayload {
    /// Its name (`S2`).
    pub name: String,
    /// The tag address true while it is active.
    pub flag: String,
    /// What it does.
    pub comment: Option<String>,
    /// Its supervision time, ms.
    pub supervision_ms: Option<u64>,
    /// Whether it is active now; `null` while its flag is unknown.
    pub active: Option<bool>,
    /// The id of its stuck alarm.
    pub alarm: String,
}

/// A transition of a chart.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TransitionPayload {
    /// Its id in its chart (`t3`).
    pub id: String,
    /// The steps it leaves, `CHART.STEP`.
    pub from: Vec<String>,
    /// The steps it activates, `CHART.STEP` (another chart's: a jump).
    pub to: Vec<String>,
    /// Its condition (`+` or, `*` and, `-` not).
    pub condition: String,
    /// The contacts the condition reads.
    pub operands: Vec<OperandPayload>,
    /// Whether the condition holds now; `null` while an operand is unknown.
    pub holds: Option<bool>,
    /// What it waits for.
    pub comment: Option<String>,
    /// Whether an operator may force it (declared forcible).
    pub forcible: bool,
}

/// A contact a transition's condition reads.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct OperandPayload {
    /// Its tag address.
    pub address: String,
    /// Its comment (the I/O list's).
    pub comment: Option<String>,
    /// Its value now; `null` while unknown.
    pub value: Option<bool>,
}

impl ChartPayload {
    /// Every chart of a `[[checks.sfc]]` with id `check`, its forcible
    /// transitions, its contacts' comments, and each contact's value now.
    pub fn of(
        check: &str,
        sfc: &cellwatch_models::sfc::Sfc,
        forcible: &[(String, String)],
        comments: &cellwatch_models::comments::CommentDb,
        value: &dyn Fn(&cellwatch_models::signal::Signal) -> Option<bool>,
    ) -> Vec<ChartPayload> {
        use cellwatch_models::sfc::StepRef;
        let holds = |e: &cellwatch_models::expr::Expr| {
            let known = e.signals().iter().all(|s| value(s).is_some());
            known.then(|| e.eval(&|s| value(s).unwrap_or(false)))
        };
        let name = |r: &StepRef| format!("{}.{}", sfc.charts[r.chart].name, sfc.step(*r).name);
        sfc.charts
            .iter()
            .enumerate()
            .map(|(ci, c)| ChartPayload {
                check: check.into(),
                name: c.name.clone(),
                initial: c.initial.map(|i| c.steps[i].name.clone()),
                steps: c
                    .steps
                    .iter()
                    .enumerate()
                    .map(|(si, st)| StepPayload {
                        name: st.name.clone(),
                        flag: st.flag.to_string(),
                        comment: st.comment.clone(),
                        supervision_ms: st.supervision_ms,
                        active: value(&st.flag),
                        alarm: cellwatch_models::sfc::supervise::alarm_id(
                            check,
                            sfc,
                            StepRef {
                                chart: ci,
                                step: si,
                            },
                        ),
                    })
                    .collect(),
                transitions: c
                    .transitions
                    .iter()
                    .map(|t| TransitionPayload {
                        id: t.id.clone(),
                        from: t.from.iter().map(name).collect(),
                        to: t.to.iter().map(name).collect(),
                        condition: t.condition.to_string(),
                        operands: t
                            .condition
                            .signals()
                            .iter()
                            .map(|s| OperandPayload {
                                address: s.to_string(),
                                comment: comments.get(s).map(str::to_string),
                                value: value(s),
                            })
                            .collect(),
                        holds: holds(&t.condition),
                        comment: t.comment.clone(),
                        forcible: forcible.iter().any(|(fc, ft)| *fc == c.name && *ft == t.id),
                    })
                    .collect(),
            })
            .collect()
    }
}

/// A comparison culprit's `compared` text read back
/// (`rSpindleSpeed = 1650.0 (needs >= 1800)`), as a restored alarm shows
/// it again.
fn compared(text: &str) -> Option<cellwatch_models::explain::Compared> {
    let (variable, rest) = text.split_once(" = ")?;
    let (value, needs) = rest.strip_suffix(')')?.rsplit_once(" (needs ")?;
    Some(cellwatch_models::explain::Compared {
        variable: cellwatch_models::signal::Signal::new(variable),
        value: value.to_string(),
        needs: needs.to_string(),
    })
}

/// A tag value as JSON: a boolean, a number (integers exact) or a string.
pub fn json_value(v: &cellwatch_models::engine::Value) -> serde_json::Value {
    use cellwatch_models::engine::Value;
    use cellwatch_models::value::Num;
    match v {
        Value::Bool(b) => (*b).into(),
        Value::Num(Num::Int(n)) => (*n).into(),
        Value::Num(Num::UInt(n)) => (*n).into(),
        Value::Num(Num::Float(n)) => serde_json::Number::from_f64(*n)
            .map_or(serde_json::Value::Null, serde_json::Value::Number),
        Value::Text(t) => t.to_string().into(),
    }
}

#[cfg(test)]
mod tests;

mod about;
mod consequence;
mod guidance;
mod oee;
mod overdue;
pub use about::{AboutPayload, CertificateAbout, ABOUT_SCHEMA};
pub use consequence::{ConsequencePayload, ThroughPayload};
pub use guidance::GuidancePayload;
pub use oee::{BreakdownPayload, LossesPayload, OeePayload};
