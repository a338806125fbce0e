//! The whole agent against Python asyncua's server (`tests/interop/
//! asyncua_server.py`, asyncua pinned, in a virtual environment under
//! `target/`), Basic256Sha256 + SignAndEncrypt, its certificate trusted as
//! `trust-server` does, through a TCP relay that can stall: a server that
//! numbers and resends its publishes in its own way, and answers a
//! Republish of what it does not hold with an empty message, not an error.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use cellwatch::config::{self, CellConfig};
use cellwatch::sources::pki;

use crate::agent::alarm_until;
use crate::liveness::{relay_with_cut, Cut};
use crate::network_cut::metric;
use crate::stacks::{StackServer, URI};

/// The Republish requests `server` answered so far.
async fn republishes(server: StackServer) -> (StackServer, u64) {
    tokio::task::spawn_blocking(move || {
        let mut server = server;
        let n = server.ask("republishes", "republishes ").parse().unwrap();
        (server, n)
    })
    .await
    .unwrap()
}

/// A cell of two asyncua tags, each with a high limit (80) raised at once,
/// reading from `endpoint` and verifying its items every `verify`.
fn cell(dir: &Path, endpoint: &str, verify: Duration) -> CellConfig {
    let text = format!(
        r#"
[cell]
id = "m01ps0004"

[opcua]
endpoint = "{endpoint}"
pki_dir = "agent-pki"
namespace_uri = "{URI}"
publishing_interval = "100ms"
verify_interval = "{}ms"

[[tags]]
name = "oven_temperature"
node_id = "ns=2;s=Temp"
address = "D100"
type = "Double"

[[tags]]
name = "tank_level"
node_id = "ns=2;s=Level"
address = "D102"
type = "Double"

[[checks.limit]]
id = "oven"
tag = "D100"
h = {{ limit = 80.0 }}

[[checks.limit]]
id = "tank"
tag = "D102"
h = {{ limit = 80.0 }}

{}"#,
        verify.as_millis(),
        crate::robust::bus_metrics_journal(dir)
    );
    let mut c = config::parse("cell.toml", &text, dir, &config::Disk).unwrap();
    let secrets = dir.join("operators.toml");
    std::fs::write(
        &secrets,
        crate::spawned::operators_file(&cellwatch::operator::Action::ALL),
    )
    .unwrap();
    c.operators_file = Some(secrets);
    c
}

/// The sum of a counter's series whose labels hold every one of `labels`.
fn counted(metrics: &str, name: &str, labels: &[&str]) -> f64 {
    metrics
        .lines()
        .filter(|l| l.starts_with(&format!("{name}{{")))
        .filter(|l| labels.iter().all(|want| l.contains(want)))
        .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .sum()
}

/// A stall of the traffic (held both ways, nothing closed, then delivered)
/// longer than the subscription's silence allows, while the oven goes
/// over its limit and back: the excursion is raised and cleared from what
/// arrives after it, the Republish requests stay few (asyncua answers one
/// for a message it does not hold with an empty message), and a node the
/// server then deletes and adds again without a word, its value over the
/// limit, is found by the next verification.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn asyncua_server_a_stall_ends_in_few_republishes_and_a_node_recreated_in_silence_is_found() {
    crate::network_cut::logs();
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let server = tokio::task::spawn_blocking({
        let pki = dir.join("server-pki");
        move || StackServer::asyncua(0, &pki, &[("Temp", 20.0), ("Level", 50.0)])
    })
    .await
    .unwrap();
    let stall = Cut::default();
    let via = relay_with_cut(
        format!("127.0.0.1:{}", server.port).parse().unwrap(),
        Arc::new(AtomicBool::new(false)),
        stall.clone(),
    )
    .await;
    let verify = Duration::from_secs(7);
    let config = cell(dir, &format!("opc.tcp://{via}/"), verify);
    // What `cellwatch trust-server` does once the engineer said yes.
    pki::trust(&server.cert, &config.opcua.as_ref().unwrap().pki_dir).unwrap();
    let agent = cellwatch::agent::start(config, None).await.unwrap();
    let zenoh_port = crate::util::agent_port(&agent).await;
    let client = crate::util::operator_session(dir, "operator-kim", zenoh_port).await;
    let sub = crate::robust::alarms(&client, "m01ps0004").await;
    crate::spawned::snapshot_until(&client, "every tag known", |snap| {
        snap["connected"] == true
            && snap["tags"]
                .as_array()
                .unwrap()
                .iter()
                .all(|t| t["quality"] == "good")
    })
    .await;
    // Right after a verification round (its Read counted), so that none
    // is under way during the stall: the oven over its limit and back
    // while nothing passes; then the held bytes are delivered.
    let metrics_at = agent.metrics_addr().unwrap();
    let reads = || async move {
        let metrics = crate::util::scrape(metrics_at).await;
        counted(
            &metrics,
            "cellwatch_opcua_requests_total",
            &["service=\"Read\"", "result=\"good\""],
        )
    };
    let before = reads().await;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while reads().await == before {
        assert!(tokio::time::Instant::now() < deadline, "no verification");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    stall.stall(true);
    let server = server.said("set Temp 95").await;
    let server = server.said("set Temp 20").await;
    // Three keep-alive periods (1 s each at a 100 ms publishing interval)
    // and more: the subscription is silent for longer than allowed, and
    // asked for what it holds.
    tokio::time::sleep(Duration::from_secs(5)).await;
    stall.stall(false);
    let mut seen = Vec::new();
    alarm_until(&sub, "oven-h raised after the stall", &mut seen, |a| {
        a.id == "oven-h" && a.transition.as_str() == "raised"
    })
    .await;
    alarm_until(&sub, "oven-h cleared", &mut seen, |a| {
        a.id == "oven-h" && a.transition.as_str() == "cleared"
    })
    .await;
    // The tank's node deleted and added again in silence, over its limit:
    // found within a verification interval and its grace.
    let server = server.said("recreate Level 95").await;
    let found = std::time::Instant::now();
    let raised = alarm_until(&sub, "tank-h raised", &mut seen, |a| {
        a.id == "tank-h" && a.transition.as_str() == "raised"
    })
    .await;
    let took = found.elapsed();
    assert!(
        raised.message.contains("trigger uncertain"),
        "{}",
        raised.message
    );
    // A round, the grace, and a loaded machine's delays.
    assert!(took < verify + Duration::from_secs(8), "{took:?}");
    let (server, asked) = republishes(server).await;
    assert!(asked <= 16, "{asked} Republish requests");
    let metrics = crate::util::scrape(agent.metrics_addr().unwrap()).await;
    let requests = |labels: &[&str]| counted(&metrics, "cellwatch_opcua_requests_total", labels);
    // Asked during the stall, answered after it, then what it holds.
    assert!(
        requests(&["service=\"SetPublishingMode\"", "result=\"good\""]) >= 1.0,
        "{metrics}"
    );
    assert!(requests(&["service=\"Republish\""]) <= 16.0, "{metrics}");
    // The tank's item created again, after the read that found it deaf.
    for service in ["Read", "CreateMonitoredItems", "DeleteMonitoredItems"] {
        let good = [&format!("service=\"{service}\"")[..], "result=\"good\""];
        assert!(requests(&good) >= 1.0, "{service}: {metrics}");
    }
    assert!(
        metric(&metrics, "cellwatch_source_gaps_total") >= 1.0,
        "{metrics}"
    );
    agent.stop().await;
    drop(server);
}
