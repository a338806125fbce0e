//! The event a condition sends on each transition (and on a
//! `ConditionRefresh`): the fields of `AlarmConditionType` and the cell's
//! own `Culprits` and `Consequence`, answered to any select clause the server accepted.
//! Holds no state: `conditions.rs` fills it in.

use opcua::nodes::{BaseEventType, Event, EventField};
use opcua::types::{
    AttributeId, DateTime, LocalizedText, NodeId, NumericRange, QualifiedName, StatusCode,
    UAString, Variant,
};

/// A `TwoStateVariableType` as an event field: `AckedState` is the text,
/// `AckedState/Id` the boolean. (The generated type keeps its value where
/// the derive never looks for an empty path.)
#[derive(Debug, Default, EventField)]
pub(super) struct TwoState {
    pub(super) value: LocalizedText,
    pub(super) id: bool,
    pub(super) transition_time: DateTime,
    pub(super) true_state: LocalizedText,
    pub(super) false_state: LocalizedText,
}

impl TwoState {
    /// The state `id`, named `yes` or `no`, entered at `at`.
    pub(super) fn new(id: bool, yes: &str, no: &str, at: DateTime) -> TwoState {
        TwoState {
            value: if id { yes } else { no }.into(),
            id,
            transition_time: at,
            true_state: yes.into(),
            false_state: no.into(),
        }
    }
}

/// `Comment` (a `ConditionVariableType` with its value typed).
#[derive(Debug, Default, EventField)]
pub(super) struct CommentVar {
    pub(super) value: LocalizedText,
    pub(super) source_timestamp: DateTime,
}

/// `LastSeverity`.
#[derive(Debug, Default, EventField)]
pub(super) struct SeverityVar {
    pub(super) value: u16,
    pub(super) source_timestamp: DateTime,
}

/// `Quality`.
#[derive(Debug, Default, EventField)]
pub(super) struct QualityVar {
    pub(super) value: StatusCode,
    pub(super) source_timestamp: DateTime,
}

/// `ShelvingState/CurrentState` (a `FiniteStateVariableType`): the
/// state's name, `Id` its node.
#[derive(Debug, Default, EventField)]
pub(super) struct CurrentStateVar {
    pub(super) value: LocalizedText,
    pub(super) id: NodeId,
}

/// `ShelvingState`: its state, and the milliseconds until a timed shelf
/// ends.
#[derive(Debug, Default, EventField)]
pub(super) struct ShelvingVar {
    pub(super) current_state: CurrentStateVar,
    pub(super) unshelve_time: f64,
}

/// Every field of a cell alarm's event; each answers to its PascalCase
/// browse name, `base` to `BaseEventType`'s (EventId, Message, Severity…).
#[derive(Debug, EventField)]
pub(super) struct AlarmFields {
    pub(super) base: BaseEventType,
    pub(super) condition_name: UAString,
    pub(super) branch_id: NodeId,
    pub(super) retain: bool,
    pub(super) client_user_id: UAString,
    pub(super) comment: CommentVar,
    pub(super) last_severity: SeverityVar,
    pub(super) quality: QualityVar,
    pub(super) enabled_state: TwoState,
    pub(super) active_state: TwoState,
    pub(super) acked_state: TwoState,
    pub(super) confirmed_state: TwoState,
    pub(super) suppressed_or_shelved: bool,
    pub(super) shelving_state: ShelvingVar,
    /// `CellAlarmType`'s own: the alarm's culprits as one text.
    pub(super) culprits: UAString,
    /// `CellAlarmType`'s own: why the occurrence is a consequence (the
    /// cause, the signal it follows through, the first-out); empty for a
    /// first-out.
    pub(super) consequence: UAString,
    /// `CellAlarmType`'s own, from the master alarm database: what the
    /// operator does.
    pub(super) corrective_action: UAString,
    /// What happens if nobody acts.
    pub(super) consequence_of_inaction: UAString,
    /// The alarm's class, as the plant names them.
    pub(super) alarm_class: UAString,
    /// How long the operator has, ms (0: not said).
    pub(super) response_time: f64,
    /// Unacknowledged past its response time.
    pub(super) overdue: bool,
}

/// One condition's event. `Event` is written by hand so that a select
/// clause of any condition type is answered, and the `ConditionId` clause
/// (`ConditionType`, empty path, attribute `NodeId`) gives the condition.
#[derive(Debug)]
pub(super) struct CellAlarmEvent {
    pub(super) fields: AlarmFields,
    pub(super) condition_id: NodeId,
}

impl EventField for CellAlarmEvent {
    fn get_value(
        &self,
        attribute_id: AttributeId,
        index_range: &NumericRange,
        remaining_path: &[QualifiedName],
    ) -> Variant {
        self.fields
            .get_value(attribute_id, index_range, remaining_path)
    }
}

impl Event for CellAlarmEvent {
    fn get_field(
        &self,
        _type_definition_id: &NodeId,
        attribute_id: AttributeId,
        index_range: &NumericRange,
        browse_path: &[QualifiedName],
    ) -> Variant {
        // The select clause was checked against the type tree already.
        if browse_path.is_empty() {
            return if attribute_id == AttributeId::NodeId {
                self.condition_id.clone().into()
            } else {
                Variant::Empty
            };
        }
        self.fields
            .get_value(attribute_id, index_range, browse_path)
    }

    fn time(&self) -> &DateTime {
        &self.fields.base.time
    }

    fn event_type_id(&self) -> &NodeId {
        &self.fields.base.event_type
    }
}
