//! A client reading machines the OPC UA for Machinery way reads the cell's
//! `MachineryItemState`: `Executing` while it runs, `OutOfService` in a
//! fault, the state's node in the Machinery namespace with its number.

use std::time::Duration;

use opcua::client::{IdentityToken, Session};
use opcua::types::{AttributeId, LocalizedText, NodeId, ReadValueId, TimestampsToReturn, Variant};

use super::{connect, scada, serving};

/// The value of node `node`.
async fn read(session: &Session, node: NodeId) -> Variant {
    let read = session
        .read(
            &[ReadValueId {
                node_id: node,
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

/// Reads `node` until it is `value`.
async fn read_until(session: &Session, node: &NodeId, value: &Variant, what: &str) {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let now = read(session, node.clone()).await;
        if now == *value {
            return;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "{what}: still {now:?}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_cell_says_its_state_as_a_machinery_item_state() {
    let fx = serving().await;
    let addr = fx.agent().alarm_server_addr().unwrap();
    let (server_pki, scada_pki) = (
        fx.dir().join("alarm-server-pki"),
        fx.dir().join("scada-pki"),
    );
    drop(scada(&scada_pki));
    use cellwatch::sources::pki;
    pki::trust(&pki::own_cert(&scada_pki), &server_pki).unwrap();
    pki::trust(&pki::own_cert(&server_pki), &scada_pki).unwrap();
    let session = connect(
        &format!("opc.tcp://{addr}/"),
        &scada_pki,
        IdentityToken::Anonymous,
    )
    .await;
    let ns = session
        .get_namespace_index("urn:cellwatch:alarms:m01ps0004")
        .await
        .unwrap();
    let machinery = session
        .get_namespace_index(cellwatch_models::machinery::NAMESPACE)
        .await
        .unwrap();
    let current = NodeId::new(ns, "m01ps0004.MachineryItemState.CurrentState");
    let id = NodeId::new(ns, "m01ps0004.MachineryItemState.CurrentState.Id");
    fx.settled().await;
    read_until(
        &session,
        &id,
        &Variant::from(NodeId::new(machinery, 5006u32)),
        "never Executing",
    )
    .await;
    assert_eq!(
        read(&session, current.clone()).await,
        Variant::from(LocalizedText::from("Executing"))
    );
    // The emergency stop: a fault.
    fx.sim.set("X0.06", false).unwrap();
    read_until(
        &session,
        &id,
        &Variant::from(NodeId::new(machinery, 5004u32)),
        "never OutOfService",
    )
    .await;
    assert_eq!(
        read(&session, current).await,
        Variant::from(LocalizedText::from("OutOfService"))
    );
    // The state's node says its number, as the Machinery NodeSet's does.
    assert_eq!(
        read(&session, NodeId::new(machinery, "OutOfService.StateNumber")).await,
        Variant::from(1u32)
    );
}
