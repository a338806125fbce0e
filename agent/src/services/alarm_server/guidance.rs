//! What the master alarm database tells the operator, as `CellAlarmType`'s
//! own properties (`CorrectiveAction`, `ConsequenceOfInaction`,
//! `AlarmClass`, `ResponseTime`) and whether the occurrence is `Overdue`:
//! unacknowledged past its response time (ISA-18.2). A condition turning
//! overdue sends an event of its own: [`Overdue`] says when the next one
//! falls due.

use opcua::types::{DataTypeId, Variant};
use tokio::sync::Notify;

use crate::payload::AlarmPayload;

/// The properties `CellAlarmType` adds for its guidance: browse name and
/// data type.
pub(super) const PROPERTIES: [(&str, DataTypeId); 5] = [
    ("CorrectiveAction", DataTypeId::String),
    ("ConsequenceOfInaction", DataTypeId::String),
    ("AlarmClass", DataTypeId::String),
    ("ResponseTime", DataTypeId::Duration),
    ("Overdue", DataTypeId::Boolean),
];

/// A condition's guidance and lateness, from its latest payload.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Guidance {
    pub(super) corrective_action: String,
    pub(super) consequence_of_inaction: String,
    pub(super) class: String,
    /// ms; 0 when not said.
    pub(super) response_time: f64,
    /// When it is overdue (ms since the epoch), while it can be.
    pub(super) overdue_from: Option<u64>,
    /// Overdue now (as last sent).
    pub(super) overdue: bool,
}

impl Guidance {
    /// From payload `p`, at `now` (ms since the epoch).
    pub(super) fn of(p: &AlarmPayload, now: u64) -> Guidance {
        let overdue_from = p.overdue_from();
        let Some(g) = &p.guidance else {
            return Guidance::default();
        };
        Guidance {
            corrective_action: g.corrective_action.clone(),
            consequence_of_inaction: g.consequence_of_inaction.clone(),
            class: g.class.clone(),
            response_time: g.response_time_ms().map_or(0.0, |ms| ms as f64),
            overdue_from,
            overdue: overdue_from.is_some_and(|from| now >= from),
        }
    }

    /// Becomes overdue at `now`: whether it just did.
    pub(super) fn falls_due(&mut self, now: u64) -> bool {
        let due = !self.overdue && self.overdue_from.is_some_and(|from| now >= from);
        self.overdue |= due;
        due
    }

    /// When it falls due, if it is not overdue yet.
    pub(super) fn due_at(&self) -> Option<u64> {
        self.overdue_from.filter(|_| !self.overdue)
    }

    /// The value of property `name` (of [`PROPERTIES`]).
    pub(super) fn value(&self, name: &str) -> Variant {
        match name {
            "CorrectiveAction" => self.corrective_action.as_str().into(),
            "ConsequenceOfInaction" => self.consequence_of_inaction.as_str().into(),
            "AlarmClass" => self.class.as_str().into(),
            "ResponseTime" => self.response_time.into(),
            "Overdue" => self.overdue.into(),
            _ => Variant::Empty,
        }
    }
}

/// Wakes the task that marks conditions overdue when a condition's
/// deadline may have changed.
#[derive(Debug, Default)]
pub(super) struct Overdue {
    pub(super) changed: Notify,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_condition_falls_due_once_at_its_response_time_and_never_once_acknowledged() {
        let mut p: AlarmPayload = serde_json::from_value(serde_json::json!({
            "schema": "cellwatch.alarm.v1", "cell": "m01", "id": "ese",
            "kind": "switching", "severity": "critical", "state": "active_unacknowledged",
            "transition": "raised", "at": "2026-11-28T10:00:00.000Z",
            "raised_at": "2026-11-28T10:00:00.000Z", "cleared_at": null, "acked_by": null,
            "fault_type": "ESE", "fault_step": 6, "culprits": [], "message": "ESE",
            "guidance": {"class": "safety", "consequence_of_inaction": "scrap",
                         "corrective_action": "Release the emergency stop",
                         "response_time": "5m"}
        }))
        .unwrap();
        let raised = crate::clock::parse_time("2026-11-28T10:00:00.000Z", 0).unwrap();
        let mut g = Guidance::of(&p, raised);
        assert_eq!(g.value("ResponseTime"), Variant::from(300_000.0));
        assert_eq!(g.value("AlarmClass"), Variant::from("safety"));
        assert_eq!(g.due_at(), Some(raised + 300_000));
        assert!(!g.falls_due(raised + 299_999));
        assert!(g.falls_due(raised + 300_000));
        assert!(!g.falls_due(raised + 300_001), "once");
        assert_eq!(g.value("Overdue"), Variant::from(true));
        assert_eq!(g.due_at(), None);
        p.state = cellwatch_models::alarm::AlarmState::ActiveAcknowledged;
        let acked = Guidance::of(&p, raised + 400_000);
        assert_eq!((acked.overdue, acked.due_at()), (false, None));
    }
}
