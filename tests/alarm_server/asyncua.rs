//! The alarm server with Python asyncua's client as the SCADA
//! (`tests/interop/scada.py`), subscribed as that library does by default:
//! `subscribe_events(Server, AlarmConditionType)`, whose where clause is
//! `EventType InList [AlarmConditionType and every subtype]` of NodeIds
//! (`CellAlarmType` among them, browsed from the server).

use super::{commands_journaled, serving, ScadaProgram};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_asyncuas_default_alarm_subscription_sees_refreshes_and_acknowledges_ese() {
    let fx = serving().await;
    let url = format!("opc.tcp://{}", fx.agent().alarm_server_addr().unwrap());
    let mut scada = ScadaProgram::asyncua_connected(
        &url,
        &fx.dir().join("asyncua-scada-pki"),
        &fx.dir().join("alarm-server-pki"),
        "scada-kim",
    );
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();

    // Raised: the where clause takes CellAlarmType's NodeId.
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
        raised["eventType"]
            .as_str()
            .unwrap()
            .ends_with(";s=CellAlarmType"),
        "{raised}"
    );
    let condition = raised["conditionId"].as_str().unwrap().to_string();
    let event_id = raised["eventId"].as_str().unwrap().to_string();

    // Acknowledged with a comment, which reaches the cell loop and the
    // journal, and comes back in the condition's event.
    assert_eq!(
        scada.ask(
            &format!("ack {condition} {event_id} seen on the asyncua SCADA"),
            "ack "
        ),
        "Good"
    );
    let acked = scada.event("ESE acknowledged", |e| {
        e["conditionName"] == "ese" && e["acked"] == true
    });
    assert_eq!(acked["clientUserId"], "kim");
    assert_eq!(acked["comment"], "seen on the asyncua SCADA");
    assert_eq!(acked["active"], true);
    commands_journaled(
        &fx,
        &[(
            true,
            "kim",
            "ack ese by kim: seen on the asyncua SCADA",
            "opcua user scada-kim",
        )],
    )
    .await;

    // A refresh: its start and end pass the where clause (which names no
    // refresh event type), ESE between them.
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

    // Cleared: back to normal, no longer retained.
    fx.sim.set("X0.06", true).unwrap();
    let cleared = scada.event("ESE cleared", |e| {
        e["conditionName"] == "ese" && e["active"] == false
    });
    assert_eq!(
        (&cleared["acked"], &cleared["retain"]),
        (&serde_json::json!(true), &serde_json::json!(false))
    );
}
