//! The OPC UA source against a server nobody here wrote: node-opcua
//! (`tests/interop/server.js`, installed with `npm ci` from the committed
//! lock file on first use), Basic256Sha256 + SignAndEncrypt with mutual
//! certificate trust.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Once;
use std::time::Duration;

use cellwatch::config::TagConfig;
use cellwatch::sources::{opcua, pki, Source, SourceEvent, QUEUE_CAPACITY};
use cellwatch_models::engine::Reading;
use cellwatch_models::signal::Signal;
use futures_util::FutureExt;

use crate::liveness::Running;
use crate::network_cut::until;
use crate::opcua::{all, has, next, opcua_config};
use crate::stacks::StackServer;
use crate::util::root;

pub(crate) const URI: &str = "urn:cellwatch:test:node-opcua:plc";

/// `npm ci` in tests/interop, once per test run, unless already installed.
pub(crate) fn installed() -> PathBuf {
    static ONCE: Once = Once::new();
    let dir = root().join("tests/interop");
    ONCE.call_once(|| {
        let modules = dir.join("node_modules");
        if modules.join("node-opcua-server").exists() && modules.join("node-opcua-client").exists()
        {
            return;
        }
        let out = Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund"])
            .current_dir(&dir)
            .output()
            .expect("npm (Node.js) is needed for the interoperability tests");
        assert!(
            out.status.success(),
            "npm ci failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    });
    dir
}

/// The agent's key pair made in `agent_pki` and its certificate trusted by
/// the server of `server_pki`, before that server starts: node-opcua reads
/// its trusted folder at start, and a certificate added later is seen only
/// when its folder watch catches up (on a loaded machine, after the first
/// connection was refused).
pub(crate) fn trusted_by_server(agent_pki: &Path, server_pki: &Path) {
    let config = opcua_config("opc.tcp://127.0.0.1:1/", agent_pki);
    drop(opcua::client("test", &config).unwrap());
    let trusted = server_pki.join("trusted/certs");
    std::fs::create_dir_all(&trusted).unwrap();
    std::fs::copy(pki::own_cert(agent_pki), trusted.join("cellwatch.der")).unwrap();
}

fn tag(i: usize) -> TagConfig {
    TagConfig::boolean(
        &format!("t{i}"),
        &format!("nsu={URI};s=T{i}"),
        Signal::new(&format!("T{i}")),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn node_opcua_server_five_thousand_items_bursts_and_a_restart() {
    const TAGS: usize = 5000;
    let dir = tempfile::tempdir().unwrap();
    let server_pki = dir.path().join("server-pki");
    let port = crate::util::restartable_port();
    // Mutual trust, certificate by certificate.
    trusted_by_server(&dir.path().join("agent-pki"), &server_pki);
    let mut server = tokio::task::spawn_blocking({
        let server_pki = server_pki.clone();
        move || StackServer::node_opcua(port, &server_pki, TAGS)
    })
    .await
    .unwrap();
    let mut config = opcua_config(
        &format!("opc.tcp://127.0.0.1:{port}/"),
        &dir.path().join("agent-pki"),
    );
    config.publishing_interval = Duration::from_millis(200);
    config.sampling_interval = Duration::ZERO;
    config.queue_size = 100;
    pki::trust(&server.cert, &config.pki_dir).unwrap();
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
    let started = std::time::Instant::now();
    let mut source = Running::start(config, (0..TAGS).map(tag).collect());
    // Every tag gets its value (one publish holds thousands of them).
    let mut seen = vec![false; TAGS];
    let mut connected = false;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(120);
    while !(connected && seen.iter().all(|s| *s)) {
        let ev = tokio::time::timeout_at(deadline, source.rx.recv())
            .await
            .unwrap_or_else(|_| {
                panic!(
                    "{} of {TAGS} tags seen, connected {connected}",
                    seen.iter().filter(|s| **s).count()
                )
            })
            .unwrap();
        match ev {
            SourceEvent::Connected(_) => connected = true,
            SourceEvent::Readings(rs) => {
                for r in rs {
                    assert_eq!(r.reading, Reading::Good(true), "tag {}", r.tag);
                    seen[r.tag] = true;
                }
            }
            SourceEvent::Disconnected(why) => panic!("disconnected: {why}"),
            SourceEvent::Problem {
                problem: Some(p), ..
            } => panic!("{p}"),
            SourceEvent::Problem { .. } => {}
            SourceEvent::Gap { why, .. } => panic!("changes lost: {why}"),
            SourceEvent::Resumed => {}
            SourceEvent::Conditions(_) | SourceEvent::ConditionsHeld { .. } => {
                panic!("no PLC alarm asked for: {ev:?}")
            }
        }
    }
    eprintln!("all {TAGS} tags in {:?}", started.elapsed());
    // A contact toggled 20 times within one publishing interval: all 20.
    let server = tokio::task::spawn_blocking(move || {
        server.send("toggle T7 20");
        server
    })
    .await
    .unwrap();
    let mut changes = Vec::new();
    while changes.len() < 20 {
        let ev = tokio::time::timeout_at(deadline, source.rx.recv())
            .await
            .unwrap_or_else(|_| panic!("T7 changes: {changes:?}"))
            .unwrap();
        match ev {
            SourceEvent::Readings(rs) => {
                changes.extend(rs.iter().filter(|r| r.tag == 7).map(|r| r.reading.clone()))
            }
            SourceEvent::Problem {
                problem: Some(p), ..
            } => panic!("{p}"),
            _ => {}
        }
    }
    let expected: Vec<Reading> = (0..20).map(|i| Reading::Good(i % 2 == 1)).collect();
    assert_eq!(changes, expected);
    // The server restarts on the same port with the same certificates.
    tokio::task::spawn_blocking(move || server.stop())
        .await
        .unwrap();
    next(&mut source.rx, "connection lost", |e| {
        matches!(e, SourceEvent::Disconnected(_))
    })
    .await;
    let mut server = tokio::task::spawn_blocking({
        let server_pki = server_pki.clone();
        move || StackServer::node_opcua(port, &server_pki, TAGS)
    })
    .await
    .unwrap();
    next(&mut source.rx, "connected again", |e| {
        matches!(e, SourceEvent::Connected(_))
    })
    .await;
    server = server.said("set T42 0").await;
    next(&mut source.rx, "T42 = 0 after the restart", |e| {
        matches!(e, SourceEvent::Readings(rs) if rs.iter().any(|r| r.tag == 42 && r.reading == Reading::Good(false)))
    })
    .await;
    source.stop().await;
    tokio::task::spawn_blocking(move || server.stop())
        .await
        .unwrap();
}

/// A redundant pair of node-opcua servers: the source reads from the first
/// (both say 255), and moves to the second when the first says 120; each
/// server's T0 differs, so the value read shows the server.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn node_opcua_redundant_pair_the_source_moves_to_the_healthier_server() {
    crate::network_cut::logs();
    let dir = tempfile::tempdir().unwrap();
    let agent_pki = dir.path().join("agent-pki");
    let (a_pki, b_pki) = (dir.path().join("a-pki"), dir.path().join("b-pki"));
    let (a_port, b_port) = (
        crate::util::restartable_port(),
        crate::util::restartable_port(),
    );
    trusted_by_server(&agent_pki, &a_pki);
    trusted_by_server(&agent_pki, &b_pki);
    let start = |port: u16, pki: PathBuf| {
        tokio::task::spawn_blocking(move || StackServer::node_opcua(port, &pki, 10))
    };
    let (a, b) = (
        start(a_port, a_pki).await.unwrap(),
        start(b_port, b_pki).await.unwrap(),
    );
    let b = b.said("set T0 0").await;
    let mut config = opcua_config(&format!("opc.tcp://127.0.0.1:{a_port}/"), &agent_pki);
    config.redundant = vec![format!("opc.tcp://127.0.0.1:{b_port}/")];
    config.publishing_interval = Duration::from_millis(100);
    pki::trust(&a.cert, &config.pki_dir).unwrap();
    pki::trust(&b.cert, &config.pki_dir).unwrap();
    let mut source = Running::start(config, (0..10).map(tag).collect());
    all(
        &mut source.rx,
        "connected to the first, its T0",
        &[&|e| matches!(e, SourceEvent::Connected(_)), &|e| {
            has(e, 0, Reading::Good(true))
        }],
    )
    .await;
    let a = a.said("level 120").await;
    // T0 from the second, and the source saying it reads from it (its
    // first values may come before it says so).
    let to_b =
        |e: &SourceEvent| matches!(e, SourceEvent::Connected(s) if s.contains(&b_port.to_string()));
    let seen = until(&mut source, "T0 = 0 from the second", |e| {
        has(e, 0, Reading::Good(false))
    })
    .await;
    if !seen.iter().any(to_b) {
        until(&mut source, "connected to the second", to_b).await;
    }
    source.stop().await;
    tokio::task::spawn_blocking(move || {
        a.stop();
        b.stop();
    })
    .await
    .unwrap();
}

/// Reverse connect (`opcua.reverse_listen`) with a server nobody here
/// wrote: the agent listens on a port the system picks, node-opcua is told
/// to dial it (a ReverseHello naming its endpoint, then the same secure
/// channel and session as a dialled connection), and dials again whenever
/// a connection ends (the agent asks the endpoints over the first and runs
/// the session over the next): the source connects, reads T0, and a change
/// made on the server arrives.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn node_opcua_reverse_connect_the_server_dials_the_agent() {
    crate::network_cut::logs();
    let dir = tempfile::tempdir().unwrap();
    let server_pki = dir.path().join("server-pki");
    let port = crate::util::restartable_port();
    trusted_by_server(&dir.path().join("agent-pki"), &server_pki);
    let server = tokio::task::spawn_blocking({
        let server_pki = server_pki.clone();
        move || StackServer::node_opcua(port, &server_pki, 10)
    })
    .await
    .unwrap();
    // The endpoint the server names in its ReverseHello.
    let mut config = opcua_config(
        &format!("opc.tcp://127.0.0.1:{port}/"),
        &dir.path().join("agent-pki"),
    );
    config.publishing_interval = Duration::from_millis(100);
    config.reverse_listen = Some("127.0.0.1:0".parse().unwrap());
    pki::trust(&server.cert, &config.pki_dir).unwrap();
    let source = opcua::OpcUaSource::new("test", config, (0..10).map(tag).collect(), []);
    let listening = source.listening().expect("bound when made");
    assert_ne!(listening.port(), 0);
    let (tx, mut rx) = tokio::sync::mpsc::channel(QUEUE_CAPACITY);
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let shutdown = async {
        let _ = stopped.await;
    };
    let task = tokio::spawn(Box::new(source).run(tx, shutdown.boxed()));
    let server = tokio::task::spawn_blocking(move || {
        let mut server = server;
        server.send(&format!("reverse opc.tcp://{listening}"));
        server
    })
    .await
    .unwrap();
    // The first values may come before the connection is reported.
    all(
        &mut rx,
        "connected over the server's connection, and T0's value",
        &[&|e| matches!(e, SourceEvent::Connected(_)), &|e| {
            has(e, 0, Reading::Good(true))
        }],
    )
    .await;
    let server = server.said("set T0 0").await;
    next(&mut rx, "T0 = 0 over the server's connection", |e| {
        has(e, 0, Reading::Good(false))
    })
    .await;
    let _ = stop.send(());
    task.await.unwrap().unwrap();
    tokio::task::spawn_blocking(move || server.stop())
        .await
        .unwrap();
}
