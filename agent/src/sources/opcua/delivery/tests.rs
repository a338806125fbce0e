//! A publishing cycle split over several publishes is handed on whole.

use std::sync::atomic::AtomicU32;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use cellwatch_models::engine::Reading;
use opcua::types::{DataValue, DateTime, MonitoredItemNotification, NotificationMessage};
use tokio::sync::mpsc;

use super::{delivery, Shared, Told};
use crate::sources::opcua::conditions::Conditions;
use crate::sources::opcua::subscription::{Heard, Monitored, Uses};
use crate::sources::opcua::Names;
use crate::sources::SourceEvent;
use crate::tags::TagConfig;

/// The limit of notifications per publish the test's cells ask for.
const FULL: usize = 100;

/// A delivery for tags `a`, `b` and `c` (client handles 1, 2, 3) whose
/// publishes are full at [`FULL`], and what it hands on.
pub(in crate::sources::opcua) fn cell() -> (Shared, mpsc::Receiver<SourceEvent>, tempfile::TempDir)
{
    cell_of(0)
}

/// [`cell`] with `more` tags besides (`x1`…, handles 4…).
fn cell_of(more: usize) -> (Shared, mpsc::Receiver<SourceEvent>, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("cell.toml");
    let mut text = format!(
        "[cell]\nid = \"m01\"\n\n[opcua]\nendpoint = \"opc.tcp://127.0.0.1:4840/\"\n\
         max_notifications_per_publish = {FULL}\npublishing_interval = \"100ms\"\n\n\
         [zenoh]\nplain = true\n\n[[tags]]\nname = \"a\"\nnode_id = \"ns=2;s=A\"\naddress = \"A\"\n\n\
         [[tags]]\nname = \"b\"\nnode_id = \"ns=2;s=B\"\naddress = \"B\"\n\n\
         [[tags]]\nname = \"c\"\nnode_id = \"ns=2;s=C\"\naddress = \"C\"\n"
    );
    for i in 1..=more {
        text.push_str(&format!(
            "\n[[tags]]\nname = \"x{i}\"\nnode_id = \"ns=2;i={i}\"\naddress = \"X{i}\"\n"
        ));
    }
    std::fs::write(&file, text).unwrap();
    let config = crate::config::load(&file).unwrap();
    let tags: &[TagConfig] = &config.tags;
    let uses = Arc::new(Uses::of_tags(tags));
    let nodes = Arc::new(
        tags.iter()
            .map(|t| crate::sources::opcua::TagNode::parse(&t.node_id, None).ok())
            .collect::<Vec<_>>(),
    );
    let pairs = nodes
        .iter()
        .enumerate()
        .filter_map(|(t, n)| Some((n.as_ref()?.resolve(&[])?, t)));
    let monitored = Arc::new(Monitored::group(pairs, &uses, nodes.clone(), Vec::new()));
    let (tx, rx) = mpsc::channel(64);
    let told = Told {
        tx,
        names: Arc::new(Names::of(tags)),
        conditions: Arc::new(Mutex::new(Conditions::new(&[]))),
    };
    let opcua = config.opcua.as_ref().unwrap();
    let shared = delivery(
        monitored,
        uses,
        told,
        Arc::new(Heard::new()),
        Arc::new(AtomicU32::new(10)),
        opcua,
    );
    shared.lock().granted(Duration::from_millis(100));
    (shared, rx, dir)
}

/// Publish `seq`, stamped `stamp_ms`, with `(handle, value, source ms)`
/// changes.
pub(in crate::sources::opcua) fn publish(
    seq: u32,
    stamp_ms: i64,
    changes: &[(u32, bool, i64)],
) -> NotificationMessage {
    let at = |ms: i64| DateTime::from(chrono::DateTime::from_timestamp_millis(ms).unwrap());
    let items = changes
        .iter()
        .map(|&(client_handle, v, ms)| MonitoredItemNotification {
            client_handle,
            value: DataValue::new_at(v, at(ms)),
        })
        .collect();
    NotificationMessage::data_change(seq, at(stamp_ms), items, Vec::new())
}

/// `n` changes of tag `c`, toggling, at source times from `from_ms`.
fn noise(n: usize, from_ms: i64) -> Vec<(u32, bool, i64)> {
    (0..n)
        .map(|k| (3, k % 2 == 0, from_ms + k as i64 % 3))
        .collect()
}

/// The batches handed on so far: each as `(tag, value, source ms)`.
fn batches(rx: &mut mpsc::Receiver<SourceEvent>) -> Vec<Vec<(usize, bool, u64)>> {
    let mut out = Vec::new();
    while let Ok(e) = rx.try_recv() {
        if let SourceEvent::Readings(b) = e {
            out.push(
                b.readings
                    .iter()
                    .map(|r| {
                        let Reading::Good(v) = r.reading.clone() else {
                            panic!("{r:?}")
                        };
                        (r.tag, v, r.source_time)
                    })
                    .collect(),
            );
        }
    }
    out
}

/// Where tags `a` and `b` are in a batch.
fn order(batch: &[(usize, bool, u64)]) -> Vec<usize> {
    batch.iter().map(|r| r.0).filter(|&t| t < 2).collect()
}

const T: i64 = 1_800_000_000_000;

#[test]
fn a_full_publish_waits_for_the_rest_of_its_cycle_and_the_cycle_is_judged_in_source_time_order() {
    let (shared, mut rx, _dir) = cell();
    // The server's cut puts B's later change before A's earlier one.
    let mut first = noise(FULL - 1, T);
    first.push((2, true, T + 10));
    shared.lock().arrived(publish(1, T + 50, &first));
    assert!(batches(&mut rx).is_empty(), "a full publish waits");
    shared
        .lock()
        .arrived(publish(2, T + 50, &[(1, false, T + 5), (3, true, T + 1)]));
    let got = batches(&mut rx);
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].len(), FULL + 2);
    assert_eq!(order(&got[0]), [0, 1], "A's change before B's");
    assert!(got[0].windows(2).all(|w| w[0].2 <= w[1].2));
    // A publish that is not full goes on at once.
    shared
        .lock()
        .arrived(publish(3, T + 150, &[(1, true, T + 120)]));
    assert_eq!(batches(&mut rx).len(), 1);
}

#[test]
fn a_held_cycle_goes_on_before_a_later_cycle_and_when_its_rest_never_comes() {
    let (shared, mut rx, _dir) = cell();
    // Full, then a full one stamped a cycle later: two cycles.
    shared.lock().arrived(publish(1, T, &noise(FULL, T - 50)));
    shared
        .lock()
        .arrived(publish(2, T + 100, &noise(FULL, T + 50)));
    let got = batches(&mut rx);
    assert_eq!(got.len(), 1, "the first cycle alone");
    assert_eq!(got[0].len(), FULL);
    assert!(got[0].iter().all(|r| r.2 < (T + 50) as u64));
    // The second, full too, waits; the supervisor looks before its time
    // is up and is told when to look again.
    let again = shared.lock().flush_stale();
    assert!(again.is_some(), "held a publishing interval at most");
    assert!(batches(&mut rx).is_empty());
    // Its rest never comes: handed on once the interval is up.
    shared.lock().granted(Duration::ZERO);
    assert_eq!(shared.lock().flush_stale(), None);
    let got = batches(&mut rx);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].len(), FULL);
    assert_eq!(shared.lock().flush_stale(), None, "nothing held");
}

#[test]
fn a_lost_connection_hands_on_what_came_of_a_cycle() {
    let (shared, mut rx, _dir) = cell();
    shared.lock().arrived(publish(1, T, &noise(FULL, T - 50)));
    assert!(batches(&mut rx).is_empty());
    shared.lock().pause();
    assert_eq!(batches(&mut rx).len(), 1);
}

#[test]
fn a_cycle_is_held_for_at_most_max_cycle_changes() {
    let (shared, mut rx, _dir) = cell();
    let publishes = super::MAX_CYCLE / FULL;
    for seq in 1..=publishes as u32 {
        shared.lock().arrived(publish(seq, T, &noise(FULL, T)));
    }
    let got = batches(&mut rx);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].len(), super::MAX_CYCLE);
}

#[test]
fn a_server_slow_to_send_the_rest_of_a_cycle_is_waited_for_longer() {
    let (shared, mut rx, _dir) = cell();
    shared.lock().granted(Duration::from_millis(1));
    shared.lock().arrived(publish(1, T, &noise(FULL, T)));
    // The next publish of the cycle came ten seconds after the first.
    let before = std::time::Instant::now().checked_sub(Duration::from_secs(10));
    shared.lock().order.cycle.last = before.unwrap();
    shared.lock().arrived(publish(2, T, &noise(FULL, T)));
    assert!(batches(&mut rx).is_empty());
    // Full too, and nothing after it: held four times that wait, not
    // the publishing interval (here 1 ms).
    let again = shared.lock().flush_stale().expect("still held");
    assert!(again >= std::time::Instant::now() + Duration::from_secs(30));
    assert!(batches(&mut rx).is_empty());
    // The cycle's rest: handed on whole; the wait is remembered, a
    // sixteenth of it forgotten.
    shared.lock().arrived(publish(3, T, &[(1, true, T + 1)]));
    assert_eq!(batches(&mut rx)[0].len(), 2 * FULL + 1);
    let slowest = shared.lock().order.cycle.slowest;
    assert!(slowest >= Duration::from_secs(9) && slowest < Duration::from_secs(10));
}

#[test]
fn a_big_cells_cycle_is_held_up_to_four_changes_per_monitored_item() {
    // 30,000 items: a cycle of up to 120,000 changes is one.
    let (shared, mut rx, _dir) = cell_of(30_000 - 3);
    let publishes = 120_000 / FULL - 1;
    for seq in 1..=publishes as u32 {
        shared.lock().arrived(publish(seq, T, &noise(FULL, T)));
    }
    assert!(batches(&mut rx).is_empty(), "past 100,000 and still held");
    shared
        .lock()
        .arrived(publish(publishes as u32 + 1, T, &[(1, true, T - 1)]));
    let got = batches(&mut rx);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].len(), publishes * FULL + 1);
    assert_eq!(got[0][0].0, 0, "the cycle's earliest change first");
}

#[test]
fn a_server_sending_fewer_than_asked_is_found_out_by_two_publishes_stamped_alike() {
    let (shared, mut rx, _dir) = cell();
    // The server sends at most 60 a publish, not the 100 asked: its first
    // split cycle cannot be told (two publishes, each not full, judged
    // apart)...
    let cap = 60;
    shared.lock().arrived(publish(1, T, &noise(cap, T - 50)));
    shared.lock().arrived(publish(2, T, &noise(10, T - 40)));
    assert_eq!(batches(&mut rx).len(), 2);
    assert_eq!(shared.lock().order.cycle.full, cap);
    // ... but from then on a publish of 60 waits for the rest of its
    // cycle: B's later change, then A's earlier one, judged A first.
    let mut first = noise(cap - 1, T + 50);
    first.push((2, true, T + 60));
    shared.lock().arrived(publish(3, T + 100, &first));
    assert!(
        batches(&mut rx).is_empty(),
        "a publish of the server's limit waits"
    );
    shared
        .lock()
        .arrived(publish(4, T + 100, &[(1, false, T + 55)]));
    let got = batches(&mut rx);
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(order(&got[0]), [0, 1], "A's change before B's");
    // Two cycles each in one publish, not full: nothing learnt from them.
    shared
        .lock()
        .arrived(publish(5, T + 200, &noise(20, T + 150)));
    shared
        .lock()
        .arrived(publish(6, T + 300, &noise(10, T + 250)));
    assert_eq!(batches(&mut rx).len(), 2);
    assert_eq!(shared.lock().order.cycle.full, cap);
}

#[test]
fn a_status_change_about_a_node_verifies_the_items_and_only_a_timeout_closes_the_subscription() {
    use opcua::types::StatusCode;
    use std::sync::atomic::Ordering;
    let (shared, _rx, _dir) = cell();
    let heard = shared.lock().order.heard.clone();
    // Python asyncua, a node deleted under an item: the subscription goes
    // on, its items verified now.
    let now = DateTime::now();
    shared.lock().arrived(NotificationMessage::status_change(
        1,
        now,
        StatusCode::BadNodeIdUnknown,
    ));
    assert_eq!(heard.closed(), None);
    assert!(heard.doubted.load(Ordering::Relaxed));
    // Its lifetime over: closed.
    shared.lock().arrived(NotificationMessage::status_change(
        2,
        now,
        StatusCode::BadTimeout,
    ));
    assert_eq!(heard.closed(), Some(StatusCode::BadTimeout));
}
