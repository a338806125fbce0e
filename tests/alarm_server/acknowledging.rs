//! A SCADA client of async-opcua sees ESE raised with its diagnosis and
//! culprits and acknowledges it as kim; users mapped (or not) to operators.

use std::time::Duration;

use opcua::client::{IdentityToken, MonitoredItem, OnSubscriptionNotification, Session};
use opcua::types::{
    AttributeId, ByteString, CallMethodRequest, EventFilter, ExtensionObject, LocalizedText,
    MethodId, MonitoredItemCreateRequest, MonitoringMode, MonitoringParameters, NodeId,
    NumericRange, ObjectId, ObjectTypeId, QualifiedName, ReadValueId, SimpleAttributeOperand,
    StatusCode, TimestampsToReturn, Variant,
};
use tokio::sync::mpsc;
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::agent::alarm_until;

use super::{commands_journaled, connect, scada, serving_with, state};

/// Each event's fields, in the order of [`select`].
struct Events(mpsc::UnboundedSender<Vec<Variant>>);

impl OnSubscriptionNotification for Events {
    fn on_event(&mut self, fields: Option<Vec<Variant>>, _item: &MonitoredItem) {
        let _ = self.0.send(fields.unwrap_or_default());
    }
}

const EVENT_ID: usize = 0;
const EVENT_TYPE: usize = 1;
const SOURCE_NAME: usize = 2;
const MESSAGE: usize = 3;
const SEVERITY: usize = 4;
const CONDITION_NAME: usize = 5;
const ACTIVE: usize = 6;
const ACKED: usize = 7;
const RETAIN: usize = 8;
const CLIENT_USER: usize = 9;
const CONDITION_ID: usize = 10;
/// A field no condition has: refused, null, and the fields after it in
/// their places (the patched async-opcua-nodes, vendor/README.md).
const NO_SUCH_FIELD: usize = 11;
const CULPRITS: usize = 12;
const CORRECTIVE_ACTION: usize = 13;
const RESPONSE_TIME: usize = 14;
const OVERDUE: usize = 15;

/// The select clauses of a SCADA client of `CellAlarmType` (in namespace
/// `ns`).
fn select(ns: u16) -> Vec<SimpleAttributeOperand> {
    let base = |p: &str| SimpleAttributeOperand::new_value(ObjectTypeId::BaseEventType, p);
    let alarm = |p: &str| SimpleAttributeOperand::new_value(ObjectTypeId::AlarmConditionType, p);
    let own = |name: &str| SimpleAttributeOperand {
        type_definition_id: NodeId::new(ns, "CellAlarmType"),
        browse_path: Some(vec![QualifiedName::new(ns, name)]),
        attribute_id: AttributeId::Value as u32,
        index_range: NumericRange::None,
    };
    vec![
        base("EventId"),
        base("EventType"),
        base("SourceName"),
        base("Message"),
        base("Severity"),
        alarm("ConditionName"),
        alarm("ActiveState/Id"),
        alarm("AckedState/Id"),
        alarm("Retain"),
        alarm("ClientUserId"),
        SimpleAttributeOperand {
            type_definition_id: ObjectTypeId::ConditionType.into(),
            browse_path: Some(vec![]),
            attribute_id: AttributeId::NodeId as u32,
            index_range: NumericRange::None,
        },
        alarm("NoSuchField"),
        own("Culprits"),
        own("CorrectiveAction"),
        own("ResponseTime"),
        own("Overdue"),
    ]
}

/// Acknowledges condition `condition`'s event `event_id`.
async fn acknowledge(session: &Session, condition: &NodeId, event_id: &Variant) -> StatusCode {
    session
        .call_one(CallMethodRequest {
            object_id: condition.clone(),
            method_id: MethodId::AcknowledgeableConditionType_Acknowledge.into(),
            input_arguments: Some(vec![
                event_id.clone(),
                LocalizedText::from("seen on the SCADA").into(),
            ]),
        })
        .await
        .unwrap()
        .status_code
}

/// Calls `method` (no arguments) on `object`.
async fn call(session: &Session, object: &NodeId, method: MethodId) -> StatusCode {
    session
        .call_one(CallMethodRequest {
            object_id: object.clone(),
            method_id: method.into(),
            input_arguments: Some(Vec::new()),
        })
        .await
        .unwrap()
        .status_code
}

/// The browse names of what `node` organises or has as components and
/// properties.
async fn browse(session: &Session, node: &NodeId) -> Vec<String> {
    let results = session
        .browse(
            &[opcua::types::BrowseDescription {
                node_id: node.clone(),
                browse_direction: opcua::types::BrowseDirection::Forward,
                reference_type_id: opcua::types::ReferenceTypeId::HierarchicalReferences.into(),
                include_subtypes: true,
                node_class_mask: 0,
                result_mask: opcua::types::BrowseResultMask::All as u32,
            }],
            100,
            None,
        )
        .await
        .unwrap();
    results[0]
        .references
        .iter()
        .flatten()
        .map(|r| r.browse_name.name.to_string())
        .collect()
}

/// Receives events until `f` accepts one.
async fn event_until(
    rx: &mut mpsc::UnboundedReceiver<Vec<Variant>>,
    what: &str,
    f: impl Fn(&[Variant]) -> bool,
) -> Vec<Variant> {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    let mut seen = Vec::new();
    loop {
        let e = tokio::time::timeout_at(deadline, rx.recv())
            .await
            .unwrap_or_else(|_| panic!("timed out waiting for {what}; saw {seen:#?}"))
            .unwrap();
        if f(&e) {
            return e;
        }
        seen.push(e);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scada_client_sees_ese_and_acknowledges_it_as_kim() {
    // The master alarm database gives ESE a corrective action and a
    // second to act.
    let fx = serving_with(|c| {
        let dir = c.journal.path.parent().unwrap().to_path_buf();
        let text = "id,priority,class,consequence_of_inaction,corrective_action,response_time\n\
                    ese,,safety,the line stays down,Release the emergency stop,1s\n";
        let path = dir.join("mad.csv");
        std::fs::write(&path, text).unwrap();
        let database = cellwatch_models::madb::Database::parse("mad.csv", text).unwrap();
        c.database = Some((path, database));
    })
    .await;
    let addr = fx.agent().alarm_server_addr().unwrap();
    let url = format!("opc.tcp://{addr}/");
    // Each trusts the other's certificate.
    let (server_pki, scada_pki) = (
        fx.dir().join("alarm-server-pki"),
        fx.dir().join("scada-pki"),
    );
    drop(scada(&scada_pki));
    use cellwatch::sources::pki;
    pki::trust(&pki::own_cert(&scada_pki), &server_pki).unwrap();
    pki::trust(&pki::own_cert(&server_pki), &scada_pki).unwrap();

    let kim = connect(
        &url,
        &scada_pki,
        IdentityToken::UserName("scada-kim".into(), "kims-password".into()),
    )
    .await;
    let ns = kim
        .get_namespace_index("urn:cellwatch:alarms:m01ps0004")
        .await
        .unwrap();
    let (tx, mut events) = mpsc::unbounded_channel();
    let subscription = kim
        .create_subscription(
            Duration::from_millis(50),
            600,
            20,
            1000,
            0,
            true,
            Events(tx),
        )
        .await
        .unwrap();
    let created = kim
        .create_monitored_items(
            subscription,
            TimestampsToReturn::Both,
            vec![MonitoredItemCreateRequest {
                item_to_monitor: ReadValueId {
                    node_id: ObjectId::Server.into(),
                    attribute_id: AttributeId::EventNotifier as u32,
                    ..Default::default()
                },
                monitoring_mode: MonitoringMode::Reporting,
                requested_parameters: MonitoringParameters {
                    queue_size: 100,
                    discard_oldest: true,
                    filter: ExtensionObject::new(EventFilter {
                        select_clauses: Some(select(ns)),
                        where_clause: Default::default(),
                    }),
                    ..Default::default()
                },
            }],
        )
        .await
        .unwrap();
    assert!(created[0].result.status_code.is_good(), "{created:?}");
    let filter = created[0]
        .result
        .filter_result
        .inner_as::<opcua::types::EventFilterResult>()
        .unwrap();
    let refused: Vec<usize> = filter
        .select_clause_results
        .iter()
        .flatten()
        .enumerate()
        .filter(|(_, s)| !s.is_good())
        .map(|(i, _)| i)
        .collect();
    assert_eq!(refused, [NO_SUCH_FIELD], "{filter:?}");

    let bus = fx
        .client()
        .declare_subscriber("cellwatch/m01ps0004/alarms/ese")
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .unwrap();
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();

    // The event of ESE raised: the diagnosis as its message, the culprits.
    let raised = event_until(&mut events, "ESE raised", |e| {
        e[CONDITION_NAME] == Variant::from("ese") && e[ACTIVE] == Variant::from(true)
    })
    .await;
    let mut seen = Vec::new();
    let payload = alarm_until(&bus, "ESE raised on the bus", &mut seen, |a| {
        a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(
        raised[MESSAGE],
        Variant::from(LocalizedText::from(payload.message.as_str()))
    );
    assert!(payload.message.contains("X0.06"), "{}", payload.message);
    assert_eq!(raised[SOURCE_NAME], Variant::from("m01ps0004"));
    assert_eq!(raised[ACKED], Variant::from(false));
    assert_eq!(raised[RETAIN], Variant::from(true));
    assert_eq!(raised[NO_SUCH_FIELD], Variant::Empty);
    assert_eq!(
        raised[EVENT_TYPE],
        Variant::from(NodeId::new(ns, "CellAlarmType"))
    );
    let expected = match payload.severity.as_str() {
        "low" => 250u16,
        "medium" => 500,
        "high" => 750,
        _ => 1000,
    };
    assert_eq!(raised[SEVERITY], Variant::from(expected));
    let Variant::String(culprits) = &raised[CULPRITS] else {
        panic!("culprits: {:?}", raised[CULPRITS]);
    };
    assert!(
        culprits.as_ref().contains("X0.06 = 0 (expected 1)"),
        "{culprits}"
    );
    let Variant::NodeId(condition) = &raised[CONDITION_ID] else {
        panic!("condition id: {:?}", raised[CONDITION_ID]);
    };
    let condition = (**condition).clone();
    let event_id = raised[EVENT_ID].clone();
    // The guidance, in the event and as properties.
    assert_eq!(
        raised[CORRECTIVE_ACTION],
        Variant::from("Release the emergency stop")
    );
    assert_eq!(raised[RESPONSE_TIME], Variant::from(1_000.0f64));
    assert_eq!(raised[OVERDUE], Variant::from(false));
    // Unacknowledged past its second: an event says it is overdue, the
    // same state otherwise.
    let late = event_until(&mut events, "ESE overdue", |e| {
        e[CONDITION_NAME] == Variant::from("ese") && e[OVERDUE] == Variant::from(true)
    })
    .await;
    assert_eq!(
        (&late[ACTIVE], &late[ACKED]),
        (&Variant::from(true), &Variant::from(false))
    );
    assert_ne!(late[EVENT_ID], event_id);
    assert_eq!(state(&kim, ns, "Overdue").await, Variant::from(true));
    // Its state is in variables too, for clients that browse and read.
    let children = browse(&kim, &condition).await;
    for name in [
        "ActiveState",
        "AckedState",
        "Retain",
        "Message",
        "Culprits",
        "CorrectiveAction",
        "Overdue",
    ] {
        assert!(children.iter().any(|c| c == name), "{name}: {children:?}");
    }
    assert_eq!(
        browse(&kim, &NodeId::new(ns, "m01ps0004.ese.ActiveState")).await,
        ["Id"]
    );
    assert_eq!(state(&kim, ns, "ActiveState.Id").await, Variant::from(true));
    assert_eq!(state(&kim, ns, "AckedState.Id").await, Variant::from(false));
    assert_eq!(state(&kim, ns, "Message").await, raised[MESSAGE]);
    assert_eq!(state(&kim, ns, "Culprits").await, raised[CULPRITS]);

    // No one but a user acting as an operator allowed `ack` acknowledges.
    let anonymous = connect(&url, &scada_pki, IdentityToken::Anonymous).await;
    assert_eq!(
        acknowledge(&anonymous, &condition, &event_id).await,
        StatusCode::BadUserAccessDenied
    );
    let viewer = connect(
        &url,
        &scada_pki,
        IdentityToken::UserName("viewer".into(), "kims-password".into()),
    )
    .await;
    assert_eq!(
        acknowledge(&viewer, &condition, &event_id).await,
        StatusCode::BadUserAccessDenied
    );
    let lee = connect(
        &url,
        &scada_pki,
        IdentityToken::UserName("scada-lee".into(), "kims-password".into()),
    )
    .await;
    assert_eq!(
        acknowledge(&lee, &condition, &event_id).await,
        StatusCode::BadUserAccessDenied
    );
    let ana = connect(
        &url,
        &scada_pki,
        IdentityToken::UserName("scada-ana".into(), "kims-password".into()),
    )
    .await;
    assert_eq!(
        acknowledge(&ana, &condition, &event_id).await,
        StatusCode::BadUserAccessDenied
    );
    assert_eq!(
        acknowledge(
            &kim,
            &condition,
            &Variant::from(ByteString::from(b"old".to_vec()))
        )
        .await,
        StatusCode::BadEventIdUnknown
    );

    // Kim acknowledges (the event she saw first: the overdue one says the
    // same state): Good once the cell loop took it.
    assert_eq!(
        acknowledge(&kim, &condition, &event_id).await,
        StatusCode::Good
    );
    let acked = event_until(&mut events, "ESE acknowledged", |e| {
        e[CONDITION_NAME] == Variant::from("ese") && e[ACKED] == Variant::from(true)
    })
    .await;
    assert_eq!(acked[CLIENT_USER], Variant::from("kim"));
    assert_eq!(acked[OVERDUE], Variant::from(false));
    assert_eq!(acked[ACTIVE], Variant::from(true));
    assert_eq!(state(&kim, ns, "AckedState.Id").await, Variant::from(true));
    assert_eq!(state(&kim, ns, "ClientUserId").await, Variant::from("kim"));
    assert_eq!(
        acknowledge(&kim, &condition, &acked[EVENT_ID]).await,
        StatusCode::BadConditionBranchAlreadyAcked
    );
    // A client that (re)connects asks for what it must show: ESE, active
    // and acknowledged, between the refresh's start and end.
    let refreshed = kim
        .call_one(CallMethodRequest {
            object_id: ObjectTypeId::ConditionType.into(),
            method_id: MethodId::ConditionType_ConditionRefresh.into(),
            input_arguments: Some(vec![Variant::UInt32(subscription)]),
        })
        .await
        .unwrap();
    assert_eq!(refreshed.status_code, StatusCode::Good);
    let is_type = |e: &[Variant], t: ObjectTypeId| e[EVENT_TYPE] == Variant::from(NodeId::from(t));
    event_until(&mut events, "the refresh's start", |e| {
        is_type(e, ObjectTypeId::RefreshStartEventType)
    })
    .await;
    let mut retained = Vec::new();
    loop {
        let e = tokio::time::timeout(Duration::from_secs(60), events.recv())
            .await
            .expect("the refresh's end never came")
            .unwrap();
        if is_type(&e, ObjectTypeId::RefreshEndEventType) {
            break;
        }
        retained.push((
            e[CONDITION_NAME].clone(),
            e[ACTIVE].clone(),
            e[ACKED].clone(),
        ));
    }
    assert_eq!(
        retained,
        [(
            Variant::from("ese"),
            Variant::from(true),
            Variant::from(true)
        )]
    );
    let on_bus = alarm_until(&bus, "ESE acknowledged on the bus", &mut seen, |a| {
        a.transition.as_str() == "acknowledged"
    })
    .await;
    assert_eq!(
        (on_bus.acked_by.as_deref(), on_bus.ack_comment.as_deref()),
        (Some("kim"), Some("seen on the SCADA"))
    );
    // Journaled before the answer: the rows are there at once.
    commands_journaled(
        &fx,
        &[
            (
                false,
                "lee",
                "unknown operator 'lee'",
                "opcua user scada-lee",
            ),
            (
                false,
                "ana",
                "operator 'ana' may not ack",
                "opcua user scada-ana",
            ),
            (
                true,
                "kim",
                "ack ese by kim: seen on the SCADA",
                "opcua user scada-kim",
            ),
        ],
    )
    .await;

    // Disabled from the SCADA: ESE out of service (ISA-18.2) as kim, not
    // by ana, who may not; enabled again.
    assert_eq!(
        call(&ana, &condition, MethodId::ConditionType_Disable).await,
        StatusCode::BadUserAccessDenied
    );
    assert_eq!(
        call(&kim, &condition, MethodId::ConditionType_Enable).await,
        StatusCode::BadConditionAlreadyEnabled
    );
    assert_eq!(
        call(&kim, &condition, MethodId::ConditionType_Disable).await,
        StatusCode::Good
    );
    let removed = alarm_until(&bus, "ESE out of service on the bus", &mut seen, |a| {
        a.transition.as_str() == "out_of_service"
    })
    .await;
    let removal = removed.out_of_service.unwrap();
    assert_eq!(
        (removal.by.as_str(), removal.reason.as_str()),
        ("kim", "disabled over OPC UA by scada-kim")
    );
    assert_eq!(
        state(&kim, ns, "EnabledState.Id").await,
        Variant::from(false)
    );
    assert_eq!(state(&kim, ns, "Retain").await, Variant::from(false));
    assert_eq!(
        call(&kim, &condition, MethodId::ConditionType_Disable).await,
        StatusCode::BadConditionAlreadyDisabled
    );
    assert_eq!(
        call(&kim, &condition, MethodId::ConditionType_Enable).await,
        StatusCode::Good
    );
    alarm_until(&bus, "ESE in service on the bus", &mut seen, |a| {
        a.transition.as_str() == "in_service"
    })
    .await;
    assert_eq!(
        state(&kim, ns, "EnabledState.Id").await,
        Variant::from(true)
    );
    let rows = fx
        .history_rows("cellwatch/m01ps0004/history?since=1h;kind=command")
        .await;
    let last: Vec<(&str, &str)> = rows[rows.len() - 3..]
        .iter()
        .map(|r| {
            let f = &r["fields"];
            (f["detail"].as_str().unwrap(), f["source"].as_str().unwrap())
        })
        .collect();
    assert_eq!(
        last,
        [
            (
                "operator 'ana' may not out-of-service",
                "opcua user scada-ana"
            ),
            ("out-of-service ese by kim", "opcua user scada-kim"),
            ("in-service ese by kim", "opcua user scada-kim"),
        ]
    );
    // The agent stops with SCADA sessions open.
    let mut fx = fx;
    tokio::time::timeout(Duration::from_secs(60), fx.stop())
        .await
        .expect("the agent stops with the alarm server's sessions open");
}
