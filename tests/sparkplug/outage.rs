//! Nothing is lost while the node cannot publish. The broker killed and
//! started again on its port: the changes made meanwhile arrive after the
//! next births, in order, flagged historical, the sequence without a gap,
//! the new session with the next bdSeq. The agent killed while holding
//! changes (its primary host offline): started again, it is born with the
//! bdSeq after the killed session's and the held changes follow as
//! history.

use std::collections::HashMap;
use std::io::Write;
use std::time::Duration;

use serde_json::json;

use super::{
    edge_node, historical, metrics, named, no_gaps, topic, until_scraped, Broker, Host, CRITICAL,
};

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn changes_made_while_the_broker_is_down_arrive_in_order_as_history() {
    let d = tempfile::tempdir().unwrap();
    let port = crate::util::restartable_port();
    let broker = Broker::start(d.path(), port).await;
    let mut host = Host::start(&broker).await;
    let (sim, mut cell) = edge_node(d.path(), &broker, "").await;
    let mut agent = cell.spawn("agent.log").await;
    let metrics_port = cell.metrics_port;
    let nbirth = host.message("NBIRTH", |_| true).await;
    let bd_seq = named(&nbirth, "bdSeq")["value"].as_u64().unwrap();
    let dbirth = host.message("DBIRTH", |_| true).await;
    let active = named(&dbirth, "Alarms/ese/Active")["alias"].clone();
    assert_eq!(named(&dbirth, "Alarms/ese/Active")["value"], false);

    // The broker goes away; the node sees it.
    drop(broker);
    until_scraped(metrics_port, "cellwatch_sparkplug_connected", |v| v == 0.0).await;
    // ESE raised, then cleared, while nobody listens: both held.
    sim.set("X0.06", false).unwrap();
    until_scraped(metrics_port, CRITICAL, |v| v == 1.0).await;
    sim.set("X0.06", true).unwrap();
    until_scraped(metrics_port, CRITICAL, |v| v == 0.0).await;
    let held = until_scraped(metrics_port, "cellwatch_sparkplug_held{", |v| v >= 2.0).await;

    // The broker back on its port: the host and the node come back; births
    // with the current values, then the held changes as history, in order.
    let broker = Broker::start(d.path(), port).await;
    host.until("the host subscribed again", |v| v["subscribed"] == true)
        .await;
    let seen = host.seen.len();
    let nbirth = host.message("NBIRTH", |_| true).await;
    let again = named(&nbirth, "bdSeq")["value"].as_u64().unwrap();
    assert_ne!(again, bd_seq, "a new session has a new bdSeq");
    let dbirth = host.message("DBIRTH", |_| true).await;
    assert_eq!(named(&dbirth, "Alarms/ese/Active")["value"], false);
    host.message("DDATA", |p| {
        metrics(p)
            .iter()
            .any(|m| m["alias"] == active && m["value"] == false && m["isHistorical"] == true)
    })
    .await;
    let after = &host.seen[seen..];
    let history = historical(after, &active);
    assert_eq!(
        history.iter().map(|(v, _)| *v).collect::<Vec<_>>(),
        [true, false],
        "{after:#?}"
    );
    assert!(history[0].1 <= history[1].1, "{history:?}");
    // Every historical metric comes before the first live one, each
    // metric's oldest first.
    let mut last: HashMap<u64, u64> = HashMap::new();
    let mut live = false;
    for m in after
        .iter()
        .filter(|m| m["topic"] == topic("DDATA").as_str())
    {
        for x in metrics(&m["payload"]) {
            if x["isHistorical"] == true {
                assert!(!live, "history after live data: {after:#?}");
                let at = x["timestamp"].as_u64().unwrap();
                let before = last.insert(x["alias"].as_u64().unwrap(), at);
                assert!(before <= Some(at), "history out of order: {after:#?}");
            } else {
                live = true;
            }
        }
    }
    no_gaps(&host.seen);
    until_scraped(metrics_port, "cellwatch_sparkplug_held{", |v| v == 0.0).await;
    assert!(held >= 2.0);
    agent.kill().unwrap();
    agent.wait().unwrap();
    drop((sim, broker));
}

/// How many changes of the ESE's `Active` the store beside the journal in
/// `dir` holds.
fn stored(dir: &std::path::Path) -> i64 {
    let store = dir.join("journal.sqlite.sparkplug");
    if !store.exists() {
        return 0;
    }
    let db =
        rusqlite::Connection::open_with_flags(&store, rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
            .unwrap();
    db.busy_timeout(Duration::from_secs(5)).unwrap();
    db.query_row(
        "SELECT count(*) FROM held WHERE metric = 'Alarms/ese/Active'",
        [],
        |r| r.get(0),
    )
    .unwrap_or(0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn changes_held_by_a_killed_agent_arrive_after_its_restart() {
    let d = tempfile::tempdir().unwrap();
    let broker = Broker::start(d.path(), crate::util::restartable_port()).await;
    let mut host = Host::start(&broker).await;
    let state = |online: bool, timestamp: u64| {
        json!({ "topic": "spBv1.0/STATE/scada", "retain": true,
                "text": json!({ "online": online, "timestamp": timestamp }).to_string() })
    };
    writeln!(host.stdin, "{}", state(false, 1)).unwrap();
    host.until("the host said it is offline", |v| {
        v["published"] == "spBv1.0/STATE/scada"
    })
    .await;
    let (sim, mut cell) = edge_node(d.path(), &broker, "primary_host = \"scada\"\n").await;
    let mut agent = cell.spawn("agent.log").await;
    until_scraped(cell.metrics_port, "cellwatch_sparkplug_connected", |v| {
        v == 1.0
    })
    .await;

    // ESE raised while the host is offline: held, on disk.
    sim.set("X0.06", false).unwrap();
    until_scraped(cell.metrics_port, CRITICAL, |v| v == 1.0).await;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(90);
    while stored(&cell.dir) < 1 {
        assert!(tokio::time::Instant::now() < deadline, "never stored");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }

    // Killed: the broker says its will.
    agent.kill().unwrap();
    agent.wait().unwrap();
    let death = host.message("NDEATH", |_| true).await;

    // A backup of the journal takes the held changes with it.
    let dest = cell.dir.join("backup.sqlite");
    let run = crate::util::cellwatch(&[
        "journal",
        "backup",
        cell.dir.join("journal.sqlite").to_str().unwrap(),
        dest.to_str().unwrap(),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert!(run.stdout.contains("held changes"), "{}", run.stdout);
    let copy = rusqlite::Connection::open(cell.dir.join("backup.sqlite.sparkplug")).unwrap();
    let copied: i64 = copy
        .query_row(
            "SELECT count(*) FROM held WHERE metric = 'Alarms/ese/Active'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(copied, stored(&cell.dir));
    assert!(copied >= 1);
    let bd_seq = named(&death, "bdSeq")["value"].as_u64().unwrap();
    assert!(
        host.seen
            .iter()
            .all(|m| !m["topic"].as_str().unwrap().contains("BIRTH")),
        "born while the host was offline: {:#?}",
        host.seen
    );

    // The host online, the agent started again: born with the next bdSeq,
    // and the raise held by the killed agent arrives as history.
    writeln!(host.stdin, "{}", state(true, 2)).unwrap();
    host.until("the host said it is online", |v| {
        v["published"] == "spBv1.0/STATE/scada"
    })
    .await;
    let mut agent = cell.spawn("agent-again.log").await;
    let nbirth = host.message("NBIRTH", |_| true).await;
    assert_eq!(
        named(&nbirth, "bdSeq")["value"],
        (bd_seq + 1) % 256,
        "bdSeq goes on across a restart: {nbirth:#}"
    );
    let dbirth = host.message("DBIRTH", |_| true).await;
    let active = named(&dbirth, "Alarms/ese/Active")["alias"].clone();
    let seen = host.seen.len() - 2;
    host.message("DDATA", |p| {
        metrics(p)
            .iter()
            .any(|m| m["alias"] == active && m["value"] == true && m["isHistorical"] == true)
    })
    .await;
    let history = historical(&host.seen[seen..], &active);
    assert_eq!(history.first().map(|(v, _)| *v), Some(true), "{history:?}");
    let born = nbirth["timestamp"].as_u64().unwrap();
    assert!(
        history[0].1 < born,
        "the held raise is older than the new birth: {history:?}"
    );
    no_gaps(&host.seen);
    until_scraped(cell.metrics_port, "cellwatch_sparkplug_held{", |v| v == 0.0).await;
    assert_eq!(stored(&cell.dir), 0);
    agent.kill().unwrap();
    agent.wait().unwrap();
    drop(sim);
}
