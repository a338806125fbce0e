//! The replay source against async-opcua's own client over TCP, with
//! security None and Basic256Sha256 + Sign: it connects, reads the
//! namespace array, subscribes, and hears every change of a run (the
//! first values, the noise, the switches' faults) exactly as made; a
//! message acknowledged is not sent again.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use opcua::client::{ClientBuilder, DataChangeCallback, IdentityToken};
use opcua::crypto::SecurityPolicy;
use opcua::types::{
    MessageSecurityMode, MonitoredItemCreateRequest, MonitoringMode, MonitoringParameters, NodeId,
    ReadValueId, StatusCode, TimestampsToReturn, Variant,
};

use super::{Order, ReplaySource};
use crate::load::{switch_id, NAMESPACE, SWITCHES};

/// Every (client handle, value) the client was given.
type Heard = Arc<Mutex<Vec<(u32, bool)>>>;

async fn subscribe_and_run(mode: MessageSecurityMode) {
    let dir = tempfile::tempdir().unwrap();
    let tags = 50;
    let source = ReplaySource::start(
        "127.0.0.1:0".parse().unwrap(),
        &dir.path().join("server"),
        tags,
    )
    .unwrap();
    let policy = match mode {
        MessageSecurityMode::None => SecurityPolicy::None,
        _ => SecurityPolicy::Basic256Sha256,
    };
    let mut client = ClientBuilder::new()
        .application_name("replay test")
        .application_uri("urn:cellwatch:test:replay-client")
        .pki_dir(dir.path().join("client"))
        .create_sample_keypair(true)
        .trust_server_certs(true)
        .session_retry_limit(0)
        .client()
        .unwrap();
    let (session, event_loop) = client
        .connect_to_matching_endpoint(
            (source.endpoint().as_str(), policy.to_str(), mode),
            IdentityToken::Anonymous,
        )
        .await
        .unwrap();
    let events = event_loop.spawn();
    tokio::time::timeout(Duration::from_secs(30), session.wait_for_connection())
        .await
        .unwrap();
    assert_eq!(session.get_namespace_index(NAMESPACE).await.unwrap(), 1);
    let heard: Heard = Arc::default();
    let into = heard.clone();
    let subscription = session
        .create_subscription(
            Duration::from_millis(50),
            60,
            10,
            20,
            0,
            true,
            DataChangeCallback::new(move |value, item| {
                if let Some(Variant::Boolean(b)) = value.value {
                    into.lock().unwrap().push((item.client_handle(), b));
                }
            }),
        )
        .await
        .unwrap();
    // Switches first (handles 1..=10), then the noise: the agent's order.
    let nodes = (0..SWITCHES)
        .map(switch_id)
        .chain(1..=tags as u32)
        .enumerate()
        .map(|(i, id)| MonitoredItemCreateRequest {
            item_to_monitor: ReadValueId::from(NodeId::new(1, id)),
            monitoring_mode: MonitoringMode::Reporting,
            requested_parameters: MonitoringParameters {
                client_handle: i as u32 + 1,
                queue_size: 100,
                ..Default::default()
            },
        })
        .collect();
    let created = session
        .create_monitored_items(subscription, TimestampsToReturn::Both, nodes)
        .await
        .unwrap();
    assert!(created.iter().all(|c| c.result.status_code.is_good()));
    // The first values: every tag once.
    let first = SWITCHES + tags;
    for _ in 0..100 {
        if heard.lock().unwrap().len() >= first {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(heard.lock().unwrap().len(), first);
    source.start_run(Order {
        at: std::time::Instant::now(),
        wall: std::time::SystemTime::now(),
        rate: 2000,
        fault_every: Duration::from_millis(200),
        fault_hold: Duration::from_millis(100),
    });
    tokio::time::sleep(Duration::from_millis(1000)).await;
    let (produced, faults) = source.end_run(Duration::from_millis(50)).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let heard = heard.lock().unwrap().clone();
    assert_eq!(heard.len() as u64, first as u64 + produced, "{mode:?}");
    assert!(
        produced > 1500 && faults.len() >= 4,
        "{produced} {faults:?}"
    );
    // Each noise tag toggles, each fault opened and closed its switch.
    let mut last = vec![None; SWITCHES + tags + 1];
    for &(h, v) in &heard {
        if h as usize > SWITCHES {
            assert_ne!(last[h as usize], Some(v), "tag {h} did not toggle");
        }
        last[h as usize] = Some(v);
    }
    let switch_changes = heard[first..]
        .iter()
        .filter(|(h, _)| *h as usize <= SWITCHES)
        .count();
    assert_eq!(switch_changes, 2 * faults.len());
    assert!(source.control().cpu() > 0.0);
    assert_eq!(source.control().dropped_so_far(), 0);
    // The first message was acknowledged long ago: not there to send
    // again.
    let again = session.republish(subscription, 1).await.unwrap_err();
    assert_eq!(again.status(), StatusCode::BadMessageNotAvailable);
    let _ = session.disconnect().await;
    events.abort();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_hears_every_change_without_security() {
    subscribe_and_run(MessageSecurityMode::None).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_hears_every_change_signed() {
    subscribe_and_run(MessageSecurityMode::Sign).await;
}
