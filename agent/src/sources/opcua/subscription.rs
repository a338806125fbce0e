//! The subscription: monitored items created in chunks the server accepts,
//! and each publish's changes passed on in source-time order.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use cellwatch_models::engine::{Reading, TagReading};
use opcua::client::services::CreateMonitoredItems;
use opcua::client::{OnSubscriptionNotificationCore, Session, UARequest};
use opcua::types::{
    DataChangeFilter, DataChangeTrigger, DataValue, ExtensionObject, MonitoredItemCreateRequest,
    MonitoredItemCreateResult, MonitoringMode, MonitoringParameters, NodeId, ReadValueId,
    StatusCode, TimestampsToReturn, Variant,
};

use super::items::Items;
use super::machinery::MachineryNamespace;
use super::requests::Requests;
use crate::sources::opcua::config::OpcUaConfig;
use crate::sources::opcua::node::TagNode;
use crate::sources::{SourceEvent, SourceSender};
use crate::tags::{Deadband, TagConfig};
use cellwatch_models::machinery::StateMachine;
use cellwatch_models::value::{Num, ValueType};

/// `Server_ServerCapabilities_OperationLimits_MaxMonitoredItemsPerCall`.
const MAX_MONITORED_ITEMS_PER_CALL: u32 = 11714;
/// Used when the server states no limit.
const DEFAULT_CHUNK: usize = 1000;
/// The most monitored items created in one call, whatever the server
/// allows (the client's decoding limits are sized from it).
pub(super) const MAX_ITEMS_PER_CALL: usize = 10_000;
/// Publishing intervals without data before the server sends a keep-alive.
const KEEP_ALIVE_COUNT: u32 = 10;

/// When the subscription was last heard from: any publish, data or
/// keep-alive.
pub(super) struct Heard {
    start: Instant,
    /// Milliseconds after `start`.
    last: AtomicU64,
    /// A publish is being handed to the cell loop (which may be behind):
    /// not silence.
    pub(super) busy: AtomicBool,
    /// The bad status the server closed the subscription with (its
    /// `StatusChangeNotification`, `BadTimeout` when it expired), or 0.
    pub(super) closed: AtomicU32,
    /// A bad status change that did not end the subscription (a node
    /// deleted under an item, Python asyncua): the items are verified now.
    pub(super) doubted: AtomicBool,
}

impl Heard {
    pub(super) fn new() -> Heard {
        Heard {
            start: Instant::now(),
            last: AtomicU64::new(0),
            busy: AtomicBool::new(false),
            closed: AtomicU32::new(0),
            doubted: AtomicBool::new(false),
        }
    }

    /// The status the server closed the subscription with, if it did.
    pub(super) fn closed(&self) -> Option<StatusCode> {
        match self.closed.load(Ordering::Relaxed) {
            0 => None,
            bits => Some(StatusCode::from(bits)),
        }
    }

    pub(super) fn beat(&self) {
        let ms = self.start.elapsed().as_millis() as u64;
        self.last.store(ms, Ordering::Relaxed);
    }

    /// How long nothing has arrived, or zero while a publish is being
    /// handed on.
    pub(super) fn silent_for(&self) -> Duration {
        if self.busy.load(Ordering::Relaxed) {
            return Duration::ZERO;
        }
        let now = self.start.elapsed().as_millis() as u64;
        Duration::from_millis(now.saturating_sub(self.last.load(Ordering::Relaxed)))
    }
}

/// A subscription in place: its id and how often the server promised to
/// publish or send a keep-alive.
pub(super) struct Subscribed {
    pub(super) id: u32,
    pub(super) keep_alive: Duration,
    /// The publishing interval granted.
    pub(super) interval: Duration,
}

/// What the server grants a subscription's items: the queue size per item
/// (which may be less than asked), and each item's id (or refusal); and
/// where the requests for them are counted.
pub(super) struct Granted<'a> {
    pub(super) queue_size: &'a AtomicU32,
    pub(super) items: &'a Mutex<Items>,
    pub(super) requests: &'a Requests,
}

/// Creates the subscription and its monitored items in chunks; `None` if the
/// server refused the subscription (reported as
/// [`SourceEvent::Disconnected`]).
pub(super) async fn subscribe(
    session: &Arc<Session>,
    config: &OpcUaConfig,
    monitored: &Arc<Monitored>,
    uses: &Arc<Uses>,
    tx: &SourceSender,
    granted: Granted<'_>,
    callback: impl OnSubscriptionNotificationCore + 'static,
) -> Option<Subscribed> {
    let Granted {
        queue_size,
        items,
        requests,
    } = granted;
    // Each node's monitored item gets client handle i + 1 (0 would let the
    // library choose): a notification finds its tags by index, without a
    // lookup in the library's item maps or a hash of the node id.
    let sub = match session
        .create_subscription(
            config.publishing_interval,
            lifetime_count(config),
            KEEP_ALIVE_COUNT,
            config.max_notifications_per_publish,
            0,
            true,
            callback,
        )
        .await
    {
        Ok(id) => {
            requests.status("CreateSubscription", StatusCode::Good);
            id
        }
        Err(e) => {
            requests.status("CreateSubscription", e.status());
            tracing::error!(error = %e, "cannot create the OPC UA subscription");
            let _ = tx
                .send(SourceEvent::Disconnected(format!(
                    "cannot create subscription: {e}"
                )))
                .await;
            return None;
        }
    };
    // The server may revise the interval and the keep-alive count.
    let (interval, keep_alive) = {
        let state = session.subscription_state().lock();
        state.get(sub).map_or(
            (
                config.publishing_interval,
                config.publishing_interval * KEEP_ALIVE_COUNT,
            ),
            |s| {
                (
                    s.publishing_interval(),
                    s.publishing_interval() * s.max_keep_alive_count().max(1),
                )
            },
        )
    };
    let chunk = max_items_per_call(session, requests)
        .await
        .min(MAX_ITEMS_PER_CALL);
    // Requests are made one call's worth at a time: 100,000 of them at
    // once would be 15 MB held for the length of the creation.
    tracing::debug!(
        subscription = sub,
        items = monitored.len(),
        chunk,
        "creating monitored items"
    );
    // Requests are made one call's worth at a time: 100,000 of them at
    // once would be 15 MB held for the length of the creation.
    for from in (0..monitored.len()).step_by(chunk.max(1)) {
        let part: Vec<_> = monitored.nodes(from..from + chunk).collect();
        let results = match create(session, sub, config, uses, &part, requests).await {
            Ok(results) => results,
            Err(e) => {
                tracing::error!(error = %e, "cannot create monitored items");
                continue;
            }
        };
        if let Some(granted) = results
            .iter()
            .filter(|r| r.status_code.is_good())
            .map(|r| r.revised_queue_size)
            .min()
        {
            if granted < queue_size.load(Ordering::Relaxed) {
                tracing::warn!(
                    asked = config.queue_size,
                    granted,
                    "the server granted a smaller queue per tag"
                );
                queue_size.store(granted, Ordering::Relaxed);
            }
        }
        if let Some(slowest) = results
            .iter()
            .filter(|r| r.status_code.is_good())
            .map(|r| r.revised_sampling_interval)
            .max_by(f64::total_cmp)
        {
            let sampling = config.sampling_interval.as_secs_f64() * 1000.0;
            if slowest > sampling {
                tracing::warn!(asked_ms = sampling, granted_ms = slowest, "the server samples less often than asked: changes shorter than its interval are not seen");
            }
        }
        let refused = taken(items, &results, &part);
        if !refused.is_empty() {
            let _ = tx.send(bad(&refused)).await;
        }
    }
    Some(Subscribed {
        id: sub,
        keep_alive,
        interval,
    })
}

/// The request that creates node `i`'s monitored item (client handle
/// `i + 1`), reading `tags` from `node`.
pub(super) fn item_request(
    config: &OpcUaConfig,
    uses: &Uses,
    i: usize,
    n: NodeId,
    tags: &[u32],
) -> MonitoredItemCreateRequest {
    // Several tags on one node are bits of one word: the first
    // says how it is sampled.
    let tag = &uses[tags[0] as usize];
    let sampling = tag
        .sampling
        .unwrap_or(config.sampling_interval)
        .as_secs_f64()
        * 1000.0;
    // Without a filter a server reports value changes only; quality
    // changes (a broken sensor wire) must be reported too.
    let (deadband_type, deadband_value) = match tag.deadband {
        None => (0, 0.0),
        Some(Deadband::Absolute(v)) => (1, v),
        Some(Deadband::Percent(v)) => (2, v),
    };
    let filter = DataChangeFilter {
        trigger: DataChangeTrigger::StatusValue,
        deadband_type,
        deadband_value,
    };
    // When the queue is full the server drops the oldest change and
    // flags the next one it delivers with the overflow bit.
    let params = MonitoringParameters {
        client_handle: i as u32 + 1,
        sampling_interval: sampling,
        queue_size: config.queue_size,
        discard_oldest: true,
        filter: ExtensionObject::from_message(filter),
    };
    MonitoredItemCreateRequest::new(ReadValueId::from(n), MonitoringMode::Reporting, params)
}

/// Creates the monitored items of `nodes` (index, id, tags) in one call:
/// each one's result, in order.
///
/// # Errors
/// The call failed.
pub(super) async fn create(
    session: &Session,
    sub: u32,
    config: &OpcUaConfig,
    uses: &Uses,
    nodes: &[(usize, NodeId, &[u32])],
    requests: &Requests,
) -> Result<Vec<MonitoredItemCreateResult>, opcua::types::Error> {
    let items = nodes
        .iter()
        .map(|(i, n, tags)| item_request(config, uses, *i, n.clone(), tags))
        .collect();
    // The service itself, not `Session::create_monitored_items`: that
    // also keeps every item in the library's subscription state (about
    // 370 bytes an item, 37 MB for 100,000 tags), which this source
    // never reads — notifications find their tags by client handle, and
    // the source recreates the subscription itself after a reconnect.
    // Source timestamps only: the checks judge time by the PLC's
    // clock, and a server timestamp per change would cost its decoding
    // (about a fifth of the agent's time at 500,000 changes/s). A
    // value without one is stamped when it arrives.
    let created = CreateMonitoredItems::new(sub, session)
        .items_to_create(items)
        .timestamps_to_return(TimestampsToReturn::Source)
        .send(session.channel())
        .await;
    requests.answered("CreateMonitoredItems", &created);
    Ok(created?.results.into_iter().map(|r| r.result).collect())
}

/// Every tag of `tags` bad, now.
pub(super) fn bad(tags: &[usize]) -> SourceEvent {
    let now = crate::clock::now_ms();
    SourceEvent::Readings(
        tags.iter()
            .map(|&tag| TagReading {
                tag,
                reading: Reading::Bad,
                source_time: now,
            })
            .collect::<Vec<_>>()
            .into(),
    )
}
/// Records what the server made of `nodes`' items: the ids of those
/// created; those refused because the node is not there are created again
/// later. The tags of the refused ones.
pub(super) fn taken(
    items: &Mutex<Items>,
    results: &[MonitoredItemCreateResult],
    nodes: &[(usize, NodeId, &[u32])],
) -> Vec<usize> {
    let mut refused = Vec::new();
    let mut items = items.lock().unwrap_or_else(|e| e.into_inner());
    let now = Instant::now();
    for (r, (i, node, tags)) in results.iter().zip(nodes) {
        let status = r.status_code;
        if status.is_good() {
            items.created(*i, r.monitored_item_id);
            continue;
        }
        if super::items::is_gone(status) {
            tracing::warn!(node = %node, %status, "monitored item refused: created again once the node exists");
            items.fail(*i, status, now);
        } else {
            tracing::error!(node = %node, %status, "monitored item refused");
        }
        refused.extend(tags.iter().map(|&t| t as usize));
    }
    refused
}

/// Publishing intervals without a publish request before the server drops
/// the subscription: `opcua.subscription_lifetime`, and at least three
/// keep-alive periods.
fn lifetime_count(config: &OpcUaConfig) -> u32 {
    let interval = config.publishing_interval.as_millis().max(1);
    let count = config.subscription_lifetime.as_millis().div_ceil(interval);
    u32::try_from(count)
        .unwrap_or(u32::MAX)
        .max(3 * KEEP_ALIVE_COUNT)
}

/// The alarm of changes lost in the server's queues (kind `system`).
pub const OVERFLOW_ALARM: &str = "opcua-overflow";

/// The server's limit on monitored items per call, or [`DEFAULT_CHUNK`].
async fn max_items_per_call(session: &Session, requests: &Requests) -> usize {
    let node = NodeId::new(0, MAX_MONITORED_ITEMS_PER_CALL);
    let read = session
        .read(&[ReadValueId::from(node)], TimestampsToReturn::Neither, 0.0)
        .await;
    requests.answered("Read", &read);
    match read {
        Ok(values) => match values.first().and_then(|v| v.value.as_ref()) {
            Some(Variant::UInt32(n)) if *n > 0 => *n as usize,
            _ => DEFAULT_CHUNK,
        },
        Err(_) => DEFAULT_CHUNK,
    }
}

/// A data value as the engine reads it.
pub fn reading(value: &DataValue, tag: &TagUse) -> Reading {
    if !value.status.is_none_or(|s| s.is_good()) {
        return Reading::Bad;
    }
    let Some(v) = &value.value else {
        return Reading::Bad;
    };
    let wrong = || Reading::WrongType {
        expected: tag.value_type,
        received: type_of(v),
    };
    if let Some((machine, ns)) = &tag.states {
        return ns.reading(*machine, v);
    }
    if let Some(bit) = tag.bit {
        return match word(v) {
            Some(w) => Reading::Good((w >> bit) & 1 == 1),
            None => wrong(),
        };
    }
    match (tag.value_type, v) {
        (ValueType::Boolean, Variant::Boolean(b)) => Reading::Good(*b),
        (ValueType::String, Variant::String(s)) => Reading::Text(Arc::from(s.as_ref())),
        (ValueType::DateTime, Variant::DateTime(t)) => {
            Reading::Number(Num::Int(t.as_chrono().timestamp_millis()))
        }
        (t, v) if t.is_numeric() => number(v).map_or_else(wrong, Reading::Number),
        _ => wrong(),
    }
}

/// How the source reads one tag's node.
#[derive(Debug, Clone)]
pub struct TagUse {
    /// The configured type.
    pub value_type: ValueType,
    /// The bit of an integer word the tag is.
    pub bit: Option<u8>,
    /// Its own sampling interval.
    pub sampling: Option<Duration>,
    /// Its data-change filter deadband.
    pub deadband: Option<Deadband>,
    /// The state machine of OPC UA for Machinery it is the current state
    /// of, and where the server's Machinery namespace is.
    pub(super) states: Option<(StateMachine, MachineryNamespace)>,
}

impl TagUse {
    /// How `tag` is read.
    pub fn of(tag: &TagConfig) -> TagUse {
        TagUse {
            value_type: tag.value_type,
            bit: tag.bit,
            sampling: tag.sampling_interval,
            deadband: tag.deadband,
            // Its own namespace index, never learnt: a reader outside a
            // subscription believes no state.
            states: tag.states.map(|m| (m, MachineryNamespace::default())),
        }
    }
}

/// The monitored nodes in client-handle order (handle `i + 1` is node
/// `i`) and the tags read from each (several when they are bits of one
/// word), kept flat: a node costs one [`Item`] of eight bytes, and a
/// notification finds its tag and how it is read with one look-up. A node's
/// id is not kept: it is its first tag's node, resolved against the
/// namespaces the subscription was made with, when a request needs it.
#[derive(Debug)]
pub(super) struct Monitored {
    tag_nodes: Arc<Vec<Option<TagNode>>>,
    namespaces: Vec<String>,
    pub(super) items: Vec<Item>,
    /// The tags of the nodes that have several, one run each.
    several: Vec<u32>,
}

/// One monitored node as a notification finds it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Item {
    /// Its tag; for a node with several, where they start in
    /// [`Monitored::several`].
    pub(super) at: u32,
    /// How its tag is read (an index into the [`Uses`]' kinds); for a node
    /// with several, [`SEVERAL`] and how many.
    how: u32,
}

/// The bit of [`Item::how`] that says the node has several tags.
const SEVERAL: u32 = 1 << 31;

impl Item {
    /// How its one tag is read, if it has one.
    pub(super) fn one(self) -> Option<u32> {
        (self.how & SEVERAL == 0).then_some(self.how)
    }
}

impl Monitored {
    /// Groups `(node, tag)` pairs by node, nodes in the order first seen,
    /// each node's tags in the order given; each `node` is
    /// `tag_nodes[tag]` resolved against `namespaces`, each tag read as
    /// `uses` says.
    pub(super) fn group(
        pairs: impl IntoIterator<Item = (NodeId, usize)>,
        uses: &Uses,
        tag_nodes: Arc<Vec<Option<TagNode>>>,
        namespaces: Vec<String>,
    ) -> Monitored {
        // Sized once for every tag (not grown by doubling: the start's peak).
        let pairs = pairs.into_iter();
        let most = pairs.size_hint().1.unwrap_or(0);
        let mut index: HashMap<NodeId, u32> = HashMap::with_capacity(most);
        let mut of_node: Vec<(u32, u32)> = Vec::with_capacity(most);
        for (id, tag) in pairs {
            let next = index.len() as u32;
            let n = *index.entry(id).or_insert(next);
            of_node.push((n, tag as u32));
        }
        let nodes = index.len();
        drop(index);
        // Stable: a node's tags keep their order.
        of_node.sort_by_key(|&(n, _)| n);
        let mut items = Vec::with_capacity(nodes);
        let mut several = Vec::new();
        for run in of_node.chunk_by(|a, b| a.0 == b.0) {
            items.push(match run {
                [(_, tag)] => Item {
                    at: *tag,
                    how: uses.of[*tag as usize],
                },
                _ => {
                    let at = several.len() as u32;
                    several.extend(run.iter().map(|&(_, tag)| tag));
                    Item {
                        at,
                        how: SEVERAL | run.len() as u32,
                    }
                }
            });
        }
        Monitored {
            tag_nodes,
            namespaces,
            items,
            several,
        }
    }

    /// How many nodes.
    pub(super) fn len(&self) -> usize {
        self.items.len()
    }

    /// The tags of a node with several.
    pub(super) fn several(&self, item: Item) -> &[u32] {
        let (from, n) = (item.at as usize, (item.how & !SEVERAL) as usize);
        &self.several[from..from + n]
    }

    /// Node `i`'s tags.
    pub(super) fn tags(&self, i: usize) -> Option<&[u32]> {
        let item = self.items.get(i)?;
        Some(match item.one() {
            Some(_) => std::slice::from_ref(&item.at),
            None => self.several(*item),
        })
    }

    /// Node `i`'s id and its tags.
    pub(super) fn node(&self, i: usize) -> Option<(NodeId, &[u32])> {
        let tags = self.tags(i)?;
        let node = self.tag_nodes.get(tags[0] as usize)?.as_ref()?;
        Some((node.resolve(&self.namespaces)?, tags))
    }

    /// Nodes `range` (clamped), each with its index, id and tags.
    pub(super) fn nodes(
        &self,
        range: std::ops::Range<usize>,
    ) -> impl Iterator<Item = (usize, NodeId, &[u32])> + '_ {
        (range.start..range.end.min(self.len()))
            .filter_map(|i| self.node(i).map(|(id, tags)| (i, id, tags)))
    }
}

/// How each tag is read, kept as an index into the few distinct ways a
/// cell's tags are read (most share one): four bytes a tag, not a
/// [`TagUse`].
#[derive(Debug, Default)]
pub(super) struct Uses {
    kinds: Vec<TagUse>,
    of: Vec<u32>,
    /// Where the server's Machinery namespace is, for the tags that read a
    /// state machine.
    machinery: MachineryNamespace,
}

impl Uses {
    /// How each of `tags` is read.
    pub(super) fn of_tags(tags: &[TagConfig]) -> Uses {
        type Key = (
            ValueType,
            Option<u8>,
            Option<Duration>,
            Option<(bool, u64)>,
            Option<StateMachine>,
        );
        let mut index: HashMap<Key, u32> = HashMap::new();
        let mut uses = Uses::default();
        for t in tags {
            let mut u = TagUse::of(t);
            if let Some((_, ns)) = &mut u.states {
                *ns = uses.machinery.clone();
            }
            let deadband = u.deadband.map(|d| match d {
                Deadband::Absolute(v) => (false, v.to_bits()),
                Deadband::Percent(v) => (true, v.to_bits()),
            });
            let key = (u.value_type, u.bit, u.sampling, deadband, t.states);
            let kinds = &mut uses.kinds;
            let k = *index.entry(key).or_insert_with(|| {
                kinds.push(u);
                (kinds.len() - 1) as u32
            });
            uses.of.push(k);
        }
        uses
    }

    /// The slowest sampling of any tag (`default` where a tag has none of
    /// its own).
    pub(super) fn slowest(&self, default: Duration) -> Duration {
        self.kinds
            .iter()
            .map(|k| k.sampling.unwrap_or(default))
            .max()
            .unwrap_or(default)
    }

    /// The server's namespace array is `namespaces` (where its Machinery
    /// namespace is).
    pub(super) fn namespaces_are(&self, namespaces: &[String]) {
        self.machinery.learn(namespaces);
    }

    /// Kind `k` of reading a tag.
    pub(super) fn kind(&self, k: u32) -> &TagUse {
        &self.kinds[k as usize]
    }
}

impl std::ops::Index<usize> for Uses {
    type Output = TagUse;

    fn index(&self, tag: usize) -> &TagUse {
        self.kind(self.of[tag])
    }
}

/// The scalar type of a value, if it is one cellwatch reads.
fn type_of(v: &Variant) -> Option<ValueType> {
    Some(match v {
        Variant::Boolean(_) => ValueType::Boolean,
        Variant::SByte(_) => ValueType::SByte,
        Variant::Byte(_) => ValueType::Byte,
        Variant::Int16(_) => ValueType::Int16,
        Variant::UInt16(_) => ValueType::UInt16,
        Variant::Int32(_) => ValueType::Int32,
        Variant::UInt32(_) => ValueType::UInt32,
        Variant::Int64(_) => ValueType::Int64,
        Variant::UInt64(_) => ValueType::UInt64,
        Variant::Float(_) => ValueType::Float,
        Variant::Double(_) => ValueType::Double,
        Variant::String(_) => ValueType::String,
        Variant::DateTime(_) => ValueType::DateTime,
        _ => return None,
    })
}

/// An integer's bits (two's complement for signed ones).
fn word(v: &Variant) -> Option<u64> {
    Some(match v {
        Variant::SByte(x) => *x as u8 as u64,
        Variant::Byte(x) => u64::from(*x),
        Variant::Int16(x) => *x as u16 as u64,
        Variant::UInt16(x) => u64::from(*x),
        Variant::Int32(x) => *x as u32 as u64,
        Variant::UInt32(x) => u64::from(*x),
        Variant::Int64(x) => *x as u64,
        Variant::UInt64(x) => *x,
        _ => return None,
    })
}

/// A number, whatever its width.
fn number(v: &Variant) -> Option<Num> {
    Some(match v {
        Variant::SByte(x) => Num::Int(i64::from(*x)),
        Variant::Byte(x) => Num::UInt(u64::from(*x)),
        Variant::Int16(x) => Num::Int(i64::from(*x)),
        Variant::UInt16(x) => Num::UInt(u64::from(*x)),
        Variant::Int32(x) => Num::Int(i64::from(*x)),
        Variant::UInt32(x) => Num::UInt(u64::from(*x)),
        Variant::Int64(x) => Num::Int(*x),
        Variant::UInt64(x) => Num::UInt(*x),
        Variant::Float(x) => Num::Float(f64::from(*x)),
        Variant::Double(x) => Num::Float(*x),
        _ => return None,
    })
}

pub(super) fn source_time(value: &DataValue) -> u64 {
    value
        .source_timestamp
        .or(value.server_timestamp)
        .map_or_else(crate::clock::now_ms, |t| {
            t.as_chrono().timestamp_millis().max(0) as u64
        })
}

#[cfg(test)]
mod tests;

/// Reads the current value of every node and sends them as readings, in
/// chunks of [`READ_CHUNK`]. A failed read is logged; the subscription's
/// liveness check covers what follows.
pub(super) async fn read_current(
    session: &Session,
    nodes: &Monitored,
    uses: &Uses,
    tx: &SourceSender,
    requests: &Requests,
) {
    for from in (0..nodes.len()).step_by(READ_CHUNK) {
        let part = || nodes.nodes(from..from + READ_CHUNK);
        let ids: Vec<ReadValueId> = part().map(|(_, n, _)| ReadValueId::from(n)).collect();
        let read = session.read(&ids, TimestampsToReturn::Both, 0.0).await;
        requests.answered("Read", &read);
        match read {
            Ok(values) => {
                let mut readings: Vec<TagReading> = values
                    .iter()
                    .zip(part())
                    .flat_map(|(v, (_, _, tags))| {
                        tags.iter().map(|&tag| TagReading {
                            tag: tag as usize,
                            reading: reading(v, &uses[tag as usize]),
                            source_time: source_time(v),
                        })
                    })
                    .collect();
                readings.sort_by_key(|r| r.source_time);
                let _ = tx.send(SourceEvent::Readings(readings.into())).await;
            }
            Err(e) => {
                tracing::warn!(error = %e, "cannot read the tags' current values after reconnecting");
                return;
            }
        }
    }
}

/// Nodes read per call when catching up after a reactivation, or when
/// verifying the items.
pub(super) const READ_CHUNK: usize = 1000;
