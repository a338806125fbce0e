//! OPC UA reverse connect (`opcua.reverse_listen`): the server dials out
//! to the agent, as a PLC behind a firewall or in a DMZ does; the agent
//! never dials it. The same security as a dialled connection
//! (Basic256Sha256, SignAndEncrypt, the server's certificate trusted).

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::agent::{alarm_until, Fixture};
use crate::liveness::{relay_with_cut, Cut};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_server_that_dials_out_is_monitored_over_its_connection_and_diagnosed() {
    crate::network_cut::logs();
    let mut fx = Fixture::start_with(|config| {
        let ua = config.opcua.as_mut().unwrap();
        ua.reverse_listen = Some("127.0.0.1:0".parse().unwrap());
    })
    .await;
    let listening = fx.agent().source_listening().expect("bound at start");
    assert_ne!(listening.port(), 0);
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    let mut seen = Vec::new();
    // The server can be dialled, but the agent waits for it to call:
    // after 10 s without a call, it says so.
    alarm_until(&sub, "the agent waiting for the server", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() == "raised"
    })
    .await;
    let (code, ready) = crate::util::http_get(fx.agent().metrics_addr().unwrap(), "/readyz").await;
    assert_eq!(code, 503, "{ready}");
    assert!(
        ready.contains(&format!("it must dial {listening} (opcua.reverse_listen")),
        "{ready}"
    );
    // The PLC dials out (through a link that can be cut): connected over
    // its connection, values flow.
    let cut = Cut::default();
    let link = relay_with_cut(listening, Arc::new(AtomicBool::new(false)), cut.clone()).await;
    fx.sim.reverse_connect(link);
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let raised = alarm_until(&sub, "ESE over the reverse connection", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(raised.culprits[0].address, "X0.06", "{raised:?}");
    fx.sim.set("X0.06", true).unwrap();
    alarm_until(&sub, "ESE cleared", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "cleared"
    })
    .await;
    // The link is cut; the switch opens meanwhile. Once the PLC has
    // dialled again, the change it kept arrives and is diagnosed.
    cut.set(true);
    alarm_until(&sub, "the connection lost", &mut seen, |a| {
        a.id == "communication" && a.message.starts_with("communication lost")
    })
    .await;
    fx.sim.set("X0.04", false).unwrap();
    cut.set(false);
    let raised = alarm_until(&sub, "ESE after the server dialled again", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(raised.culprits[0].address, "X0.04", "{raised:?}");
    assert!(raised.culprits[0].trigger, "{raised:?}");
    fx.stop().await;
    fx.sim.stop();
}
