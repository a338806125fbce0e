//! The OPC UA source against the simulated CNC over real OPC UA with
//! Basic256Sha256 + SignAndEncrypt and mutual certificate trust.

use std::time::Duration;

use cellwatch::config::{Identity, OpcUaConfig, SecurityMode, SecurityPolicy, TagConfig};
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc};
use cellwatch::sources::{opcua, pki, SourceEvent};
use cellwatch_models::engine::Reading;
use cellwatch_models::signal::Signal;
use tokio::sync::mpsc;

pub(crate) fn tag(address: &str, ns: u16) -> TagConfig {
    TagConfig::boolean(
        &address.to_lowercase(),
        &format!("ns={ns};s={address}"),
        Signal::new(address),
    )
}

pub(crate) fn opcua_config(endpoint: &str, pki_dir: &std::path::Path) -> OpcUaConfig {
    OpcUaConfig {
        endpoint: endpoint.to_string(),
        policy: SecurityPolicy::Basic256Sha256,
        mode: SecurityMode::SignAndEncrypt,
        pki_dir: pki_dir.to_path_buf(),
        identity: Identity::Anonymous,
        publishing_interval: Duration::from_millis(50),
        sampling_interval: Duration::from_millis(20),
        namespace_uri: None,
        queue_size: 10,
        max_notifications_per_publish: 10_000,
        overflow_clear_after: OpcUaConfig::DEFAULT_OVERFLOW_CLEAR_AFTER,
        subscription_lifetime: OpcUaConfig::DEFAULT_SUBSCRIPTION_LIFETIME,
        verify_interval: OpcUaConfig::DEFAULT_VERIFY_INTERVAL,
        reverse_listen: None,
        redundant: Vec::new(),
        events: Vec::new(),
    }
}

pub(crate) async fn next(
    rx: &mut mpsc::Receiver<SourceEvent>,
    what: &str,
    f: impl Fn(&SourceEvent) -> bool,
) -> SourceEvent {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let ev = tokio::time::timeout_at(deadline, rx.recv())
            .await
            .unwrap_or_else(|_| panic!("timed out waiting for {what}"))
            .expect("source stopped");
        if f(&ev) {
            return ev;
        }
    }
}

/// Waits until every condition has matched some event, in any order
/// (changes in one publish arrive in no particular order).
pub(crate) async fn all(
    rx: &mut mpsc::Receiver<SourceEvent>,
    what: &str,
    conditions: &[&dyn Fn(&SourceEvent) -> bool],
) {
    let mut seen = vec![false; conditions.len()];
    let deadline = tokio::time::Instant::now() + Duration::from_secs(90);
    while !seen.iter().all(|s| *s) {
        let ev = tokio::time::timeout_at(deadline, rx.recv())
            .await
            .unwrap_or_else(|_| panic!("timed out waiting for {what}: matched {seen:?}"))
            .expect("source stopped");
        for (i, c) in conditions.iter().enumerate() {
            seen[i] |= c(&ev);
        }
    }
}

/// Whether `e` delivers `reading` for tag `tag`.
pub(crate) fn has(e: &SourceEvent, tag: usize, reading: Reading) -> bool {
    matches!(e, SourceEvent::Readings(rs) if rs.iter().any(|r| r.tag == tag && r.reading == reading))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn source_reads_the_simulator_securely() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
    let dir = tempfile::tempdir().unwrap();
    let server_pki = dir.path().join("server-pki");
    let agent_pki = dir.path().join("agent-pki");
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: server_pki.clone(),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let config = opcua_config(&sim.endpoint(), &agent_pki);
    // Each side trusts the other's certificate, and nothing else.
    drop(opcua::client("test", &config).unwrap());
    pki::trust(&pki::own_cert(&agent_pki), &server_pki).unwrap();
    pki::trust(&pki::own_cert(&server_pki), &agent_pki).unwrap();
    let tags = vec![
        tag("X0.06", sim.namespace()),
        tag("X0.04", sim.namespace()),
        tag("G8.02", sim.namespace()),
    ];
    let (tx, mut rx) = mpsc::channel(cellwatch::sources::QUEUE_CAPACITY);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        opcua::run("test", &config, &tags, tx, async {
            let _ = stop_rx.await;
        })
        .await
    });
    all(
        &mut rx,
        "connection and initial values",
        &[&|e| matches!(e, SourceEvent::Connected(_)), &|e| {
            has(e, 0, Reading::Good(true))
        }],
    )
    .await;
    sim.set("X0.06", false).unwrap();
    // The limit switch opens and the PLC's ESE coil follows.
    all(
        &mut rx,
        "X0.06 = 0 and G8.02 = 1",
        &[&|e| has(e, 0, Reading::Good(false)), &|e| {
            has(e, 2, Reading::Good(true))
        }],
    )
    .await;
    sim.set_bad("X0.04").unwrap();
    next(&mut rx, "X0.04 bad", |e| has(e, 1, Reading::Bad)).await;
    let _ = stop_tx.send(());
    task.await.unwrap().unwrap();
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unknown_server_certificate_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let server_pki = dir.path().join("server-pki");
    let agent_pki = dir.path().join("agent-pki");
    let sim = SimulatedCnc::start(&SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: server_pki.clone(),
        insecure: false,
        decoy: None,
    })
    .await
    .unwrap();
    let config = opcua_config(&sim.endpoint(), &agent_pki);
    drop(opcua::client("test", &config).unwrap());
    // The server trusts the agent, but the agent does not trust the server.
    pki::trust(&pki::own_cert(&agent_pki), &server_pki).unwrap();
    let tags = vec![tag("X0.06", sim.namespace())];
    let (tx, mut rx) = mpsc::channel(cellwatch::sources::QUEUE_CAPACITY);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        opcua::run("test", &config, &tags, tx, async {
            let _ = stop_rx.await;
        })
        .await
    });
    let ev = next(&mut rx, "refused", |e| {
        matches!(e, SourceEvent::Disconnected(_))
    })
    .await;
    // The communication alarm says why and what to do.
    let SourceEvent::Disconnected(why) = ev else {
        unreachable!()
    };
    assert!(
        why.contains("the server's certificate is not trusted (CN=cellwatch simulated CNC")
            && why.contains("`cellwatch trust-server "),
        "{why}"
    );
    // The refused certificate waits in rejected/ for an engineer to review.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    loop {
        let rejected = std::fs::read_dir(agent_pki.join("rejected"))
            .map(|d| d.count())
            .unwrap_or(0);
        if rejected > 0 {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no certificate in rejected/"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // Trusted while the source runs (as trust-server does: out of
    // rejected/, into trusted/): the next attempt connects.
    let rejected = std::fs::read_dir(agent_pki.join("rejected"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    pki::trust(&rejected, &agent_pki).unwrap();
    next(&mut rx, "connected once trusted", |e| {
        matches!(e, SourceEvent::Connected(_))
    })
    .await;
    let _ = stop_tx.send(());
    task.await.unwrap().unwrap();
    sim.stop();
}
