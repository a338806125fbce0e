//! With a primary host: nothing is published while its `STATE` says
//! offline; once online, the births carry the current values and what was
//! held follows, flagged historical. Offline again (a newer `STATE`), the
//! node says its NDEATH and disconnects, connects again with the next
//! bdSeq and waits; a stale retained online `STATE` (older than the
//! offline one) does not bring it back; a newer one does.

use std::io::Write;

use serde_json::{json, Value};

use super::{edge_node, metrics, named, no_gaps, scraped, until_scraped, Broker, Host, CRITICAL};

/// The retained `STATE` of host `scada`: `online` at `timestamp`.
fn state(online: bool, timestamp: u64) -> Value {
    json!({ "topic": "spBv1.0/STATE/scada", "retain": true,
            "text": json!({ "online": online, "timestamp": timestamp }).to_string() })
}

/// Publishes `state` as the host and waits until the broker took it.
async fn say(host: &mut Host, state: Value) {
    writeln!(host.stdin, "{state}").unwrap();
    host.until("the host published its STATE", |v| {
        v["published"] == "spBv1.0/STATE/scada"
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_node_follows_its_primary_hosts_state_and_ignores_a_stale_one() {
    let d = tempfile::tempdir().unwrap();
    let broker = Broker::start(d.path(), crate::util::restartable_port()).await;
    let mut host = Host::start(&broker).await;
    say(&mut host, state(false, 1)).await;
    let (sim, mut cell) = edge_node(d.path(), &broker, "primary_host = \"scada\"\n").await;
    let mut agent = cell.spawn("agent.log").await;
    let port = cell.metrics_port;

    // The host offline: the node is connected, holds, and publishes nothing.
    until_scraped(port, "cellwatch_sparkplug_connected", |v| v == 1.0).await;
    until_scraped(
        port,
        "cellwatch_sparkplug_primary_host_states_total{cell=\"m01ps0004\",state=\"offline\"}",
        |v| v >= 1.0,
    )
    .await;
    // ESE raised: the metrics sink counts it, and the Sparkplug sink, which
    // takes the same step right after it with nothing to wait for, holds it.
    sim.set("X0.06", false).unwrap();
    until_scraped(port, CRITICAL, |v| v == 1.0).await;
    assert!(scraped(port, "cellwatch_sparkplug_held{") > 0.0);

    // Online: births with the current values, then what was held, flagged
    // historical.
    say(&mut host, state(true, 1)).await;
    assert!(
        host.seen.is_empty(),
        "published while the host was offline: {:#?}",
        host.seen
    );
    let nbirth = host.message("NBIRTH", |_| true).await;
    assert_eq!(nbirth["seq"], 0);
    let bd_seq = named(&nbirth, "bdSeq")["value"].as_u64().unwrap();
    let dbirth = host.message("DBIRTH", |_| true).await;
    assert_eq!(named(&dbirth, "Alarms/ese/Active")["value"], true);
    let active = named(&dbirth, "Alarms/ese/Active")["alias"].clone();
    let history = host
        .message("DDATA", |p| {
            metrics(p)
                .iter()
                .any(|m| m["alias"] == active && m["value"] == true)
        })
        .await;
    assert!(
        metrics(&history).iter().all(|m| m["isHistorical"] == true),
        "{history:#}"
    );

    // Offline, newer than the online: NDEATH with the session's bdSeq, and
    // a new session at once.
    say(&mut host, state(false, 2)).await;
    let death = host.message("NDEATH", |_| true).await;
    assert_eq!(named(&death, "bdSeq")["value"], bd_seq, "{death:#}");
    until_scraped(port, "cellwatch_sparkplug_sessions_total", |v| v >= 2.0).await;

    // A stale online (older than the offline) changes nothing: it is
    // counted as stale and no birth follows; while the node waits, the
    // alarm clears and is held.
    let seen = host.seen.len();
    say(&mut host, state(true, 1)).await;
    until_scraped(
        port,
        "cellwatch_sparkplug_primary_host_states_total{cell=\"m01ps0004\",state=\"stale\"}",
        |v| v >= 1.0,
    )
    .await;
    sim.set("X0.06", true).unwrap();
    until_scraped(port, CRITICAL, |v| v == 0.0).await;
    assert!(
        host.seen[seen..].is_empty(),
        "published after a stale STATE: {:#?}",
        &host.seen[seen..]
    );

    // Online, newer: born again with the next bdSeq, the clear as history.
    say(&mut host, state(true, 3)).await;
    let nbirth = host.message("NBIRTH", |_| true).await;
    assert_eq!(
        named(&nbirth, "bdSeq")["value"],
        (bd_seq + 1) % 256,
        "{nbirth:#}"
    );
    let dbirth = host.message("DBIRTH", |_| true).await;
    assert_eq!(named(&dbirth, "Alarms/ese/Active")["value"], false);
    let cleared = host
        .message("DDATA", |p| {
            metrics(p)
                .iter()
                .any(|m| m["alias"] == active && m["value"] == false)
        })
        .await;
    assert!(
        metrics(&cleared).iter().all(|m| m["isHistorical"] == true),
        "{cleared:#}"
    );
    no_gaps(&host.seen);
    agent.kill().unwrap();
    agent.wait().unwrap();
    drop(sim);
}
