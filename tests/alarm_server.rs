//! The alarm server (`[alarm_server]`) with real parts: the agent over the
//! simulated CNC, a SCADA client of async-opcua over Basic256Sha256 with
//! SignAndEncrypt subscribing to events on the `Server` object, seeing ESE
//! raised with its diagnosis and culprits, and acknowledging it as users
//! mapped (or not) to operators; the bus and the journal say what the cell
//! loop did.

use std::path::Path;
use std::time::Duration;

use cellwatch::config::AlarmServerConfig;
use cellwatch::operator::Action;
use cellwatch::services::alarm_server::users::hash_password;
use opcua::client::{
    Client, ClientBuilder, IdentityToken, MonitoredItem, OnSubscriptionNotification, Session,
};
use opcua::crypto::SecurityPolicy;
use opcua::types::{
    AttributeId, ByteString, CallMethodRequest, EventFilter, ExtensionObject, LocalizedText,
    MessageSecurityMode, MethodId, MonitoredItemCreateRequest, MonitoringMode,
    MonitoringParameters, NodeId, NumericRange, ObjectId, ObjectTypeId, QualifiedName, ReadValueId,
    SimpleAttributeOperand, StatusCode, TimestampsToReturn, Variant,
};
use tokio::sync::mpsc;
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use crate::agent::{alarm_until, Fixture};

mod asyncua;
mod channels;
mod scada;
pub(crate) use scada::ScadaProgram;

/// The users: kim's SCADA account, one acting as an operator the agent
/// does not know, one as an operator who may not acknowledge, one acting
/// as nobody.
pub(crate) fn users_file(path: &Path) {
    let hash = hash_password("kims-password");
    std::fs::write(
        path,
        format!(
            "[users.scada-kim]\noperator = \"kim\"\npassword_hash = \"{hash}\"\n\n\
             [users.scada-lee]\noperator = \"lee\"\npassword_hash = \"{hash}\"\n\n\
             [users.scada-ana]\noperator = \"ana\"\npassword_hash = \"{hash}\"\n\n\
             [users.viewer]\npassword_hash = \"{hash}\"\n"
        ),
    )
    .unwrap();
}

/// Kim's signed `action` on ESE over the bus (a shelf: 30 minutes, for
/// a sensor cable): accepted, and what the agent said.
async fn kim_says(fx: &Fixture, action: Action) -> (bool, String) {
    let command = match action {
        Action::Shelve => {
            crate::spawned::signed_with(action, "ese", Some("30m"), Some("sensor cable"))
        }
        _ => crate::spawned::signed(action, "ese"),
    };
    crate::spawned::send(fx.client(), &command).await
}

/// The journal's command rows are `expected`: accepted, operator,
/// detail, source.
async fn commands_journaled(fx: &Fixture, expected: &[(bool, &str, &str, &str)]) {
    let rows = fx
        .history_rows("cellwatch/m01ps0004/history?since=1h;kind=command")
        .await;
    let commands: Vec<(bool, &str, &str, &str)> = rows
        .iter()
        .map(|r| {
            let f = &r["fields"];
            (
                f["accepted"].as_bool().unwrap(),
                f["operator"].as_str().unwrap(),
                f["detail"].as_str().unwrap(),
                f["source"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(commands, expected);
}

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

/// The select clauses of a SCADA client of `CellAlarmType` (in namespace
/// `ns`).
fn select(ns: u16) -> Vec<SimpleAttributeOperand> {
    let base = |p: &str| SimpleAttributeOperand::new_value(ObjectTypeId::BaseEventType, p);
    let alarm = |p: &str| SimpleAttributeOperand::new_value(ObjectTypeId::AlarmConditionType, p);
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
        SimpleAttributeOperand {
            type_definition_id: NodeId::new(ns, "CellAlarmType"),
            browse_path: Some(vec![QualifiedName::new(ns, "Culprits")]),
            attribute_id: AttributeId::Value as u32,
            index_range: NumericRange::None,
        },
    ]
}

/// The SCADA's client, its key pair in `pki` (made if missing); it
/// trusts only the server certificates in `pki/trusted`.
pub(crate) fn scada(pki: &Path) -> Client {
    ClientBuilder::new()
        .application_name("scada")
        .application_uri("urn:cellwatch:test:scada")
        .product_uri("urn:cellwatch:test")
        .pki_dir(pki)
        .create_sample_keypair(true)
        .trust_server_certs(false)
        .session_retry_limit(0)
        .client()
        .unwrap()
}

/// A session to the alarm server at `url` as `identity`, the client's
/// certificate in `pki`.
pub(crate) async fn connect(
    url: &str,
    pki: &Path,
    identity: IdentityToken,
) -> std::sync::Arc<Session> {
    let mut client = scada(pki);
    let (session, event_loop) = client
        .connect_to_matching_endpoint(
            (
                url,
                SecurityPolicy::Basic256Sha256.to_str(),
                MessageSecurityMode::SignAndEncrypt,
            ),
            identity,
        )
        .await
        .unwrap();
    event_loop.spawn();
    tokio::time::timeout(Duration::from_secs(30), session.wait_for_connection())
        .await
        .unwrap();
    session
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

/// The value of ESE's state variable `name` (`ActiveState.Id`).
pub(crate) async fn state(session: &Session, ns: u16, name: &str) -> Variant {
    let read = session
        .read(
            &[ReadValueId {
                node_id: NodeId::new(ns, format!("m01ps0004.ese.{name}")),
                attribute_id: AttributeId::Value as u32,
                ..Default::default()
            }],
            TimestampsToReturn::Both,
            0.0,
        )
        .await
        .unwrap();
    read[0].value.clone().unwrap_or_default()
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

/// The agent over the simulated CNC with its alarm server: the users of
/// [`users_file`], ana an operator who may reset, not acknowledge.
async fn serving() -> Fixture {
    Fixture::start_with(|c| {
        let dir = c.journal.path.parent().unwrap().to_path_buf();
        users_file(&dir.join("opcua-users.toml"));
        // Ana may reset, not acknowledge.
        let operators = c.operators_file.clone().unwrap();
        let mut text = std::fs::read_to_string(&operators).unwrap();
        text +=
            &cellwatch::operator::OperatorKey::generate("ana").operators_entry(&[Action::Reset]);
        std::fs::write(&operators, text).unwrap();
        c.alarm_server = Some(AlarmServerConfig {
            listen: "127.0.0.1:0".parse().unwrap(),
            pki_dir: dir.join("alarm-server-pki"),
            users_file: dir.join("opcua-users.toml"),
        });
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scada_client_sees_ese_and_acknowledges_it_as_kim() {
    let fx = serving().await;
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
    // Its state is in variables too, for clients that browse and read.
    let children = browse(&kim, &condition).await;
    for name in ["ActiveState", "AckedState", "Retain", "Message", "Culprits"] {
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

    // Kim acknowledges: Good once the cell loop took it.
    assert_eq!(
        acknowledge(&kim, &condition, &event_id).await,
        StatusCode::Good
    );
    let acked = event_until(&mut events, "ESE acknowledged", |e| {
        e[CONDITION_NAME] == Variant::from("ese") && e[ACKED] == Variant::from(true)
    })
    .await;
    assert_eq!(acked[CLIENT_USER], Variant::from("kim"));
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_opcua_scada_acknowledges_and_shelves_ese_and_finds_it_after_a_restart() {
    let fx = serving().await;
    let addr = fx.agent().alarm_server_addr().unwrap();
    let url = format!("opc.tcp://127.0.0.1:{}", addr.port());
    let mut scada = ScadaProgram::connected(
        &url,
        &fx.dir().join("node-scada-pki"),
        &fx.dir().join("alarm-server-pki"),
        "scada-kim",
    );

    // The SCADA's session is counted.
    let line = "cellwatch_alarm_server_sessions{cell=\"m01ps0004\"} ";
    let scraped = fx.scrape().await;
    assert!(
        scraped.lines().any(|l| l == format!("{line}1")),
        "{scraped}"
    );
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let raised = scada.event("ESE raised", |e| {
        e["conditionName"] == "ese" && e["active"] == true
    });
    assert_eq!(raised["sourceName"], "m01ps0004");
    assert_eq!(raised["acked"], false);
    assert_eq!(raised["retain"], true);
    assert!(
        raised["message"].as_str().unwrap().contains("X0.06"),
        "{raised}"
    );
    assert!(
        raised["culprits"]
            .as_str()
            .unwrap()
            .contains("X0.06 = 0 (expected 1)"),
        "{raised}"
    );
    assert!(
        raised["eventType"]
            .as_str()
            .unwrap()
            .ends_with(";s=CellAlarmType"),
        "{raised}"
    );
    let severity = raised["severity"].as_u64().unwrap();
    assert!([250, 500, 750, 1000].contains(&severity), "{raised}");
    let condition = raised["conditionId"].as_str().unwrap().to_string();
    let event_id = raised["eventId"].as_str().unwrap().to_string();

    // An old event id is refused; the latest is taken, with the comment.
    assert_eq!(
        scada.ask(&format!("ack {condition} 00ff nothing"), "ack "),
        "BadEventIdUnknown"
    );
    assert_eq!(
        scada.ask(
            &format!("ack {condition} {event_id} seen on WinCC, tool changed"),
            "ack "
        ),
        "Good"
    );
    let acked = scada.event("ESE acknowledged", |e| {
        e["conditionName"] == "ese" && e["acked"] == true
    });
    assert_eq!(acked["clientUserId"], "kim");
    assert_eq!(acked["comment"], "seen on WinCC, tool changed");
    assert_eq!(acked["active"], true);
    assert_eq!(acked["suppressedOrShelved"], false);
    assert_eq!(
        scada.ask(
            &format!(
                "ack {condition} {} again",
                acked["eventId"].as_str().unwrap()
            ),
            "ack "
        ),
        "BadConditionBranchAlreadyAcked"
    );

    // A refresh: ESE between the refresh's start (i=2787) and end (i=2788).
    assert_eq!(scada.ask("refresh", "refresh "), "Good");
    let is = |e: &serde_json::Value, id: &str| {
        e["eventType"] == format!("ns=0;{id}") || e["eventType"] == id
    };
    scada.event("the refresh's start", |e| is(e, "i=2787"));
    let mut retained = Vec::new();
    loop {
        let e = scada.event("the refresh's end", |_| true);
        if is(&e, "i=2788") {
            break;
        }
        retained.push((
            e["conditionName"].clone(),
            e["active"].clone(),
            e["acked"].clone(),
        ));
    }
    assert_eq!(
        retained,
        [(
            serde_json::json!("ese"),
            serde_json::json!(true),
            serde_json::json!(true)
        )]
    );
    // Journaled with kim's comment, before the answer.
    commands_journaled(
        &fx,
        &[(
            true,
            "kim",
            "ack ese by kim: seen on WinCC, tool changed",
            "opcua user scada-kim",
        )],
    )
    .await;

    // Shelved by an operator on the bus: the SCADA sees it shelved, then
    // back.
    let (ok, detail) = kim_says(&fx, Action::Shelve).await;
    assert!(ok, "{detail}");
    scada.event("ESE shelved", |e| {
        e["conditionName"] == "ese" && e["suppressedOrShelved"] == true
    });
    let (ok, detail) = kim_says(&fx, Action::Unshelve).await;
    assert!(ok, "{detail}");
    scada.event("ESE unshelved", |e| {
        e["conditionName"] == "ese" && e["suppressedOrShelved"] == false
    });

    // Shelved from the SCADA, through its ShelvingState's methods, as kim.
    let shelving = format!("{condition}.ShelvingState");
    let call = |method: &str, ms: Option<u64>| {
        let ms = ms.map_or(String::new(), |ms| format!(" {ms}"));
        format!("call {shelving} {method}{ms}")
    };
    let (timed, one_shot, unshelve) = ("i=2949", "i=2948", "i=2947");
    // 30 days: longer than commands.max_shelve (8 h unless set).
    assert_eq!(
        scada.ask(&call(timed, Some(30 * 24 * 3_600_000)), "call "),
        "BadShelvingTimeOutOfRange"
    );
    assert_eq!(scada.ask(&call(timed, Some(600_000)), "call "), "Good");
    let shelved = scada.event("ESE shelved from the SCADA", |e| {
        e["conditionName"] == "ese" && e["shelving"] == "ns=0;i=2932"
    });
    assert_eq!(shelved["suppressedOrShelved"], true);
    assert_eq!(
        scada.ask(&call(one_shot, None), "call "),
        "BadConditionAlreadyShelved"
    );
    assert_eq!(scada.ask(&call(unshelve, None), "call "), "Good");
    scada.event("ESE unshelved from the SCADA", |e| {
        e["conditionName"] == "ese" && e["shelving"] == "ns=0;i=2930"
    });
    assert_eq!(
        scada.ask(&call(unshelve, None), "call "),
        "BadConditionNotShelved"
    );
    assert_eq!(scada.ask(&call(one_shot, None), "call "), "Good");
    scada.event("ESE shelved once from the SCADA", |e| {
        e["conditionName"] == "ese" && e["shelving"] == "ns=0;i=2933"
    });
    let shelves: Vec<(String, String)> = fx
        .history_rows("cellwatch/m01ps0004/history?since=1h;kind=command")
        .await
        .iter()
        .filter(|r| r["fields"]["source"] == "opcua user scada-kim")
        .map(|r| {
            let f = |k: &str| r["fields"][k].as_str().unwrap_or_default().to_string();
            (f("action"), f("detail"))
        })
        .collect();
    assert_eq!(
        shelves[1..],
        [
            (
                "shelve".into(),
                "shelve for 2592000000ms: at most 8h on this cell".into()
            ),
            ("shelve".into(), "shelve ese by kim".into()),
            ("unshelve".into(), "unshelve ese by kim".into()),
            ("shelve".into(), "shelve ese by kim".into()),
        ]
    );

    // The agent restarts: ESE, restored from the journal, is on its alarm
    // server again for a SCADA that refreshes, active and acknowledged by
    // kim, with her comment.
    drop(scada);
    let config = fx.config().clone();
    let mut fx = fx;
    fx.stop().await;
    let again = cellwatch::agent::start(config, None).await.unwrap();
    let url = format!("opc.tcp://{}", again.alarm_server_addr().unwrap());
    let (scada_pki, server_pki) = (
        fx.dir().join("node-scada-pki"),
        fx.dir().join("alarm-server-pki"),
    );
    let mut scada = tokio::task::spawn_blocking(move || {
        ScadaProgram::connected(&url, &scada_pki, &server_pki, "scada-kim")
    })
    .await
    .unwrap();
    assert_eq!(scada.ask("refresh", "refresh "), "Good");
    let restored = scada.event("ESE after the restart", |e| e["conditionName"] == "ese");
    assert_eq!(
        (
            &restored["active"],
            &restored["acked"],
            &restored["clientUserId"],
            &restored["comment"]
        ),
        (
            &serde_json::json!(true),
            &serde_json::json!(true),
            &serde_json::json!("kim"),
            &serde_json::json!("seen on WinCC, tool changed")
        )
    );
    drop(scada);
    again.stop().await;
}

/// A reload (SIGHUP, `cellwatch reload`) reads the alarm server's users
/// and the operators again: a session already open acknowledges as the
/// operator its user acts as now, and an operator taken out of the file
/// is refused at once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reload_reads_the_users_and_the_operators_again() {
    let mut fx = serving().await;
    let url = format!("opc.tcp://{}", fx.agent().alarm_server_addr().unwrap());
    let mut scada = ScadaProgram::connected(
        &url,
        &fx.dir().join("node-scada-pki"),
        &fx.dir().join("alarm-server-pki"),
        "scada-lee",
    );
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let raised = scada.event("ESE raised", |e| {
        e["conditionName"] == "ese" && e["active"] == true
    });
    let ack = format!(
        "ack {} {} seen",
        raised["conditionId"].as_str().unwrap(),
        raised["eventId"].as_str().unwrap()
    );
    // scada-lee acts as lee, whom the operators file does not name.
    assert_eq!(scada.ask(&ack, "ack "), "BadUserAccessDenied");

    // Lee's account now acts as kim: read again, the open session's
    // acknowledgement is kim's.
    let users = fx.dir().join("opcua-users.toml");
    let text = std::fs::read_to_string(&users).unwrap();
    let changed = text.replacen("operator = \"lee\"", "operator = \"kim\"", 1);
    assert_ne!(text, changed);
    std::fs::write(&users, changed).unwrap();
    let config = fx.config().clone();
    fx.agent.as_mut().unwrap().reload(&config).await.unwrap();
    // (The reload carries ESE over to the checks read again: a new event,
    // whose id an acknowledgement names.)
    assert_eq!(scada.ask("refresh", "refresh "), "Good");
    scada.event("the refresh's start", |e| {
        e["eventType"] == "ns=0;i=2787" || e["eventType"] == "i=2787"
    });
    let latest = scada.event("ESE, refreshed", |e| e["conditionName"] == "ese");
    let ack = format!(
        "ack {} {} seen",
        latest["conditionId"].as_str().unwrap(),
        latest["eventId"].as_str().unwrap()
    );
    assert_eq!(scada.ask(&ack, "ack "), "Good");
    let acked = scada.event("ESE acknowledged", |e| {
        e["conditionName"] == "ese" && e["acked"] == true
    });
    assert_eq!(acked["clientUserId"], "kim");

    // Kim taken out of the operators file: read again, her signed
    // command is refused.
    let operators = config.operators_file.clone().unwrap();
    let text = std::fs::read_to_string(&operators).unwrap();
    let without_kim: String = text
        .split_inclusive('\n')
        .scan(false, |in_kim, line| {
            if line.starts_with("[operators.") {
                *in_kim = line.starts_with("[operators.kim]");
            }
            Some(if *in_kim { "" } else { line })
        })
        .collect();
    assert!(!without_kim.contains("[operators.kim]") && without_kim.contains("[operators.ana]"));
    std::fs::write(&operators, without_kim).unwrap();
    let (ok, detail) = kim_says(&fx, Action::Shelve).await;
    assert!(ok, "kim may shelve before the reload: {detail}");
    fx.agent.as_mut().unwrap().reload(&config).await.unwrap();
    let (ok, detail) = kim_says(&fx, Action::Unshelve).await;
    assert!(!ok && detail.contains("unknown operator 'kim'"), "{detail}");
    // A users file that does not read is refused; the running users go on.
    std::fs::write(&users, "[users.x]\n").unwrap();
    let refused = fx
        .agent
        .as_mut()
        .unwrap()
        .reload(&config)
        .await
        .unwrap_err();
    assert!(
        refused
            .to_string()
            .contains("missing field `password_hash`"),
        "{refused}"
    );
}
