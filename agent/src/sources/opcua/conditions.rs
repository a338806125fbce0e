//! The PLC's own alarms over OPC UA Alarms & Conditions: one event
//! monitored item per `[[opcua.events]]` notifier in the cell's
//! subscription (so that a network cut loses none: they are republished
//! with the values), each condition's events read into a [`PlcCondition`],
//! the conditions the server holds asked for on every new subscription
//! (`ConditionRefresh`), and an operator's acknowledgement carried to the
//! condition's `Acknowledge` method.

use std::collections::HashMap;

use cellwatch_models::engine::PlcCondition;
use opcua::client::{Session, UARequest};
use opcua::types::{
    AttributeId, ByteString, ContentFilter, EventFieldList, EventFilter, ExtensionObject,
    LocalizedText, MethodId, MonitoredItemCreateRequest, MonitoringMode, MonitoringParameters,
    NodeId, NumericRange, ObjectTypeId, ReadValueId, SimpleAttributeOperand, TimestampsToReturn,
    Variant,
};

use super::requests::Requests;
use crate::sources::opcua::config::EventSource;
use crate::sources::SourceEvent;

/// Client handles of event items: this plus the notifier's index (tags'
/// items are numbered from 1).
pub(super) const EVENT_HANDLE: u32 = 0xE000_0000;

/// The most conditions kept per cell (their ids, the node and the last
/// event to acknowledge): a server reporting more is said, not followed.
const MAX_CONDITIONS: usize = 4096;

/// Events a server keeps for the agent between publishes (and through a
/// network cut), per notifier.
const EVENT_QUEUE: u32 = 1000;

/// The `system` alarm of conditions that cannot be followed.
pub const EVENTS_ALARM: &str = "opcua-events";

/// The fields each event is asked for, in this order.
#[derive(Clone, Copy)]
enum Field {
    EventId,
    EventType,
    SourceName,
    Time,
    Message,
    Severity,
    ConditionName,
    Retain,
    Active,
    Acked,
    ClientUserId,
    ConditionId,
}

const FIELDS: [Field; 12] = [
    Field::EventId,
    Field::EventType,
    Field::SourceName,
    Field::Time,
    Field::Message,
    Field::Severity,
    Field::ConditionName,
    Field::Retain,
    Field::Active,
    Field::Acked,
    Field::ClientUserId,
    Field::ConditionId,
];

fn select(f: Field) -> SimpleAttributeOperand {
    let value = |t: ObjectTypeId, path: &str| SimpleAttributeOperand::new_value(t, path);
    match f {
        Field::EventId => value(ObjectTypeId::BaseEventType, "EventId"),
        Field::EventType => value(ObjectTypeId::BaseEventType, "EventType"),
        Field::SourceName => value(ObjectTypeId::BaseEventType, "SourceName"),
        Field::Time => value(ObjectTypeId::BaseEventType, "Time"),
        Field::Message => value(ObjectTypeId::BaseEventType, "Message"),
        Field::Severity => value(ObjectTypeId::BaseEventType, "Severity"),
        Field::ConditionName => value(ObjectTypeId::ConditionType, "ConditionName"),
        Field::Retain => value(ObjectTypeId::ConditionType, "Retain"),
        Field::Active => value(ObjectTypeId::AlarmConditionType, "ActiveState/Id"),
        Field::Acked => value(ObjectTypeId::AcknowledgeableConditionType, "AckedState/Id"),
        Field::ClientUserId => value(ObjectTypeId::ConditionType, "ClientUserId"),
        // The condition's own node: the type, no path, its NodeId.
        Field::ConditionId => SimpleAttributeOperand {
            type_definition_id: ObjectTypeId::ConditionType.into(),
            browse_path: None,
            attribute_id: AttributeId::NodeId as u32,
            index_range: NumericRange::None,
        },
    }
}

/// The request that creates notifier `k`'s event item.
pub(super) fn item_request(k: usize, node: NodeId) -> MonitoredItemCreateRequest {
    let filter = EventFilter {
        select_clauses: Some(FIELDS.iter().map(|&f| select(f)).collect()),
        where_clause: ContentFilter { elements: None },
    };
    let params = MonitoringParameters {
        client_handle: EVENT_HANDLE + k as u32,
        sampling_interval: 0.0,
        // Events are not coalesced: room for a burst of them.
        queue_size: EVENT_QUEUE,
        discard_oldest: true,
        filter: ExtensionObject::from_message(filter),
    };
    let read = ReadValueId {
        node_id: node,
        attribute_id: AttributeId::EventNotifier as u32,
        ..ReadValueId::default()
    };
    MonitoredItemCreateRequest::new(read, MonitoringMode::Reporting, params)
}

/// Follows the PLC's alarms in new subscription `sub`, if any notifier is
/// configured: its event items, and the conditions held now; what stands in
/// the way is the `opcua-events` alarm.
pub(super) async fn follow(
    session: &Session,
    sub: u32,
    conditions: &std::sync::Mutex<Conditions>,
    namespaces: &[String],
    tx: &crate::sources::SourceSender,
    requests: &Requests,
) {
    let notifiers: Vec<Option<NodeId>> = {
        let c = conditions.lock().unwrap_or_else(|e| e.into_inner());
        if !c.any() {
            return;
        }
        c.sources().map(|s| s.source.resolve(namespaces)).collect()
    };
    let problem = subscribe(session, sub, &notifiers, requests).await;
    match &problem {
        Some(p) => tracing::warn!(problem = %p, "the PLC's alarms"),
        None => tracing::info!(
            subscription = sub,
            notifiers = notifiers.len(),
            "following the PLC's alarms"
        ),
    }
    let _ = tx
        .send(SourceEvent::Problem {
            id: EVENTS_ALARM.into(),
            problem,
        })
        .await;
}

/// Creates the event items of `notifiers` (each resolved, or `None`) in
/// subscription `sub`, then asks the server for every condition it holds
/// (`ConditionRefresh`): they arrive as events, between a refresh's start
/// and end. Problems are logged and said; the tags are read regardless.
pub(super) async fn subscribe(
    session: &Session,
    sub: u32,
    notifiers: &[Option<NodeId>],
    requests: &Requests,
) -> Option<String> {
    let items: Vec<_> = notifiers
        .iter()
        .enumerate()
        .filter_map(|(k, n)| Some(item_request(k, n.clone()?)))
        .collect();
    if items.is_empty() {
        return (!notifiers.is_empty())
            .then(|| "no notifier of opcua.events is on the server (namespace missing)".into());
    }
    let created = opcua::client::services::CreateMonitoredItems::new(sub, session)
        .items_to_create(items)
        .timestamps_to_return(TimestampsToReturn::Neither)
        .send(session.channel())
        .await;
    requests.answered("CreateMonitoredItems", &created);
    let refused: Vec<String> = match created {
        Err(e) => return Some(format!("cannot subscribe to the PLC's alarms: {e}")),
        Ok(r) => r
            .results
            .iter()
            .filter(|r| r.result.status_code.is_bad())
            .map(|r| r.result.status_code.to_string())
            .collect(),
    };
    if !refused.is_empty() {
        return Some(format!(
            "the server refused to report the PLC's alarms: {}",
            refused.join(", ")
        ));
    }
    let refresh = (
        NodeId::from(ObjectTypeId::ConditionType),
        NodeId::from(MethodId::ConditionType_ConditionRefresh),
        Some(vec![Variant::from(sub)]),
    );
    let refreshed = session.call_one(refresh).await;
    requests.answered("Call", &refreshed);
    match refreshed {
        Ok(r) if r.status_code.is_good() => None,
        Ok(r) => Some(format!(
            "the server cannot say which alarms the PLC holds now (ConditionRefresh: {})",
            r.status_code
        )),
        Err(e) => Some(format!(
            "the server cannot say which alarms the PLC holds now (ConditionRefresh: {e})"
        )),
    }
}

/// What acknowledging a condition needs: its node and its latest event.
#[derive(Debug, Clone)]
struct Target {
    condition: NodeId,
    event: ByteString,
}

/// Per notifier: its configuration and the refresh under way.
struct Notifier {
    source: EventSource,
    /// Between a refresh's start and end: the conditions held.
    refreshing: Option<Vec<String>>,
}

/// The conditions of one cell's notifiers, across its subscriptions.
pub(super) struct Conditions {
    notifiers: Vec<Notifier>,
    /// Each condition's alarm id to what acknowledging it needs.
    targets: HashMap<String, Target>,
    /// More conditions than [`MAX_CONDITIONS`] were reported and not
    /// followed: said once.
    full: bool,
}

impl Conditions {
    pub(super) fn new(sources: &[EventSource]) -> Conditions {
        Conditions {
            notifiers: sources
                .iter()
                .map(|s| Notifier {
                    source: s.clone(),
                    refreshing: None,
                })
                .collect(),
            targets: HashMap::new(),
            full: false,
        }
    }

    /// Whether any notifier is configured.
    pub(super) fn any(&self) -> bool {
        !self.notifiers.is_empty()
    }

    /// The notifiers' nodes.
    pub(super) fn sources(&self) -> impl Iterator<Item = &EventSource> {
        self.notifiers.iter().map(|n| &n.source)
    }

    /// One publish's events, in the server's order: what to tell the cell
    /// loop.
    pub(super) fn events(&mut self, lists: Vec<EventFieldList>, now: u64) -> Vec<SourceEvent> {
        let mut out = Vec::new();
        let mut conditions = Vec::new();
        tracing::debug!(events = lists.len(), "events of the PLC's alarms");
        for list in lists {
            let k = list.client_handle.wrapping_sub(EVENT_HANDLE) as usize;
            let Some(n) = self.notifiers.get_mut(k) else {
                continue;
            };
            let fields = list.event_fields.unwrap_or_default();
            let field = |f: Field| fields.get(f as usize).unwrap_or(&Variant::Empty);
            let event_type = match field(Field::EventType) {
                Variant::NodeId(id) => Some(*id.clone()),
                _ => None,
            };
            if event_type == Some(ObjectTypeId::RefreshStartEventType.into()) {
                n.refreshing = Some(Vec::new());
                continue;
            }
            if event_type == Some(ObjectTypeId::RefreshEndEventType.into()) {
                if let Some(held) = n.refreshing.take() {
                    // What came before the end is told before it.
                    out.push(SourceEvent::Conditions(std::mem::take(&mut conditions)));
                    out.push(SourceEvent::ConditionsHeld {
                        prefix: n.source.prefix.clone(),
                        held,
                    });
                }
                continue;
            }
            let Variant::NodeId(condition) = field(Field::ConditionId) else {
                // An event that is no condition's (an audit event).
                continue;
            };
            let condition = *condition.clone();
            let id = alarm_id(
                &n.source.prefix,
                text(field(Field::SourceName)),
                text(field(Field::ConditionName)),
                &condition,
            );
            let severity = match field(Field::Severity) {
                Variant::UInt16(s) => *s,
                _ => 0,
            };
            let retain = matches!(field(Field::Retain), Variant::Boolean(true));
            if severity < n.source.min_severity && !self.targets.contains_key(&id) {
                continue;
            }
            let active = match field(Field::Active) {
                Variant::Boolean(b) => *b,
                // A condition without an active state holds while kept.
                _ => retain,
            };
            let acked = matches!(field(Field::Acked), Variant::Boolean(true)).then(|| {
                match text(field(Field::ClientUserId)) {
                    "" => cellwatch_models::engine::ACKED_AT_PLC.to_string(),
                    user => format!("{}: {}", cellwatch_models::engine::ACKED_AT_PLC, clip(user)),
                }
            });
            if let Some(held) = n.refreshing.as_mut() {
                if retain && held.len() < MAX_CONDITIONS {
                    held.push(id.clone());
                }
            }
            if retain || active {
                if self.targets.len() >= MAX_CONDITIONS && !self.targets.contains_key(&id) {
                    if !self.full {
                        self.full = true;
                        out.push(SourceEvent::Conditions(std::mem::take(&mut conditions)));
                        out.push(SourceEvent::Problem {
                            id: EVENTS_ALARM.into(),
                            problem: Some(format!(
                                "the server reports more than {MAX_CONDITIONS} alarms of the PLC: the others are not followed"
                            )),
                        });
                    }
                    continue;
                }
                let event = match field(Field::EventId) {
                    Variant::ByteString(b) => b.clone(),
                    _ => ByteString::null(),
                };
                self.targets.insert(id.clone(), Target { condition, event });
            } else {
                self.targets.remove(&id);
            }
            let message = match field(Field::Message) {
                Variant::LocalizedText(t) if !t.text.is_empty() => clip(t.text.as_ref()),
                _ => clip(text(field(Field::ConditionName))),
            };
            let time = match field(Field::Time) {
                Variant::DateTime(t) => {
                    u64::try_from(t.as_chrono().timestamp_millis()).unwrap_or(now)
                }
                _ => now,
            };
            conditions.push(PlcCondition {
                severity: PlcCondition::severity_of(severity),
                id,
                message,
                active,
                acked,
                time,
            });
        }
        if !conditions.is_empty() {
            out.push(SourceEvent::Conditions(conditions));
        }
        out
    }

    /// What acknowledging alarm `id` calls: the condition's node and its
    /// latest event.
    fn target(&self, id: &str) -> Option<Target> {
        self.targets.get(id).cloned()
    }
}

/// Acknowledges the condition of alarm `id` at the PLC, with `comment`
/// (who, in cellwatch): what the server answered.
///
/// # Errors
/// The condition is not known, or the server refused.
pub(super) async fn acknowledge(
    session: &Session,
    conditions: &std::sync::Mutex<Conditions>,
    id: &str,
    comment: &str,
    requests: &Requests,
) -> Result<String, super::OpcUaError> {
    let target = conditions
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .target(id);
    // A condition the server keeps no more (it ended, and a server that
    // does not keep it while unacknowledged said so) has nothing to
    // acknowledge at the PLC: the alarm is acknowledged in cellwatch.
    let Some(target) = target else {
        return Ok(format!(
            "{id}: the PLC holds this condition no more; acknowledged in cellwatch only"
        ));
    };
    let call = (
        target.condition,
        NodeId::from(MethodId::AcknowledgeableConditionType_Acknowledge),
        Some(vec![
            Variant::from(target.event),
            Variant::from(LocalizedText::new("", comment)),
        ]),
    );
    let called = session.call_one(call).await;
    requests.answered("Call", &called);
    match called {
        Ok(r) if r.status_code.is_good() => Ok(format!("{id} acknowledged at the PLC")),
        Ok(r) => Err(super::OpcUaError::AckRefused {
            id: id.to_string(),
            status: r.status_code,
        }),
        Err(source) => Err(super::OpcUaError::Ack {
            id: id.to_string(),
            source,
        }),
    }
}

fn text(v: &Variant) -> &str {
    match v {
        Variant::String(s) => s.as_ref(),
        Variant::LocalizedText(t) => t.text.as_ref(),
        Variant::QualifiedName(q) => q.name.as_ref(),
        _ => "",
    }
}

/// A server's text, bounded.
fn clip(s: &str) -> String {
    crate::operator::clip(s, 500)
}

/// `<prefix>-<source>-<condition>`, each name a key chunk (letters, digits,
/// `-`, `_`; anything else `_`), at most 60 characters each; the condition's
/// node identifier when it has no name.
pub(super) fn alarm_id(prefix: &str, source: &str, name: &str, condition: &NodeId) -> String {
    let chunk = |s: &str| -> String {
        s.chars()
            .take(60)
            .map(|c| {
                if c.is_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    };
    let name = match name {
        "" => chunk(&condition.identifier.to_string()),
        n => chunk(n),
    };
    match source {
        "" => format!("{prefix}-{name}"),
        s => format!("{prefix}-{}-{name}", chunk(s)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_alarm_id_is_made_of_key_chunks() {
        let node = NodeId::new(2, "Press.Overpressure");
        assert_eq!(
            alarm_id("plc", "Press", "Overpressure", &node),
            "plc-Press-Overpressure"
        );
        assert_eq!(
            alarm_id("plc", "Line 1/Press", "Über Druck", &node),
            "plc-Line_1_Press-Über_Druck"
        );
        assert_eq!(alarm_id("plc", "", "", &node), "plc-s_Press_Overpressure");
        assert!(crate::tags::key_chunk(
            &alarm_id("p", &"x".repeat(500), "y", &node)["p-".len()..]
        ));
    }
}
