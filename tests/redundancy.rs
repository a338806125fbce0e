//! Non-transparent redundancy: two simulated CNCs (async-opcua, SignAndEncrypt)
//! as one cell's redundant set (`opcua.endpoint`, `opcua.redundant`). The
//! agent reads from the server with the highest `ServiceLevel`, moves to
//! the other when the one it reads degrades, and back when that one drops:
//! no process alarm, the communication alarm once for both moves.

use std::time::Duration;

use cellwatch::payload::AlarmPayload;
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};

use crate::agent::Fixture;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_agent_reads_the_best_server_of_its_set_and_moves_when_it_degrades_or_drops() {
    let b_dir = tempfile::tempdir().unwrap();
    let b = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: b_dir.path().join("sim-pki"),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    // B is the standby: healthy but below A, and its spindle reads 36 °C
    // (A's 35 °C): which server the agent reads shows in D100.
    b.set_service_level(230);
    b.set_temperature(36.0).unwrap();
    let b_pki = b_dir.path().join("sim-pki");
    let b_endpoint = b.endpoint();
    let fx = Fixture::start_with(|c| {
        c.opcua.as_mut().unwrap().redundant = vec![b_endpoint.clone()];
        crate::util::trust_sim(c, &b_pki);
    })
    .await;
    let sub = fx
        .client()
        .declare_subscriber("cellwatch/m01ps0004/alarms/**")
        .await
        .unwrap();
    fx.settled().await;
    fx.tag_value_is("D100", serde_json::json!(35.0)).await;
    // A degrades: the agent moves to B within a few seconds.
    fx.sim.set_service_level(120);
    fx.tag_value_is("D100", serde_json::json!(36.0)).await;
    fx.settled().await;
    // B drops: back to A, degraded but the only one left.
    b.stop();
    fx.tag_value_is("D100", serde_json::json!(35.0)).await;
    fx.settled().await;
    // Every alarm event so far: the communication alarm only, raised once
    // (its off-delay holds it across both moves), no process alarm.
    let mut seen: Vec<AlarmPayload> = Vec::new();
    while let Ok(Some(sample)) = tokio::time::timeout(Duration::from_millis(500), sub.recv_async())
        .await
        .map(Result::ok)
    {
        seen.push(serde_json::from_str(&crate::util::opened(sample.payload())).unwrap());
    }
    let raised: Vec<&str> = seen
        .iter()
        .filter(|a| a.transition.as_str() == "raised")
        .map(|a| a.id.as_str())
        .collect();
    assert_eq!(raised, ["communication"], "{seen:#?}");
    fx.sim.stop();
}
