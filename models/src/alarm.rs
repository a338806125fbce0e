//! Alarms and their lifecycle, after ISA-18.2.
//!
//! An [`Alarm`] has a stable id (the check's id, `communication`,
//! `tag-quality`) and two independent states: *active* (the condition holds)
//! and *acknowledged* (an operator has seen it). Raising makes it active and
//! unacknowledged; clearing ends the condition but it stays unacknowledged
//! until an operator acknowledges it; a *latched* alarm stays active after
//! its condition ends, until an operator resets it. This module owns the
//! state machine; who may acknowledge is the agent's business.

use std::fmt;
use std::str::FromStr;

use crate::explain::Culprit;

/// How urgent an alarm is.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// Advisory.
    Low,
    /// Needs attention this shift.
    Medium,
    /// Stops or will stop production.
    High,
    /// Safety or machine damage.
    Critical,
}

impl Severity {
    /// All severities, lowest first.
    pub const ALL: [Severity; 4] = [
        Severity::Low,
        Severity::Medium,
        Severity::High,
        Severity::Critical,
    ];

    /// The lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Severity::Low => "low",
            Severity::Medium => "medium",
            Severity::High => "high",
            Severity::Critical => "critical",
        }
    }
}

impl fmt::Display for Severity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A severity's name that is none of `low`, `medium`, `high`, `critical`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown severity '{text}': use low, medium, high or critical")]
pub struct UnknownSeverity {
    /// The name as given.
    pub text: String,
}

impl FromStr for Severity {
    type Err = UnknownSeverity;

    fn from_str(s: &str) -> Result<Self, UnknownSeverity> {
        Severity::ALL
            .into_iter()
            .find(|v| v.as_str() == s)
            .ok_or_else(|| UnknownSeverity { text: s.into() })
    }
}

/// What raised an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlarmKind {
    /// A switching-function check: a fault coil at its fault value.
    Switching,
    /// A transition timer: an event too early or too late.
    Timer,
    /// A transition whose recent durations drift towards a limit of its
    /// window: a warning before it times out, never a fault.
    Drift,
    /// A number past one of its limits (HH, H, L, LL).
    Limit,
    /// A step of a sequential function chart active longer than its
    /// supervision time (stuck).
    Step,
    /// Tags with bad or uncertain quality.
    TagQuality,
    /// The connection to the PLC is lost.
    Communication,
    /// The agent itself is in trouble (its journal cannot write).
    System,
    /// The PLC's own alarm: a condition its OPC UA server reports (Alarms
    /// & Conditions), with the PLC's text.
    Plc,
}

impl AlarmKind {
    /// All kinds.
    pub const ALL: [AlarmKind; 9] = [
        AlarmKind::Switching,
        AlarmKind::Timer,
        AlarmKind::Drift,
        AlarmKind::Limit,
        AlarmKind::Step,
        AlarmKind::TagQuality,
        AlarmKind::Communication,
        AlarmKind::System,
        AlarmKind::Plc,
    ];

    /// The snake-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            AlarmKind::Switching => "switching",
            AlarmKind::Timer => "timer",
            AlarmKind::Drift => "drift",
            AlarmKind::Limit => "limit",
            AlarmKind::Step => "step",
            AlarmKind::TagQuality => "tag_quality",
            AlarmKind::Communication => "communication",
            AlarmKind::System => "system",
            AlarmKind::Plc => "plc",
        }
    }
}

/// The ISA-18.2 state of an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlarmState {
    /// Condition present, not yet acknowledged.
    ActiveUnacknowledged,
    /// Condition present, acknowledged.
    ActiveAcknowledged,
    /// Condition gone, not yet acknowledged.
    ClearedUnacknowledged,
    /// Condition gone and acknowledged: nothing to show.
    Normal,
}

impl AlarmState {
    /// The snake-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            AlarmState::ActiveUnacknowledged => "active_unacknowledged",
            AlarmState::ActiveAcknowledged => "active_acknowledged",
            AlarmState::ClearedUnacknowledged => "cleared_unacknowledged",
            AlarmState::Normal => "normal",
        }
    }
}

/// What just happened to an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Transition {
    /// The condition started.
    Raised,
    /// The condition ended (or a latched alarm was reset).
    Cleared,
    /// An operator acknowledged it.
    Acknowledged,
    /// The condition still holds but its details changed (more tags bad,
    /// a new culprit).
    Updated,
    /// Taken back from the journal at the agent's start, as it was when the
    /// agent stopped (not a new occurrence).
    Restored,
    /// An operator shelved it: still evaluated and journaled, not
    /// announced as active.
    Shelved,
    /// Its shelf ended (expiry, an operator, or a one-shot shelf's alarm
    /// cleared): announced again as it is.
    Unshelved,
    /// An operator took it out of service: not raised whatever its
    /// condition (an active occurrence ends with this).
    OutOfService,
    /// Back in service: raised again if its condition holds.
    InService,
    /// A machine mode that suppresses it by design began (ISA-18.2
    /// designed suppression): still evaluated and journaled, not announced.
    Suppressed,
    /// Its designed suppression ended: announced as it is (an active
    /// alarm is announced now).
    Unsuppressed,
}

impl Transition {
    /// The snake-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Transition::Raised => "raised",
            Transition::Cleared => "cleared",
            Transition::Acknowledged => "acknowledged",
            Transition::Updated => "updated",
            Transition::Restored => "restored",
            Transition::Shelved => "shelved",
            Transition::Unshelved => "unshelved",
            Transition::OutOfService => "out_of_service",
            Transition::InService => "in_service",
            Transition::Suppressed => "suppressed",
            Transition::Unsuppressed => "unsuppressed",
        }
    }
}

impl fmt::Display for Transition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl fmt::Display for AlarmKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl fmt::Display for AlarmState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One alarm: its identity, state and the diagnosis that goes with it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Alarm {
    /// Stable id: the check's id, `communication` or `tag-quality`.
    pub id: String,
    /// What raised it.
    pub kind: AlarmKind,
    /// How urgent.
    pub severity: Severity,
    /// The fault type for machine-state history (`ESE`, `CSD`, ...).
    pub fault_type: String,
    /// The condition holds (or the alarm is latched).
    pub active: bool,
    /// An operator has acknowledged the current occurrence.
    pub acknowledged: bool,
    /// Stays active until reset.
    pub latched: bool,
    /// When the current occurrence was raised, ms since the Unix epoch.
    pub raised_at: u64,
    /// When it cleared, if it has.
    pub cleared_at: Option<u64>,
    /// Who acknowledged it.
    pub acked_by: Option<String>,
    /// What they said acknowledging it (their comment), if anything.
    pub ack_comment: Option<String>,
    /// The step block at which the fault formed.
    pub fault_step: Option<usize>,
    /// The contacts that caused it, triggers first.
    pub culprits: Vec<Culprit>,
    /// A one-line description (which tags are bad, why the link dropped).
    pub message: String,
    /// Shelved by an operator (ISA-18.2 / OPC UA Part 9), if it is.
    /// (Boxed, as `out_of_service`: rare, and alarms travel in events.)
    pub shelved: Option<Box<Shelf>>,
    /// Out of service (ISA-18.2: removed from service, e.g. a broken
    /// instrument), if it is.
    pub out_of_service: Option<Box<Removal>>,
    /// The active alarm this occurrence follows from, if it was raised as
    /// a consequence of one ([`crate::consequence`]); `None`: a first-out.
    pub consequence: Option<Box<Consequence>>,
    /// Suppressed by design: a machine mode in which it means nothing
    /// holds (ISA-18.2), if one does. Evaluated and journaled, never
    /// announced; distinct from a shelf (an operator's) and out of service.
    pub designed: Option<Box<DesignedSuppression>>,
    /// Its rationalisation from the cell's master alarm database (class,
    /// consequence of inaction, corrective action, response time), if it
    /// has one.
    pub guidance: Option<std::sync::Arc<Guidance>>,
}

/// Which machine mode suppresses an alarm by design, since when.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DesignedSuppression {
    /// The mode's id (`setup`).
    pub mode: String,
    /// When the suppression began for this alarm, ms since the epoch.
    pub since: u64,
}

/// What the operator is told of an alarm: its rationalisation, from the
/// cell's master alarm database ([`crate::madb`]).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Guidance {
    /// Its class (`fault`, `safety`, `quality`, …, as the plant names them).
    pub class: String,
    /// What happens if nobody acts.
    pub consequence_of_inaction: String,
    /// What the operator does.
    pub corrective_action: String,
    /// How long the operator has, ms; `None`: not said.
    pub response_time_ms: Option<u64>,
}

/// An alarm id, or a pattern where `*` stands for any run of characters
/// (`door-*`, `*-guard`, `*`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlarmPattern(String);

impl AlarmPattern {
    /// The pattern `text`.
    pub fn new(text: &str) -> AlarmPattern {
        AlarmPattern(text.to_string())
    }

    /// The pattern as written.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Whether alarm id `id` matches.
    pub fn matches(&self, id: &str) -> bool {
        let mut parts = self.0.split('*');
        let first = parts.next().unwrap_or("");
        let Some(mut rest) = id.strip_prefix(first) else {
            return false;
        };
        let parts: Vec<&str> = parts.collect();
        let Some((last, middle)) = parts.split_last() else {
            // No `*`: the whole id.
            return rest.is_empty();
        };
        for part in middle {
            match rest.find(part) {
                Some(at) => rest = &rest[at + part.len()..],
                None => return false,
            }
        }
        rest.len() >= last.len() && rest.ends_with(last)
    }
}

impl fmt::Display for AlarmPattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Why an occurrence is a consequence: the alarm it follows from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Consequence {
    /// The active alarm whose fault explains this one's culprits
    /// (`ese`).
    pub cause: String,
    /// The first-out of the cascade: the cause's own first-out, or the
    /// cause.
    pub first_out: String,
    /// Not annunciated (the cell suppresses consequences): journaled and
    /// shown as suppressed, never lost.
    pub suppressed: bool,
    /// The signals through which it follows: each one the cause's fault
    /// holds and this alarm's check reads, with its value now (without
    /// the cause's fault it would have the other). Empty when an edge
    /// written in the configuration or the culprits decided.
    pub through: Vec<(crate::signal::Signal, bool)>,
}

/// Who took an alarm out of service, when and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Removal {
    /// Who.
    pub by: String,
    /// Why.
    pub reason: String,
    /// When, ms since the epoch.
    pub at: u64,
}

/// An operator's shelf on an alarm.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Shelf {
    /// Who shelved it.
    pub by: String,
    /// Why.
    pub reason: String,
    /// When, ms since the epoch.
    pub at: u64,
    /// Until when (ms); `None`: one-shot, until the alarm clears.
    pub until: Option<u64>,
}

impl Alarm {
    /// An active, unacknowledged alarm raised at `raised_at`, as the
    /// journal gives it back after a restart (tests).
    #[cfg(test)]
    pub(crate) fn active_since(id: &str, kind: AlarmKind, raised_at: u64) -> Alarm {
        Alarm {
            id: id.into(),
            kind,
            severity: Severity::High,
            fault_type: id.to_uppercase(),
            active: true,
            acknowledged: false,
            latched: false,
            raised_at,
            cleared_at: None,
            acked_by: None,
            ack_comment: None,
            fault_step: None,
            culprits: Vec::new(),
            message: id.into(),
            shelved: None,
            out_of_service: None,
            consequence: None,
            designed: None,
            guidance: None,
        }
    }

    /// The ISA-18.2 state.
    pub fn state(&self) -> AlarmState {
        match (self.active, self.acknowledged) {
            (true, false) => AlarmState::ActiveUnacknowledged,
            (true, true) => AlarmState::ActiveAcknowledged,
            (false, false) => AlarmState::ClearedUnacknowledged,
            (false, true) => AlarmState::Normal,
        }
    }

    /// Whether it is a consequence the cell does not annunciate.
    pub fn is_suppressed(&self) -> bool {
        self.consequence.as_ref().is_some_and(|c| c.suppressed)
    }

    /// Whether a machine mode suppresses it by design now.
    pub fn is_suppressed_by_design(&self) -> bool {
        self.designed.is_some()
    }

    /// Whether it is announced when active: neither shelved, out of
    /// service, a suppressed consequence nor suppressed by design.
    pub fn is_announced(&self) -> bool {
        self.shelved.is_none()
            && self.out_of_service.is_none()
            && !self.is_suppressed()
            && self.designed.is_none()
    }

    /// The element to name in machine-state history: the first culprit.
    pub fn element(&self) -> Option<&str> {
        self.culprits.first().map(|c| c.address.name())
    }
}

/// Why an operator command was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CommandRefused {
    /// No alarm with that id.
    #[error("no alarm '{0}'")]
    UnknownAlarm(String),
    /// Reset of an alarm that is not latched, or whose condition still holds.
    #[error("alarm '{id}' cannot be reset: {why}")]
    CannotReset {
        /// The alarm.
        id: String,
        /// Why.
        why: String,
    },
    /// Acknowledging an alarm with nothing to acknowledge.
    #[error("alarm '{0}' has nothing to acknowledge")]
    NothingToAcknowledge(String),
    /// Out of service refused (already out, or not out when put back).
    #[error("alarm '{id}' {why}")]
    Service {
        /// The alarm.
        id: String,
        /// Why.
        why: &'static str,
    },
    /// Shelving refused, or unshelving an alarm that is not shelved.
    #[error("alarm '{id}' cannot be {what}: {why}")]
    Shelving {
        /// The alarm.
        id: String,
        /// `shelved` or `unshelved`.
        what: &'static str,
        /// Why.
        why: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pattern_matches_ids_with_any_run_of_characters_for_a_star() {
        let cases = [
            ("door-*", "door-left", true),
            ("door-*", "door-", true),
            ("door-*", "doors", false),
            ("*-guard", "left-guard", true),
            ("*-guard", "left-guard2", false),
            ("a*b*c", "a-x-b-y-c", true),
            ("a*b*c", "a-c", false),
            ("ab*ba", "aba", false),
            ("*", "anything", true),
            ("ese", "ese", true),
            ("ese", "ese2", false),
        ];
        for (pattern, id, matches) in cases {
            assert_eq!(
                AlarmPattern::new(pattern).matches(id),
                matches,
                "{pattern} {id}"
            );
        }
    }
}
