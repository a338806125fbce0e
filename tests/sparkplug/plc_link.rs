//! The device lives while the cell's PLC link is up (Sparkplug B 3.0: a
//! device gone offline has its DDEATH, and a fresh DBIRTH when it is
//! back). The link lost: the machine state `offline` as DDATA, then DDEATH
//! with the next sequence number; while it is dead, a change (an alarm the
//! device had not declared) sends no DDATA and no rebirth, only held; the
//! link back: DBIRTH on the same session with every current value (the
//! alarm among them), the held change as history after it, the sequence
//! without a gap.

use serde_json::Value;

use super::{
    contact, current, metrics, named, no_gaps, scripted_node, topic, until_scraped, Broker, Host,
    RUN,
};
use cellwatch::sources::SourceEvent;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_device_dies_with_its_plc_link_and_is_born_again_when_it_is_back() {
    let d = tempfile::tempdir().unwrap();
    let broker = Broker::start(d.path(), crate::util::restartable_port()).await;
    let mut host = Host::start(&broker).await;
    let clock = cellwatch::clock::Clock::system();
    let (agent, script) = scripted_node(d.path(), &broker, "", &clock).await;
    let port = agent.metrics_addr().unwrap().port();
    host.message("NBIRTH", |_| true).await;
    let dbirth = host.message("DBIRTH", |_| true).await;
    let state = named(&dbirth, "Machine/State")["alias"].clone();

    // The PLC connected, the machine running.
    script
        .send(SourceEvent::Connected("scripted".into()))
        .await
        .unwrap();
    script
        .send(contact(RUN, true, clock.now_ms()))
        .await
        .unwrap();
    host.message("DDATA", |p| {
        metrics(p)
            .iter()
            .any(|m| m["alias"] == state && m["value"] == "running")
    })
    .await;

    // The link lost: `offline` first, then the device's death.
    script
        .send(SourceEvent::Disconnected("cable pulled".into()))
        .await
        .unwrap();
    let ddeath = host.message("DDEATH", |_| true).await;
    assert!(ddeath["seq"].is_u64(), "{ddeath:#}");
    assert!(metrics(&ddeath).is_empty(), "{ddeath:#}");
    let died = host.seen.len();
    assert_eq!(current(&host.seen)["Machine/State"], "offline");

    // While it is dead: an alarm it had not declared is raised, and held.
    script
        .send(SourceEvent::Problem {
            id: "opcua-namespace".into(),
            problem: Some("urn:cellwatch:test is missing".into()),
        })
        .await
        .unwrap();
    until_scraped(
        port,
        "cellwatch_alarms_active{cell=\"m01ps0004\",kind=\"system\",severity=\"high\"}",
        |v| v == 1.0,
    )
    .await;
    until_scraped(port, "cellwatch_sparkplug_held{", |v| v >= 1.0).await;

    // The link back: DBIRTH on the same session, with the alarm; then the
    // held change as history.
    script
        .send(SourceEvent::Connected("scripted".into()))
        .await
        .unwrap();
    let reborn = host.message("DBIRTH", |_| true).await;
    assert_eq!(
        named(&reborn, "Alarms/opcua-namespace/Active")["value"],
        true
    );
    let active = named(&reborn, "Alarms/opcua-namespace/Active")["alias"].clone();
    host.message("DDATA", |p| {
        metrics(p)
            .iter()
            .any(|m| m["alias"] == active && m["value"] == true && m["isHistorical"] == true)
    })
    .await;
    let between: Vec<&Value> = host.seen[died..]
        .iter()
        .take_while(|m| m["topic"] != topic("DBIRTH").as_str())
        .collect();
    assert!(
        between.is_empty(),
        "nothing between DDEATH and DBIRTH: {between:#?}"
    );
    assert!(
        !host
            .seen
            .iter()
            .skip(2)
            .any(|m| m["topic"] == topic("NBIRTH").as_str()),
        "the same session, no rebirth of the node"
    );
    no_gaps(&host.seen);
    let scrape = crate::spawned::scrape(port);
    assert!(
        scrape
            .lines()
            .any(|l| l.starts_with("cellwatch_sparkplug_messages_total")
                && l.contains("kind=\"ddeath\"")
                && l.contains("result=\"published\"")
                && l.ends_with(" 1")),
        "{scrape}"
    );
    agent.stop().await;
}
