//! The cell's alarms as conditions: one `CellAlarmType` object per alarm
//! id, kept from the alarm payloads the sink hands over (`apply`), each
//! change sent as an event from the cell's notifier (and so from the
//! `Server` object). The conditions' nodes are made on an alarm's first
//! transition, with their state as variables a client may read or
//! subscribe to ([`STATE_VARIABLES`]). Acknowledging and refreshing are
//! `methods.rs`'s.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use cellwatch_models::alarm::{AlarmState, Severity};
use opcua::nodes::{BaseEventType, Event};
use opcua::server::address_space::{AddressSpace, ObjectBuilder, VariableBuilder};
use opcua::server::node_manager::memory::SimpleNodeManager;
use opcua::server::SubscriptionCache;
use opcua::sync::{Mutex, RwLock};
use opcua::types::{
    ByteString, DataTypeId, DataValue, DateTime, LocalizedText, MethodId, NodeId, ObjectId,
    ObjectTypeId, ReferenceTypeId, StatusCode, VariableTypeId, Variant,
};

use super::events::{
    AlarmFields, CellAlarmEvent, CommentVar, CurrentStateVar, QualityVar, SeverityVar, ShelvingVar,
    TwoState,
};
use super::guidance::{self, Guidance, Overdue};
use crate::payload::{AlarmPayload, ConsequencePayload, CulpritPayload};

/// A state variable: its name, data type and initial value.
pub(super) type StateVariable = (&'static str, DataTypeId, fn() -> Variant);

/// The state variables of each condition, readable and subscribable:
/// name (the node id's last part after the alarm's, `m01.ese.ActiveState.Id`),
/// data type, initial value. `…State` are `TwoStateVariableType` components
/// with their `Id` property (`ShelvingState`'s `CurrentState` a
/// `FiniteStateVariableType`); the others properties of what they follow.
pub(super) const STATE_VARIABLES: [StateVariable; 15] = [
    ("EnabledState", DataTypeId::LocalizedText, || {
        LocalizedText::from("Enabled").into()
    }),
    ("EnabledState.Id", DataTypeId::Boolean, || true.into()),
    ("ActiveState", DataTypeId::LocalizedText, || {
        LocalizedText::from("Inactive").into()
    }),
    ("ActiveState.Id", DataTypeId::Boolean, || false.into()),
    ("AckedState", DataTypeId::LocalizedText, || {
        LocalizedText::from("Acknowledged").into()
    }),
    ("AckedState.Id", DataTypeId::Boolean, || true.into()),
    ("Retain", DataTypeId::Boolean, || false.into()),
    ("Message", DataTypeId::LocalizedText, || {
        LocalizedText::null().into()
    }),
    ("Severity", DataTypeId::UInt16, || 0u16.into()),
    ("ClientUserId", DataTypeId::String, || "".into()),
    ("Culprits", DataTypeId::String, || "".into()),
    ("Consequence", DataTypeId::String, || "".into()),
    (
        "ShelvingState.CurrentState",
        DataTypeId::LocalizedText,
        || LocalizedText::from("Unshelved").into(),
    ),
    ("ShelvingState.CurrentState.Id", DataTypeId::NodeId, || {
        NodeId::from(ObjectId::ShelvedStateMachineType_Unshelved).into()
    }),
    ("ShelvingState.UnshelveTime", DataTypeId::Duration, || {
        0.0f64.into()
    }),
];

/// What the conditions need of the built server: set once, before it runs.
pub(super) struct Served {
    /// The server's namespace for the cell's nodes.
    pub(super) ns: u16,
    /// The cell's object: every condition's event comes from it.
    pub(super) notifier: NodeId,
    /// `CellAlarmType`.
    pub(super) event_type: NodeId,
    /// Where events are delivered to the subscriptions' monitored items.
    pub(super) subscriptions: Arc<SubscriptionCache>,
    /// The cell's namespace, where the conditions' nodes are added.
    pub(super) nodes: Arc<SimpleNodeManager>,
    /// Namespace 0's address space: each condition needs its
    /// `HasComponent` to `Acknowledge`, `Enable` and `Disable` there for
    /// calls to reach them.
    pub(super) core: Arc<RwLock<AddressSpace>>,
}

/// One alarm as its condition.
#[derive(Debug, Clone)]
pub(super) struct Condition {
    /// The condition's node.
    pub(super) node: NodeId,
    pub(super) message: String,
    pub(super) severity: u16,
    pub(super) culprits: String,
    /// Why it is a consequence, if it is ([`consequence_text`]).
    pub(super) consequence: String,
    pub(super) active: bool,
    pub(super) acked: bool,
    /// In service (ISA-18.2): not disabled.
    pub(super) enabled: bool,
    pub(super) active_at: DateTime,
    pub(super) acked_at: DateTime,
    pub(super) enabled_at: DateTime,
    /// The operator who acknowledged it.
    pub(super) acked_by: String,
    /// The comment of the occurrence's acknowledgement, if any.
    pub(super) comment: String,
    /// Shelved, out of service, or suppressed as a consequence.
    pub(super) suppressed_or_shelved: bool,
    /// Shelved: until when (`None`: one-shot, until the alarm clears).
    pub(super) shelved: Option<Option<DateTime>>,
    /// Its `ShelvingState` object, where the shelving methods are called.
    pub(super) shelving_node: NodeId,
    /// The event last sent: an `Acknowledge` must name it.
    pub(super) event_id: ByteString,
    pub(super) time: DateTime,
    /// What the master alarm database tells the operator, and lateness.
    pub(super) guidance: Guidance,
    /// The event before `event_id` when that one only said the condition
    /// became overdue: the same state, so acknowledging either is one.
    pub(super) before_overdue: Option<ByteString>,
}

impl Condition {
    /// Whether `event_id` names this condition's state as it stands.
    pub(super) fn names(&self, event_id: &ByteString) -> bool {
        self.event_id == *event_id || self.before_overdue.as_ref() == Some(event_id)
    }
}

impl Condition {
    /// Kept for clients (ConditionRefresh) while active or unacknowledged.
    pub(super) fn retain(&self) -> bool {
        self.active || !self.acked
    }
}

/// The cell's conditions, shared by the sink (changes) and the server's
/// methods (acknowledge, refresh).
pub(super) struct Conditions {
    pub(super) cell: String,
    /// Set once the server is built ([`Served`]).
    pub(super) served: OnceLock<Served>,
    /// By alarm id; held only to change or copy a condition, never while
    /// events are delivered.
    alarms: Mutex<HashMap<String, Condition>>,
    /// The last event id handed out.
    counter: AtomicU64,
    /// Wakes the task marking conditions overdue.
    pub(super) overdue: Overdue,
}

/// The shelving state machine's state of a shelf: its name and node.
pub(super) fn shelving_state(shelved: Option<Option<DateTime>>) -> (&'static str, ObjectId) {
    match shelved {
        None => ("Unshelved", ObjectId::ShelvedStateMachineType_Unshelved),
        Some(Some(_)) => (
            "TimedShelved",
            ObjectId::ShelvedStateMachineType_TimedShelved,
        ),
        Some(None) => (
            "OneShotShelved",
            ObjectId::ShelvedStateMachineType_OneShotShelved,
        ),
    }
}

/// A timed shelf's milliseconds left now (0 for none, or one-shot).
fn unshelve_in(shelved: Option<Option<DateTime>>) -> f64 {
    match shelved {
        Some(Some(until)) => (until.as_chrono() - DateTime::now().as_chrono())
            .num_milliseconds()
            .max(0) as f64,
        _ => 0.0,
    }
}

/// OPC UA's severity (1–1000) of a cellwatch severity.
pub(super) fn severity(s: Severity) -> u16 {
    match s {
        Severity::Low => 250,
        Severity::Medium => 500,
        Severity::High => 750,
        Severity::Critical => 1000,
    }
}

/// The culprits as one text, each as the CLI, the console and the
/// Alertmanager show it, joined by `; `:
/// `X0.06 = 0 (expected 1): Y Over Travel Limit SW (B)   <- trigger`.
pub(super) fn culprits_text(culprits: &[CulpritPayload]) -> String {
    culprits
        .iter()
        .map(CulpritPayload::line)
        .collect::<Vec<_>>()
        .join("; ")
}

/// Why an occurrence is a consequence, as the console and Alertmanager
/// say it, with the cascade's first-out when it is another alarm:
/// `follows from clamp: G10.01 = 1 (0 without clamp's fault); first-out
/// hydraulic`. Empty for a first-out.
pub(super) fn consequence_text(consequence: Option<&ConsequencePayload>) -> String {
    let Some(c) = consequence else {
        return String::new();
    };
    let mut text = c.why();
    if c.first_out != c.cause {
        text.push_str(&format!("; first-out {}", c.first_out));
    }
    text
}

impl Conditions {
    /// The conditions of `cell`, none yet.
    pub(super) fn new(cell: &str) -> Conditions {
        Conditions {
            cell: cell.into(),
            served: OnceLock::new(),
            alarms: Mutex::new(HashMap::new()),
            counter: AtomicU64::new(1),
            overdue: Overdue::default(),
        }
    }

    /// A fresh event id.
    pub(super) fn next_event_id(&self) -> ByteString {
        let n = self.counter.fetch_add(1, Ordering::Relaxed);
        ByteString::from(format!("{}-{n:016}", self.cell).into_bytes())
    }

    /// The alarm whose condition is `node`, and a copy of it.
    pub(super) fn by_node(&self, node: &NodeId) -> Option<(String, Condition)> {
        let alarms = self.alarms.lock();
        alarms
            .iter()
            .find(|(_, c)| c.node == *node)
            .map(|(id, c)| (id.clone(), c.clone()))
    }

    /// The alarm whose condition's `ShelvingState` is `node`, and a copy
    /// of the condition.
    pub(super) fn by_shelving_node(&self, node: &NodeId) -> Option<(String, Condition)> {
        let alarms = self.alarms.lock();
        alarms
            .iter()
            .find(|(_, c)| c.shelving_node == *node)
            .map(|(id, c)| (id.clone(), c.clone()))
    }

    /// One alarm transition: the condition made if new, changed, and its
    /// event sent.
    pub(super) fn apply(&self, p: &AlarmPayload) {
        let Some(served) = self.served.get() else {
            return;
        };
        let now = DateTime::now();
        let active = matches!(
            p.state,
            AlarmState::ActiveUnacknowledged | AlarmState::ActiveAcknowledged
        );
        let acked = matches!(p.state, AlarmState::ActiveAcknowledged | AlarmState::Normal);
        let event = {
            let mut alarms = self.alarms.lock();
            let c = alarms
                .entry(p.id.clone())
                .or_insert_with(|| self.add_condition(served, &p.id, now));
            if active != c.active {
                c.active_at = now;
            }
            if acked != c.acked {
                c.acked_at = now;
            }
            // The acknowledgement's comment, wherever it was made; none
            // for a new occurrence.
            c.comment = p.ack_comment.clone().unwrap_or_default();
            let enabled = p.out_of_service.is_none();
            if enabled != c.enabled {
                c.enabled_at = now;
            }
            c.active = active;
            c.acked = acked;
            c.enabled = enabled;
            c.acked_by = p.acked_by.clone().unwrap_or_default();
            c.message = p.message.clone();
            c.severity = severity(p.severity);
            c.culprits = culprits_text(&p.culprits);
            c.consequence = consequence_text(p.consequence.as_ref());
            c.shelved = p.shelved.as_ref().map(|shelf| {
                shelf
                    .until
                    .as_deref()
                    .and_then(|t| t.parse::<DateTime>().ok())
            });
            c.suppressed_or_shelved = p.shelved.is_some()
                || p.out_of_service.is_some()
                || p.consequence.as_ref().is_some_and(|c| c.suppressed)
                || p.suppressed_by_design.is_some();
            c.guidance = Guidance::of(p, crate::clock::now_ms());
            c.before_overdue = None;
            c.event_id = self.next_event_id();
            c.time = now;
            (
                self.event(served, &p.id, c),
                self.state_values(served.ns, &p.id, c),
            )
        };
        let (event, values) = event;
        if let Err(e) = served.nodes.set_values(
            &served.subscriptions,
            values.iter().map(|(n, v)| (n, None, v.clone())),
        ) {
            tracing::warn!(alarm = %p.id, error = %e, "alarm server: a condition's state variables not updated");
        }
        served
            .subscriptions
            .notify_events([(&event as &dyn Event, &served.notifier)].into_iter());
        // Its deadline may have moved.
        self.overdue.changed.notify_one();
    }

    /// Time reached `now` (ms since the epoch): the conditions past their
    /// response time unacknowledged become overdue, each with an event.
    /// When the next one falls due.
    pub(super) fn mark_overdue(&self, now: u64) -> Option<u64> {
        let served = self.served.get()?;
        let (due, next) = {
            let mut alarms = self.alarms.lock();
            let mut due = Vec::new();
            for (id, c) in alarms.iter_mut() {
                if c.guidance.falls_due(now) {
                    let before = std::mem::replace(&mut c.event_id, self.next_event_id());
                    c.before_overdue = Some(before);
                    c.time = DateTime::now();
                    due.push((
                        id.clone(),
                        self.event(served, id, c),
                        self.state_values(served.ns, id, c),
                    ));
                }
            }
            let next = alarms.values().filter_map(|c| c.guidance.due_at()).min();
            (due, next)
        };
        for (id, event, values) in due {
            tracing::info!(alarm = %id, "alarm server: unacknowledged past its response time: overdue");
            if let Err(e) = served.nodes.set_values(
                &served.subscriptions,
                values.iter().map(|(n, v)| (n, None, v.clone())),
            ) {
                tracing::warn!(alarm = %id, error = %e, "alarm server: a condition's state variables not updated");
            }
            served
                .subscriptions
                .notify_events([(&event as &dyn Event, &served.notifier)].into_iter());
        }
        next
    }

    /// The events of the conditions clients must keep (ConditionRefresh).
    pub(super) fn retained(&self) -> Vec<CellAlarmEvent> {
        let Some(served) = self.served.get() else {
            return Vec::new();
        };
        let alarms = self.alarms.lock();
        alarms
            .iter()
            .filter(|(_, c)| c.retain())
            .map(|(id, c)| self.event(served, id, c))
            .collect()
    }

    /// A new condition's nodes for alarm `id`.
    fn add_condition(&self, served: &Served, id: &str, now: DateTime) -> Condition {
        let node = NodeId::new(served.ns, format!("{}.{id}", self.cell));
        {
            let space = served.nodes.address_space();
            let mut space = space.write();
            ObjectBuilder::new(&node, id, id)
                .has_type_definition(served.event_type.clone())
                .component_of(served.notifier.clone())
                .insert(&mut *space);
            space.insert_reference(&served.notifier, &node, ReferenceTypeId::HasCondition);
            VariableBuilder::new(
                &NodeId::new(served.ns, format!("{}.{id}.ConditionName", self.cell)),
                "ConditionName",
                "ConditionName",
            )
            .data_type(DataTypeId::String)
            .value(id)
            .property_of(node.clone())
            .has_type_definition(VariableTypeId::PropertyType)
            .insert(&mut *space);
            ObjectBuilder::new(
                &self.state_node(served.ns, id, "ShelvingState"),
                "ShelvingState",
                "ShelvingState",
            )
            .has_type_definition(ObjectTypeId::ShelvedStateMachineType)
            .component_of(node.clone())
            .insert(&mut *space);
            for (name, data_type, initial) in STATE_VARIABLES {
                let var = self.state_node(served.ns, id, name);
                let (parent, browse) = match name.rsplit_once('.') {
                    Some((state, leaf)) => (self.state_node(served.ns, id, state), leaf),
                    None => (node.clone(), name),
                };
                let builder = VariableBuilder::new(&var, browse, browse)
                    .data_type(data_type)
                    .value(initial());
                let builder = if name.ends_with("CurrentState") {
                    builder
                        .component_of(parent)
                        .has_type_definition(VariableTypeId::FiniteStateVariableType)
                } else if name.ends_with("State") {
                    builder
                        .component_of(parent)
                        .has_type_definition(VariableTypeId::TwoStateVariableType)
                } else {
                    builder
                        .property_of(parent)
                        .has_type_definition(VariableTypeId::PropertyType)
                };
                builder.insert(&mut *space);
            }
            let none = Guidance::default();
            for (name, data_type) in guidance::PROPERTIES {
                VariableBuilder::new(&self.state_node(served.ns, id, name), name, name)
                    .data_type(data_type)
                    .value(none.value(name))
                    .property_of(node.clone())
                    .has_type_definition(VariableTypeId::PropertyType)
                    .insert(&mut *space);
            }
        }
        {
            let mut core = served.core.write();
            for method in [
                MethodId::AcknowledgeableConditionType_Acknowledge,
                MethodId::ConditionType_Enable,
                MethodId::ConditionType_Disable,
            ] {
                core.insert_reference(&node, &method.into(), ReferenceTypeId::HasComponent);
            }
            let shelving = self.state_node(served.ns, id, "ShelvingState");
            for method in [
                MethodId::ShelvedStateMachineType_TimedShelve,
                MethodId::ShelvedStateMachineType_OneShotShelve,
                MethodId::ShelvedStateMachineType_Unshelve,
            ] {
                core.insert_reference(&shelving, &method.into(), ReferenceTypeId::HasComponent);
            }
        }
        Condition {
            node,
            message: String::new(),
            severity: 0,
            culprits: String::new(),
            consequence: String::new(),
            active: false,
            acked: true,
            enabled: true,
            active_at: now,
            acked_at: now,
            enabled_at: now,
            acked_by: String::new(),
            comment: String::new(),
            suppressed_or_shelved: false,
            shelved: None,
            shelving_node: self.state_node(served.ns, id, "ShelvingState"),
            event_id: ByteString::null(),
            time: now,
            guidance: Guidance::default(),
            before_overdue: None,
        }
    }

    /// The node of state variable `name` (`ActiveState.Id`) of alarm `id`.
    fn state_node(&self, ns: u16, id: &str, name: &str) -> NodeId {
        NodeId::new(ns, format!("{}.{id}.{name}", self.cell))
    }

    /// The values of the state variables of condition `c` of alarm `id`.
    fn state_values(&self, ns: u16, id: &str, c: &Condition) -> Vec<(NodeId, DataValue)> {
        let text = |on: bool, yes: &str, no: &str| {
            Variant::from(LocalizedText::from(if on { yes } else { no }))
        };
        let (shelf_name, shelf_id) = shelving_state(c.shelved);
        let values: [(&str, Variant, DateTime); 15] = [
            (
                "EnabledState",
                text(c.enabled, "Enabled", "Disabled"),
                c.enabled_at,
            ),
            ("EnabledState.Id", c.enabled.into(), c.enabled_at),
            (
                "ActiveState",
                text(c.active, "Active", "Inactive"),
                c.active_at,
            ),
            ("ActiveState.Id", c.active.into(), c.active_at),
            (
                "AckedState",
                text(c.acked, "Acknowledged", "Unacknowledged"),
                c.acked_at,
            ),
            ("AckedState.Id", c.acked.into(), c.acked_at),
            ("Retain", c.retain().into(), c.time),
            (
                "Message",
                LocalizedText::from(c.message.as_str()).into(),
                c.time,
            ),
            ("Severity", c.severity.into(), c.time),
            ("ClientUserId", c.acked_by.as_str().into(), c.acked_at),
            ("Culprits", c.culprits.as_str().into(), c.time),
            ("Consequence", c.consequence.as_str().into(), c.time),
            (
                "ShelvingState.CurrentState",
                LocalizedText::from(shelf_name).into(),
                c.time,
            ),
            (
                "ShelvingState.CurrentState.Id",
                NodeId::from(shelf_id).into(),
                c.time,
            ),
            (
                "ShelvingState.UnshelveTime",
                unshelve_in(c.shelved).into(),
                c.time,
            ),
        ];
        let guidance = guidance::PROPERTIES
            .iter()
            .map(|(name, _)| (*name, c.guidance.value(name), c.time));
        values
            .into_iter()
            .chain(guidance)
            .map(|(name, v, at)| {
                let mut dv = DataValue::new_now(v);
                dv.source_timestamp = Some(at);
                (self.state_node(ns, id, name), dv)
            })
            .collect()
    }

    /// The event saying condition `c` of alarm `id` as it stands.
    fn event(&self, served: &Served, id: &str, c: &Condition) -> CellAlarmEvent {
        condition_event(&self.cell, &served.event_type, &served.notifier, id, c)
    }
}

/// The event saying condition `c` of alarm `id` of `cell` as it stands,
/// of type `event_type` (`CellAlarmType`) from `notifier` (the cell's
/// object).
pub(super) fn condition_event(
    cell: &str,
    event_type: &NodeId,
    notifier: &NodeId,
    id: &str,
    c: &Condition,
) -> CellAlarmEvent {
    let (shelf_name, shelf_id) = shelving_state(c.shelved);
    let mut base = BaseEventType::new(
        event_type.clone(),
        c.event_id.clone(),
        c.message.as_str(),
        c.time,
    );
    base.source_node = notifier.clone();
    base.source_name = cell.into();
    base.severity = c.severity;
    base.condition_class_id = Some(ObjectTypeId::ProcessConditionClassType.into());
    base.condition_class_name = Some("ProcessConditionClassType".into());
    CellAlarmEvent {
        condition_id: c.node.clone(),
        fields: AlarmFields {
            base,
            condition_name: id.into(),
            branch_id: NodeId::null(),
            retain: c.retain(),
            client_user_id: c.acked_by.as_str().into(),
            comment: CommentVar {
                value: if c.comment.is_empty() {
                    LocalizedText::null()
                } else {
                    c.comment.as_str().into()
                },
                source_timestamp: c.acked_at,
            },
            last_severity: SeverityVar {
                value: c.severity,
                source_timestamp: c.time,
            },
            quality: QualityVar {
                value: StatusCode::Good,
                source_timestamp: c.time,
            },
            enabled_state: TwoState::new(c.enabled, "Enabled", "Disabled", c.enabled_at),
            active_state: TwoState::new(c.active, "Active", "Inactive", c.active_at),
            acked_state: TwoState::new(c.acked, "Acknowledged", "Unacknowledged", c.acked_at),
            confirmed_state: TwoState::new(true, "Confirmed", "Unconfirmed", c.acked_at),
            suppressed_or_shelved: c.suppressed_or_shelved,
            shelving_state: ShelvingVar {
                current_state: CurrentStateVar {
                    value: shelf_name.into(),
                    id: shelf_id.into(),
                },
                unshelve_time: unshelve_in(c.shelved),
            },
            culprits: c.culprits.as_str().into(),
            consequence: c.consequence.as_str().into(),
            corrective_action: c.guidance.corrective_action.as_str().into(),
            consequence_of_inaction: c.guidance.consequence_of_inaction.as_str().into(),
            alarm_class: c.guidance.class.as_str().into(),
            response_time: c.guidance.response_time,
            overdue: c.guidance.overdue,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::ThroughPayload;

    #[test]
    fn severities_spread_over_opc_uas_range_and_culprits_read_as_on_the_console() {
        let all: Vec<u16> = Severity::ALL.iter().map(|s| severity(*s)).collect();
        assert_eq!(all, [250, 500, 750, 1000]);
        let culprit = |address: &str, trigger| CulpritPayload {
            address: address.into(),
            value: false,
            expected: true,
            comment: Some("Y Over Travel Limit SW (B)".into()),
            trigger,
            compared: None,
        };
        assert_eq!(
            culprits_text(&[culprit("X0.06", true), culprit("X0.07", false)]),
            "X0.06 = 0 (expected 1): Y Over Travel Limit SW (B)   <- trigger; X0.07 = 0 (expected 1): Y Over Travel Limit SW (B)"
        );
    }

    #[test]
    fn a_consequence_says_its_cause_the_signal_it_follows_through_and_the_first_out() {
        assert_eq!(consequence_text(None), "");
        let mut c = ConsequencePayload {
            cause: "clamp".into(),
            first_out: "hydraulic".into(),
            suppressed: false,
            through: vec![ThroughPayload {
                signal: "G10.01".into(),
                value: true,
            }],
        };
        assert_eq!(
            consequence_text(Some(&c)),
            "follows from clamp: G10.01 = 1 (0 without clamp's fault); first-out hydraulic"
        );
        c.first_out = "clamp".into();
        assert_eq!(
            consequence_text(Some(&c)),
            "follows from clamp: G10.01 = 1 (0 without clamp's fault)"
        );
    }
}
