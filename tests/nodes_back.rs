//! A node that disappears and comes back (a PLC download that recreates a
//! data block, a server whose configuration changed), with the session and
//! subscription kept: a server that says so (`BadNodeIdUnknown`), and one
//! that says nothing, whose old monitored items never hear of the node
//! again, and one that says it has no data and then nothing. The item is
//! created again without a reconnect, the tag bad in between; a silent
//! server is caught by the periodic verification.

use std::time::Duration;

use cellwatch::config::TagConfig;
use cellwatch::sim::cnc::NAMESPACE;
use cellwatch::sources::SourceEvent;
use cellwatch_models::engine::Reading;
use cellwatch_models::signal::Signal;

use crate::liveness::{trusted_cnc, Running};
use crate::network_cut::until;
use crate::opcua::{all, has};

fn tag(address: &str) -> TagConfig {
    TagConfig::boolean(
        &address.to_lowercase(),
        &format!("nsu={NAMESPACE};s={address}"),
        Signal::new(address),
    )
}

/// The source reading X0.06 (tag 0) and X0.04 (tag 1) of a simulated CNC,
/// verifying its items every second, connected.
async fn watching(dir: &std::path::Path) -> (cellwatch::sim::cnc::SimulatedCnc, Running) {
    crate::network_cut::logs();
    let (sim, mut config, _) = trusted_cnc(dir).await;
    config.verify_interval = Duration::from_secs(1);
    let mut source = Running::start(config, vec![tag("X0.06"), tag("X0.04")]);
    all(
        &mut source.rx,
        "connection and initial values",
        &[
            &|e| matches!(e, SourceEvent::Connected(_)),
            &|e| has(e, 0, Reading::Good(true)),
            &|e| has(e, 1, Reading::Good(true)),
        ],
    )
    .await;
    (sim, source)
}

fn reconnected(events: &[SourceEvent]) -> bool {
    events
        .iter()
        .any(|e| matches!(e, SourceEvent::Disconnected(_) | SourceEvent::Connected(_)))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_the_server_deletes_and_adds_back_is_monitored_again_without_a_reconnect() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut source) = watching(dir.path()).await;
    // The server says so, and the old item never hears of the node again.
    sim.delete("X0.04").unwrap();
    let mut seen = until(&mut source, "X0.04 bad", |e| has(e, 1, Reading::Bad)).await;
    sim.set("X0.04", false).unwrap();
    sim.restore("X0.04").unwrap();
    seen.extend(
        until(&mut source, "X0.04 = 0 from a new item", |e| {
            has(e, 1, Reading::Good(false))
        })
        .await,
    );
    // And it is followed from then on.
    sim.set("X0.04", true).unwrap();
    seen.extend(until(&mut source, "X0.04 = 1", |e| has(e, 1, Reading::Good(true))).await);
    assert!(!reconnected(&seen), "{seen:?}");
    assert_eq!(sim.subscriptions(), 1);
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_recreated_in_silence_is_found_by_the_verification_and_its_loss_said() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut source) = watching(dir.path()).await;
    // The node is recreated and changes; its old item hears nothing.
    sim.recreate_quietly("X0.04").unwrap();
    sim.set("X0.04", false).unwrap();
    let seen = until(&mut source, "X0.04 = 0", |e| {
        has(e, 1, Reading::Good(false))
    })
    .await;
    let gap = seen
        .iter()
        .position(|e| matches!(e, SourceEvent::Gap { tags: Some(t), .. } if t == &[1]))
        .unwrap_or_else(|| panic!("no gap said for X0.04: {seen:?}"));
    let SourceEvent::Gap { why, .. } = &seen[gap] else {
        unreachable!()
    };
    assert!(why.contains("s=X0.04"), "{why}");
    // Before the value the new item says.
    assert_eq!(gap, seen.len() - 2, "{seen:?}");
    assert!(!reconnected(&seen), "{seen:?}");
    // The new item follows the node.
    sim.set("X0.04", true).unwrap();
    let seen = until(&mut source, "X0.04 = 1", |e| has(e, 1, Reading::Good(true))).await;
    assert!(!reconnected(&seen), "{seen:?}");
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_gone_in_silence_makes_its_tag_bad_until_it_is_back() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut source) = watching(dir.path()).await;
    sim.delete_quietly("X0.04").unwrap();
    let mut seen = until(&mut source, "X0.04 bad, found by the verification", |e| {
        has(e, 1, Reading::Bad)
    })
    .await;
    // The other tag is still read.
    sim.set("X0.06", false).unwrap();
    seen.extend(
        until(&mut source, "X0.06 = 0", |e| {
            has(e, 0, Reading::Good(false))
        })
        .await,
    );
    sim.set("X0.04", false).unwrap();
    sim.restore("X0.04").unwrap();
    seen.extend(
        until(&mut source, "X0.04 = 0 once back", |e| {
            has(e, 1, Reading::Good(false))
        })
        .await,
    );
    assert!(!reconnected(&seen), "{seen:?}");
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_item_that_says_no_data_and_then_nothing_is_created_again() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut source) = watching(dir.path()).await;
    // `GoodNoData`, and the item says nothing more, whatever the node does.
    sim.no_data("X0.04");
    let mut seen = until(&mut source, "X0.04 bad", |e| has(e, 1, Reading::Bad)).await;
    sim.set("X0.04", false).unwrap();
    seen.extend(
        until(&mut source, "X0.04 = 0 from a new item", |e| {
            has(e, 1, Reading::Good(false))
        })
        .await,
    );
    assert!(!reconnected(&seen), "{seen:?}");
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn faults_on_nodes_recreated_in_silence_are_alarmed_and_the_loss_said() {
    let mut fx = crate::agent::Fixture::start_with(|c| {
        c.opcua.as_mut().unwrap().verify_interval = Duration::from_secs(1);
    })
    .await;
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    // A download recreates the spindle's register; the old item hears
    // nothing of the 120 °C that follow (HH is 100 °C, 2 s on-delay).
    fx.sim.recreate_quietly("D100").unwrap();
    fx.sim.set_temperature(120.0).unwrap();
    let mut seen = Vec::new();
    let hh = crate::agent::alarm_until(&sub, "spindle-temp-hh raised", &mut seen, |a| {
        a.id == "spindle-temp-hh" && a.transition.as_str() == "raised"
    })
    .await;
    assert!(
        hh.message
            .starts_with("D100 (spindle_temperature) = 120 °C, above the HH limit 100 °C"),
        "{}",
        hh.message
    );
    // And the over-travel switch's contact: the emergency stop error is
    // diagnosed, but the changes its item missed may have held the
    // trigger.
    fx.sim.recreate_quietly("X0.06").unwrap();
    fx.sim.set("X0.06", false).unwrap();
    let ese = crate::agent::alarm_until(&sub, "ESE raised", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    assert_eq!(ese.culprits[0].address.as_str(), "X0.06", "{ese:?}");
    assert!(ese.culprits.iter().all(|c| !c.trigger), "{ese:?}");
    assert!(
        ese.message
            .contains("(trigger uncertain: the server stopped reporting ns=2;s=X0.06"),
        "{}",
        ese.message
    );
    let metrics = fx.scrape().await;
    assert_eq!(
        crate::network_cut::metric(&metrics, "cellwatch_source_gaps_total"),
        2.0,
        "{metrics}"
    );
    // Both followed from then on.
    fx.sim.set_temperature(20.0).unwrap();
    fx.sim.set("X0.06", true).unwrap();
    let cleared = |a: &cellwatch::payload::AlarmPayload, id: &str| {
        a.id == id && a.transition.as_str() == "cleared"
    };
    for id in ["spindle-temp-hh", "ese"] {
        if !seen.iter().any(|a| cleared(a, id)) {
            crate::agent::alarm_until(&sub, &format!("{id} cleared"), &mut seen, |a| {
                cleared(a, id)
            })
            .await;
        }
    }
    fx.stop().await;
    fx.sim.stop();
}
