//! The OPC UA source when the server changes under it: namespaces that
//! move or vanish, a decoy at the old index, deleted nodes, and a
//! subscription that goes silent while the session lives.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use cellwatch::config::{OpcUaConfig, SecurityMode, SecurityPolicy, TagConfig};
use cellwatch::sim::cnc::{SimOptions, SimulatedCnc, NAMESPACE};
use cellwatch::sources::{opcua, pki, SourceEvent};
use cellwatch_models::engine::Reading;
use cellwatch_models::signal::Signal;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;

use crate::opcua::{all, has, next, opcua_config};

/// Whether any of `events` raises a source problem (an alarm).
fn any_problem(events: &[SourceEvent]) -> bool {
    events.iter().any(|e| {
        matches!(
            e,
            SourceEvent::Problem {
                problem: Some(_),
                ..
            }
        )
    })
}

/// A tag read from `node_id`.
fn tag(address: &str, node_id: &str) -> TagConfig {
    TagConfig::boolean(&address.to_lowercase(), node_id, Signal::new(address))
}

/// A source running in the background.
pub(crate) struct Running {
    pub(crate) rx: mpsc::Receiver<SourceEvent>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<Result<(), cellwatch::sources::SourceError>>,
}

impl Running {
    pub(crate) fn start(config: OpcUaConfig, tags: Vec<TagConfig>) -> Running {
        let (tx, rx) = mpsc::channel(cellwatch::sources::QUEUE_CAPACITY);
        let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(async move {
            opcua::run("test", &config, &tags, tx, async {
                let _ = stop_rx.await;
            })
            .await
        });
        Running {
            rx,
            stop: Some(stop),
            task,
        }
    }

    /// [`Running::start`] with the source's requests counted by service
    /// and result (`cellwatch_opcua_requests_total`) in the counter
    /// returned.
    pub(crate) fn counted(
        config: OpcUaConfig,
        tags: Vec<TagConfig>,
    ) -> (Running, prometheus::IntCounterVec) {
        use cellwatch::sources::Source;
        use futures_util::FutureExt;
        let requests = prometheus::IntCounterVec::new(
            prometheus::Opts::new("cellwatch_opcua_requests_total", "requests"),
            &["service", "result"],
        )
        .unwrap();
        let mut source = opcua::OpcUaSource::new("test", config, tags, []);
        source.count_requests(requests.clone());
        let (tx, rx) = mpsc::channel(cellwatch::sources::QUEUE_CAPACITY);
        let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let shutdown = async {
            let _ = stop_rx.await;
        };
        let task = tokio::spawn(Box::new(source).run(tx, shutdown.boxed()));
        let running = Running {
            rx,
            stop: Some(stop),
            task,
        };
        (running, requests)
    }

    /// Waits for the connection and tag 0's initial value (true).
    pub(crate) async fn connected(&mut self) {
        all(
            &mut self.rx,
            "connection and initial value",
            &[&|e| matches!(e, SourceEvent::Connected(_)), &|e| {
                has(e, 0, Reading::Good(true))
            }],
        )
        .await;
    }

    pub(crate) async fn stop(mut self) {
        let _ = self.stop.take().unwrap().send(());
        self.task.await.unwrap().unwrap();
    }
}

async fn cnc(
    listen: SocketAddr,
    pki_dir: &Path,
    insecure: bool,
    decoy: Option<&str>,
) -> SimulatedCnc {
    let options = SimOptions {
        listen,
        pki_dir: pki_dir.to_path_buf(),
        insecure,
        decoy: decoy.map(str::to_string),
    };
    // A restarted server may find its port still closing.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(10);
    loop {
        match SimulatedCnc::start(&options).await {
            Ok(s) => return s,
            Err(e) => {
                assert!(tokio::time::Instant::now() < deadline, "{e}");
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
        }
    }
}

/// A simulated CNC and an agent configuration that trust each other.
pub(crate) async fn trusted_cnc(dir: &Path) -> (SimulatedCnc, OpcUaConfig, PathBuf) {
    let server_pki = dir.join("server-pki");
    let sim = cnc("127.0.0.1:0".parse().unwrap(), &server_pki, false, None).await;
    let config = opcua_config(&sim.endpoint(), &dir.join("agent-pki"));
    drop(opcua::client("test", &config).unwrap());
    pki::trust(&pki::own_cert(&config.pki_dir), &server_pki).unwrap();
    pki::trust(&pki::own_cert(&server_pki), &config.pki_dir).unwrap();
    (sim, config, server_pki)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_moved_namespace_is_followed_and_the_decoy_at_the_old_index_never_read() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut config, server_pki) = trusted_cnc(dir.path()).await;
    let old = sim.namespace();
    // One tag by index with the URI it means, one by URI.
    config.namespace_uri = Some(NAMESPACE.into());
    let tags = vec![
        tag("X0.06", &format!("ns={old};s=X0.06")),
        tag("X0.04", &format!("nsu={NAMESPACE};s=X0.04")),
    ];
    let mut source = Running::start(config, tags);
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
    // The server restarts with another namespace registered first: the
    // PLC's moves up one, and the decoy, holding the same names with the
    // opposite values, takes its old index.
    let addr = sim.addr();
    sim.stop();
    next(&mut source.rx, "connection lost", |e| {
        matches!(e, SourceEvent::Disconnected(_))
    })
    .await;
    let sim = cnc(addr, &server_pki, false, Some("urn:cellwatch:test:decoy")).await;
    assert_eq!(sim.namespace(), old + 1, "the namespace must have moved");
    // Everything the source delivers until the PLC's own change arrives:
    // initial values, then decoy changes, then the change.
    let mut seen = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    let mut connected = false;
    let mut initial = [false, false];
    while !(connected && initial.iter().all(|i| *i)) {
        let ev = tokio::time::timeout_at(deadline, source.rx.recv())
            .await
            .expect("reconnection and values")
            .unwrap();
        connected |= matches!(ev, SourceEvent::Connected(_));
        for (t, i) in initial.iter_mut().enumerate() {
            *i |= has(&ev, t, Reading::Good(true));
        }
        seen.push(ev);
    }
    sim.set_decoy("X0.06", true).unwrap();
    sim.set_decoy("X0.06", false).unwrap();
    sim.set_decoy("X0.04", true).unwrap();
    sim.set("X0.06", false).unwrap();
    loop {
        let ev = tokio::time::timeout_at(deadline, source.rx.recv())
            .await
            .expect("the PLC's change")
            .unwrap();
        let done = has(&ev, 0, Reading::Good(false));
        seen.push(ev);
        if done {
            break;
        }
    }
    // Before the PLC's own change, nothing but the PLC's values.
    let before = &seen[..seen.len() - 1];
    assert!(
        !before
            .iter()
            .any(|e| has(e, 0, Reading::Good(false)) || has(e, 1, Reading::Good(false))),
        "decoy values were read: {seen:?}"
    );
    assert!(!any_problem(before), "{seen:?}");
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_missing_namespace_makes_its_tags_unknown_with_an_alarm_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, config, _) = trusted_cnc(dir.path()).await;
    let tags = vec![
        tag("X0.06", "nsu=urn:cellwatch:sim:elsewhere:plc;s=X0.06"),
        tag("X0.04", &format!("nsu={NAMESPACE};s=X0.04")),
    ];
    let mut source = Running::start(config, tags);
    let mut problem = None;
    let mut connected = false;
    let (mut bad, mut good) = (false, false);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while !(connected && bad && good && problem.is_some()) {
        let ev = tokio::time::timeout_at(deadline, source.rx.recv())
            .await
            .expect("connection, values and the problem")
            .unwrap();
        connected |= matches!(ev, SourceEvent::Connected(_));
        bad |= has(&ev, 0, Reading::Bad);
        good |= has(&ev, 1, Reading::Good(true));
        assert!(!has(&ev, 0, Reading::Good(true)) && !has(&ev, 0, Reading::Good(false)));
        if let SourceEvent::Problem { id, problem: p } = ev {
            assert_eq!(id, opcua::NAMESPACE_ALARM);
            problem = p;
        }
    }
    assert_eq!(
        problem.unwrap(),
        "namespace 'urn:cellwatch:sim:elsewhere:plc' is not on the server (1 tag unknown: x0.06)"
    );
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_deleted_node_makes_its_tag_unknown() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, config, _) = trusted_cnc(dir.path()).await;
    let tags = vec![
        tag("X0.06", &format!("nsu={NAMESPACE};s=X0.06")),
        tag("X0.04", &format!("nsu={NAMESPACE};s=X0.04")),
    ];
    let mut source = Running::start(config, tags);
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
    sim.delete("X0.04").unwrap();
    next(&mut source.rx, "X0.04 unknown", |e| has(e, 1, Reading::Bad)).await;
    // The other tag is still read.
    sim.set("X0.06", false).unwrap();
    next(&mut source.rx, "X0.06 = 0", |e| {
        has(e, 0, Reading::Good(false))
    })
    .await;
    source.stop().await;
    sim.stop();
}

/// `PublishResponse_Encoding_DefaultBinary` as a four-byte node id.
const PUBLISH_RESPONSE: [u8; 4] = [0x01, 0x00, 0x3D, 0x03];

/// A simulated CNC with an endpoint without security, and a configuration
/// reaching it through the relay `relay` makes for the server's address.
pub(crate) async fn insecure_behind<F>(
    dir: &Path,
    relay: impl FnOnce(SocketAddr) -> F,
) -> (SimulatedCnc, OpcUaConfig)
where
    F: std::future::Future<Output = SocketAddr>,
{
    let sim = cnc(
        "127.0.0.1:0".parse().unwrap(),
        &dir.join("server-pki"),
        true,
        None,
    )
    .await;
    let via = relay(sim.addr()).await;
    let mut config = opcua_config(&format!("opc.tcp://{via}/"), &dir.join("agent-pki"));
    config.policy = SecurityPolicy::None;
    config.mode = SecurityMode::None;
    (sim, config)
}

/// Where a secure-channel chunk (security None) holds its sequence number.
fn sequence_number_at(chunk: &[u8]) -> Option<usize> {
    match &chunk[..3] {
        // Header, channel id, token id.
        b"MSG" | b"CLO" => Some(16),
        // Header, channel id, then the asymmetric security header: policy
        // URI, certificate and thumbprint, each length-prefixed.
        b"OPN" => {
            let mut at = 12;
            for _ in 0..3 {
                let len = i32::from_le_bytes(chunk.get(at..at + 4)?.try_into().ok()?);
                at += 4 + usize::try_from(len).unwrap_or(0);
            }
            Some(at)
        }
        _ => None,
    }
    .filter(|&at| chunk.len() >= at + 4)
}

/// A TCP relay between an OPC UA client and server (security None) that
/// can swallow every publish response while passing everything else: a
/// subscription silent while the session lives.
async fn relay(server: SocketAddr, mute: Arc<AtomicBool>) -> SocketAddr {
    relay_with_cut(server, mute, Cut::default()).await
}

/// Cuts a relay's connections: while set, every connection is closed and
/// new ones are refused. Or stalls them: while stalled, nothing is passed
/// either way (what was sent waits in the sockets), or only the server's
/// way (the client's requests reach it, its answers wait), then it all
/// flows on.
#[derive(Clone)]
pub(crate) struct Cut {
    on: Arc<AtomicBool>,
    links: Arc<std::sync::Mutex<Vec<tokio::task::AbortHandle>>>,
    /// Held: (towards the server, towards the client).
    stalled: Arc<tokio::sync::watch::Sender<(bool, bool)>>,
}

impl Default for Cut {
    fn default() -> Cut {
        Cut {
            on: Arc::default(),
            links: Arc::default(),
            stalled: Arc::new(tokio::sync::watch::channel((false, false)).0),
        }
    }
}

impl Cut {
    /// Holds (or lets flow) what passes either way.
    pub(crate) fn stall(&self, on: bool) {
        self.stalled.send_replace((on, on));
    }

    /// Holds (or lets flow) what the server sends, only.
    pub(crate) fn stall_answers(&self, on: bool) {
        self.stalled.send_replace((false, on));
    }

    /// Returns once traffic may flow towards the server (`up`) or the
    /// client.
    async fn flowing(&self, up: bool) {
        let mut rx = self.stalled.subscribe();
        let _ = rx
            .wait_for(|&(to_server, to_client)| !if up { to_server } else { to_client })
            .await;
    }

    pub(crate) fn set(&self, on: bool) {
        self.on.store(on, Ordering::SeqCst);
        if on {
            for link in self.links.lock().unwrap().drain(..) {
                link.abort();
            }
        }
    }
}

pub(crate) async fn relay_with_cut(
    server: SocketAddr,
    mute: Arc<AtomicBool>,
    cut: Cut,
) -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move {
        while let Ok((client, _)) = listener.accept().await {
            if cut.on.load(Ordering::SeqCst) {
                continue;
            }
            let Ok(upstream) = TcpStream::connect(server).await else {
                continue;
            };
            let (mut cr, mut cw) = client.into_split();
            let (mut ur, mut uw) = upstream.into_split();
            let flow = cut.clone();
            let up = tokio::spawn(async move {
                let mut buf = vec![0u8; 64 * 1024];
                loop {
                    let n = match cr.read(&mut buf).await {
                        Ok(0) | Err(_) => break,
                        Ok(n) => n,
                    };
                    flow.flowing(true).await;
                    if uw.write_all(&buf[..n]).await.is_err() {
                        break;
                    }
                }
            });
            cut.links.lock().unwrap().push(up.abort_handle());
            let mute = mute.clone();
            let flow = cut.clone();
            let down = tokio::spawn(async move {
                let mut muted_requests = std::collections::HashSet::new();
                let mut dropped = 0u32;
                loop {
                    let mut header = [0u8; 8];
                    if ur.read_exact(&mut header).await.is_err() {
                        break;
                    }
                    let size = u32::from_le_bytes(header[4..8].try_into().unwrap()) as usize;
                    let mut chunk = header.to_vec();
                    chunk.resize(size.max(8), 0);
                    if ur.read_exact(&mut chunk[8..]).await.is_err() {
                        break;
                    }
                    // MSG: header, channel id, token id, sequence number,
                    // request id, then the body's type id.
                    if &chunk[..3] == b"MSG" && chunk.len() >= 28 {
                        let request = u32::from_le_bytes(chunk[20..24].try_into().unwrap());
                        if chunk[24..28] == PUBLISH_RESPONSE && mute.load(Ordering::SeqCst) {
                            muted_requests.insert(request);
                        }
                        if muted_requests.contains(&request) {
                            if chunk[3] != b'C' {
                                muted_requests.remove(&request);
                            }
                            dropped += 1;
                            continue;
                        }
                    }
                    // The client checks that sequence numbers follow each
                    // other: renumber past the dropped chunks.
                    if let Some(at) = sequence_number_at(&chunk) {
                        let n = u32::from_le_bytes(chunk[at..at + 4].try_into().unwrap());
                        chunk[at..at + 4].copy_from_slice(&n.wrapping_sub(dropped).to_le_bytes());
                    }
                    flow.flowing(false).await;
                    if cw.write_all(&chunk).await.is_err() {
                        break;
                    }
                }
            });
            cut.links.lock().unwrap().push(down.abort_handle());
        }
    });
    addr
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_silent_subscription_is_reported_and_recreated() {
    let dir = tempfile::tempdir().unwrap();
    let mute = Arc::new(AtomicBool::new(false));
    let (sim, config) = insecure_behind(dir.path(), |addr| relay(addr, mute.clone())).await;
    let tags = vec![tag("X0.06", &format!("nsu={NAMESPACE};s=X0.06"))];
    let mut source = Running::start(config, tags);
    source.connected().await;
    mute.store(true, Ordering::SeqCst);
    let ev = next(&mut source.rx, "the subscription called silent", |e| {
        matches!(e, SourceEvent::Disconnected(_))
    })
    .await;
    let SourceEvent::Disconnected(why) = ev else {
        unreachable!()
    };
    assert!(why.starts_with("subscription silent for "), "{why}");
    mute.store(false, Ordering::SeqCst);
    next(&mut source.rx, "subscribed again", |e| {
        matches!(e, SourceEvent::Connected(_))
    })
    .await;
    sim.set("X0.06", false).unwrap();
    let ev = next(
        &mut source.rx,
        "X0.06 = 0 through the new subscription",
        |e| has(e, 0, Reading::Good(false)) || matches!(e, SourceEvent::Disconnected(_)),
    )
    .await;
    assert!(has(&ev, 0, Reading::Good(false)), "{ev:?}");
    source.stop().await;
    sim.stop();
}

/// Toggles X0.06 `n` times as fast as the simulator takes it, ending at
/// its normal value (true).
fn toggle(sim: &SimulatedCnc, n: usize) {
    for i in 0..n {
        sim.set("X0.06", i % 2 == 1).unwrap();
    }
}

/// Readings of tag 0 until `n` changes after the initial value have
/// arrived, or a 5 s quiet spell; with the other events seen.
async fn changes(source: &mut Running, n: usize) -> (Vec<Reading>, Vec<SourceEvent>) {
    let mut values = Vec::new();
    let mut others = Vec::new();
    while values.len() < n {
        let Ok(Some(ev)) = tokio::time::timeout(Duration::from_secs(5), source.rx.recv()).await
        else {
            break;
        };
        match &ev {
            SourceEvent::Readings(rs) => {
                values.extend(rs.iter().filter(|r| r.tag == 0).map(|r| r.reading.clone()));
            }
            _ => others.push(ev),
        }
    }
    (values, others)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_change_within_one_publishing_interval_arrives_with_sampling_zero() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut config, _) = trusted_cnc(dir.path()).await;
    config.publishing_interval = Duration::from_millis(500);
    config.sampling_interval = Duration::ZERO;
    config.queue_size =
        OpcUaConfig::default_queue_size(config.publishing_interval, config.sampling_interval);
    let tags = vec![tag("X0.06", &format!("nsu={NAMESPACE};s=X0.06"))];
    let mut source = Running::start(config, tags);
    source.connected().await;
    toggle(&sim, 20);
    let (values, others) = changes(&mut source, 20).await;
    let expected: Vec<Reading> = (0..20).map(|i| Reading::Good(i % 2 == 1)).collect();
    assert_eq!(values, expected, "{others:?}");
    assert!(!any_problem(&others), "{others:?}");
    source.stop().await;
    sim.stop();
}

/// Changes lost in the server's queue raise `opcua-overflow` once while
/// they keep being lost (burst after burst, publish after publish), never a
/// raise and a clear per publish; it clears once none was lost for
/// `overflow_clear_after`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn changes_lost_in_a_full_server_queue_raise_the_overflow_alarm() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut config, _) = trusted_cnc(dir.path()).await;
    config.publishing_interval = Duration::from_millis(500);
    config.sampling_interval = Duration::ZERO;
    config.queue_size = 4;
    config.overflow_clear_after = Duration::from_secs(3);
    let tags = vec![tag("X0.06", &format!("nsu={NAMESPACE};s=X0.06"))];
    let mut source = Running::start(config, tags);
    source.connected().await;
    toggle(&sim, 20);
    // The loss is said before the values behind it, with the tag and the
    // count: the checks judge them knowing it (and it is counted).
    let gap = next(&mut source.rx, "the gap", |e| {
        matches!(e, SourceEvent::Gap { .. } | SourceEvent::Readings(_))
    })
    .await;
    let SourceEvent::Gap { tags, values, why } = gap else {
        panic!("values before the gap: {gap:?}")
    };
    assert_eq!(tags, Some(vec![0]));
    assert!(values > 0 && why.contains("x0.06"), "{values} {why}");
    let ev = next(&mut source.rx, "the overflow alarm", |e| {
        matches!(e, SourceEvent::Problem { id, problem: Some(_) } if id == opcua::OVERFLOW_ALARM)
    })
    .await;
    let SourceEvent::Problem {
        problem: Some(why), ..
    } = ev
    else {
        unreachable!()
    };
    assert!(
        why.starts_with("changes lost in the server's queue (queue size 4) for x0.06 (1 tag, ")
            && why.ends_with(" so far): raise opcua.queue_size or sample less often"),
        "{why}"
    );
    // More bursts, publish after publish, each losing changes again within
    // the clear time: the alarm is not cleared between them (one
    // occurrence), though publishes without a loss come in between.
    for burst in 0..3 {
        // A burst that overflows, then one change that arrives whole.
        for (what, last) in [("the burst", true), ("the whole change", false)] {
            if last {
                toggle(&sim, 20);
            } else {
                sim.set("X0.06", false).unwrap();
            }
            let ev = next(&mut source.rx, what, |e| {
                matches!(e, SourceEvent::Readings(_))
                    || matches!(e, SourceEvent::Problem { id, problem: None } if id == opcua::OVERFLOW_ALARM)
            })
            .await;
            assert!(
                matches!(ev, SourceEvent::Readings(_)),
                "cleared at {what} of burst {burst}"
            );
        }
    }
    // Then quiet: one clear, after the clear time.
    let cleared = next(
        &mut source.rx,
        "the overflow alarm cleared",
        |e| matches!(e, SourceEvent::Problem { id, problem: None } if id == opcua::OVERFLOW_ALARM),
    )
    .await;
    drop(cleared);
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_change_made_while_the_connection_was_down_arrives_after_the_reactivation() {
    let dir = tempfile::tempdir().unwrap();
    let cut = Cut::default();
    let (sim, config) = insecure_behind(dir.path(), |addr| {
        relay_with_cut(addr, Arc::new(AtomicBool::new(false)), cut.clone())
    })
    .await;
    let tags = vec![tag("X0.06", &format!("nsu={NAMESPACE};s=X0.06"))];
    let mut source = Running::start(config, tags);
    source.connected().await;
    // The network goes down; the server keeps the session (30 s) and the
    // subscription; the PLC changes meanwhile; the network comes back.
    cut.set(true);
    next(&mut source.rx, "connection lost", |e| {
        matches!(e, SourceEvent::Disconnected(_))
    })
    .await;
    sim.set("X0.06", false).unwrap();
    cut.set(false);
    next(&mut source.rx, "X0.06 = 0 after the reactivation", |e| {
        has(e, 0, Reading::Good(false))
    })
    .await;
    source.stop().await;
    sim.stop();
}

/// The network is down longer than the subscription's lifetime but not the
/// session's: the server drops the subscription and keeps the session. The
/// reactivated session gets a communication alarm for the gap and a new
/// subscription that delivers again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_subscription_the_server_dropped_during_a_cut_is_replaced_after_the_reactivation() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
    let dir = tempfile::tempdir().unwrap();
    let cut = Cut::default();
    let (sim, mut config) = insecure_behind(dir.path(), |addr| {
        relay_with_cut(addr, Arc::new(AtomicBool::new(false)), cut.clone())
    })
    .await;
    // The shortest lifetime allowed: 30 publishing intervals.
    config.subscription_lifetime = config.publishing_interval * 30;
    let tags = vec![tag("X0.06", &format!("nsu={NAMESPACE};s=X0.06"))];
    let mut source = Running::start(config, tags);
    source.connected().await;
    assert_eq!(sim.subscriptions(), 1);
    cut.set(true);
    next(&mut source.rx, "connection lost", |e| {
        matches!(e, SourceEvent::Disconnected(_))
    })
    .await;
    // No publish requests reach the server: after the subscription's
    // lifetime it closes it; the session (30 s)
    // stays. (This server then says so in the next publish, with a
    // `BadTimeout` status change; others forget the subscription at once.)
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    while sim.subscriptions() > 0 {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the server never dropped the subscription"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    sim.set("X0.06", false).unwrap();
    cut.set(false);
    next(
        &mut source.rx,
        "the gap reported",
        |e| matches!(e, SourceEvent::Disconnected(why) if why.contains("dropped subscription")),
    )
    .await;
    all(
        &mut source.rx,
        "connected again, and X0.06 = 0",
        &[&|e| matches!(e, SourceEvent::Connected(_)), &|e| {
            has(e, 0, Reading::Good(false))
        }],
    )
    .await;
    assert_eq!(sim.subscriptions(), 1, "one new subscription, no leftovers");
    // The new subscription delivers (not only the read after the gap).
    sim.set("X0.06", true).unwrap();
    next(
        &mut source.rx,
        "X0.06 = 1 through the new subscription",
        |e| has(e, 0, Reading::Good(true)),
    )
    .await;
    source.stop().await;
    sim.stop();
}
