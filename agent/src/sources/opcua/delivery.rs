//! Each publish's changes handed to the cell loop: in sequence-number
//! order across publishes ([`Sequence`]), in source-time order within one
//! publishing cycle — a cycle the server split over several publishes is
//! taken whole ([`InTimeOrder`]) — with what the server's queues dropped
//! said (the `opcua-overflow` alarm) and every loss said as a
//! [`SourceEvent::Gap`] before what follows it.

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use cellwatch_models::engine::{Reading, TagReading};
use opcua::client::{MonitoredItemMap, OnSubscriptionNotificationCore};
use opcua::types::{
    DataChangeNotification, DataValue, EventFieldList, EventNotificationList, NotificationMessage,
    StatusChangeNotification, StatusCode,
};
use tokio::sync::mpsc::error::TrySendError;
use tokio::sync::Notify;

use super::conditions::Conditions;
use super::items::{Items, Standing};
use super::names::Names;
use super::overflow::Overflow;
use super::republishes::Republishes;
use super::sequence::{Next, Sequence};
use super::subscription::{reading, source_time, Heard, Monitored, Uses, OVERFLOW_ALARM};
use crate::clock::Every;
use crate::sources::opcua::config::OpcUaConfig;
use crate::sources::{SourceEvent, SourceSender};

/// One subscription's delivery, shared by the session's notification
/// callback and the supervisor that fills gaps by `Republish`.
pub(super) struct Delivery {
    /// The subscription's id, once the server gave one.
    pub(super) id: u32,
    pub(super) sequence: Sequence,
    order: InTimeOrder,
    /// The connection was lost: publishes wait until the source knows
    /// whether it resumes without a loss.
    paused: bool,
    waiting: Vec<NotificationMessage>,
}

/// A [`Delivery`] behind its lock, and the supervisor's wake-up when a
/// publish is missing.
#[derive(Clone)]
pub(super) struct Shared {
    delivery: Arc<Mutex<Delivery>>,
    /// Woken when a publish is found missing.
    pub(super) missing: Arc<Notify>,
    /// Each monitored item's standing.
    pub(super) items: Arc<Mutex<Items>>,
    /// Woken when a monitored item fails.
    pub(super) failed: Arc<Notify>,
    /// Woken when the publishes of a cycle start being held for the rest
    /// of it: the supervisor hands them on if the rest never comes.
    pub(super) held: Arc<Notify>,
    /// The bounds on the `Republish` requests filling the gaps.
    republishes: Arc<Mutex<Republishes>>,
}

impl Shared {
    pub(super) fn lock(&self) -> MutexGuard<'_, Delivery> {
        self.delivery.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub(super) fn republishes(&self) -> MutexGuard<'_, Republishes> {
        self.republishes.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Delivery {
    /// Does what the sequence says, in order.
    pub(super) fn handle(&mut self, next: Vec<Next>) {
        for n in next {
            match n {
                Next::Deliver(m) => self.order.publish(m),
                Next::Lost { from, to } => {
                    let which = if from == to {
                        format!("publish {from}")
                    } else {
                        format!("publishes {from} to {to}")
                    };
                    self.order.gap(format!(
                        "{which} of subscription {} lost: the server no longer had them to send again",
                        self.id
                    ));
                }
            }
        }
    }

    /// Publishes are handed on as they come: none held back by a cut or
    /// for a missing one before them.
    pub(super) fn flowing(&self) -> bool {
        !self.paused && self.sequence.missing().is_none()
    }

    /// The connection is lost: what arrives after waits for
    /// [`Delivery::resume`] or [`Delivery::gap`].
    pub(super) fn pause(&mut self) {
        self.paused = true;
        // A cycle cut short by the loss: what came of it goes on now.
        self.order.flush();
    }

    /// The publishing interval the server granted: publishes stamped
    /// further apart than half of it are of different cycles.
    pub(super) fn granted(&mut self, interval: Duration) {
        self.order.cycle.interval = interval;
    }

    /// Hands on a cycle whose rest has not come for a publishing interval,
    /// or four times the longest wait seen between two publishes of a
    /// cycle if longer (a server slow to answer), when its last publish
    /// was full too. When to look again, if one is held still.
    pub(super) fn flush_stale(&mut self) -> Option<Instant> {
        self.order.cycle.since?;
        let cycle = &self.order.cycle;
        let until = cycle.last + cycle.interval.max(cycle.slowest * 4);
        if Instant::now() < until {
            return Some(until);
        }
        tracing::debug!(
            held = self.order.cycle.changes,
            "nothing more of a split publishing cycle came in time: judged as it came"
        );
        self.order.flush();
        None
    }

    /// The subscription goes on where it was, nothing lost: the cell loop
    /// is told so before the changes that follow, which it judges against
    /// the values from before the cut.
    pub(super) fn resume(&mut self) {
        if self.paused {
            send_blocking(&self.order.tx, SourceEvent::Resumed);
            self.unpause();
        }
    }

    fn unpause(&mut self) {
        self.paused = false;
        for m in std::mem::take(&mut self.waiting) {
            self.arrived(m);
        }
    }

    /// A publish, data or keep-alive, as it came: handed on in order.
    pub(super) fn arrived(&mut self, m: NotificationMessage) {
        if self.paused {
            if self.waiting.len() < super::sequence::MAX_HELD {
                self.waiting.push(m);
                return;
            }
            // Undecided for too long: on, as after a loss.
            self.unpause();
        }
        let mut next = Vec::new();
        self.sequence.arrived(m, &mut next);
        self.handle(next);
    }

    /// Changes were lost for good (`why`): said before what follows.
    pub(super) fn gap(&mut self, why: String) {
        self.order.gap(why);
        self.unpause();
    }
}

/// The library's notification callback: every publish goes through the
/// shared [`Delivery`].
pub(super) struct Feed(pub(super) Shared);

impl OnSubscriptionNotificationCore for Feed {
    fn on_subscription_notification(
        &mut self,
        notification: NotificationMessage,
        _items: MonitoredItemMap<'_>,
    ) {
        let mut d = self.0.lock();
        d.arrived(notification);
        if d.sequence.missing().is_some() {
            self.0.missing.notify_one();
        }
    }
}

/// Where a delivery tells what it has, and what it reads it with: the
/// tags' names, the PLC's alarms.
pub(super) struct Told {
    pub(super) tx: SourceSender,
    pub(super) names: Arc<Names>,
    pub(super) conditions: Arc<Mutex<Conditions>>,
}

/// A delivery for a subscription about to be created.
pub(super) fn delivery(
    monitored: Arc<Monitored>,
    uses: Arc<Uses>,
    told: Told,
    heard: Arc<Heard>,
    queue_size: Arc<AtomicU32>,
    config: &OpcUaConfig,
) -> Shared {
    let Told {
        tx,
        names,
        conditions,
    } = told;
    let items = Arc::new(Mutex::new(Items::new(monitored.len())));
    let bound = MAX_CYCLE.max(monitored.len() * CHANGES_PER_ITEM);
    let failed = Arc::new(Notify::new());
    let held = Arc::new(Notify::new());
    Shared {
        delivery: Arc::new(Mutex::new(Delivery {
            id: 0,
            sequence: Sequence::default(),
            paused: false,
            waiting: Vec::new(),
            order: InTimeOrder {
                monitored,
                uses,
                tx,
                heard,
                names,
                queue_size,
                overflow: Overflow::new(config.overflow_clear_after),
                items: items.clone(),
                failed: failed.clone(),
                conditions,
                cycle: Cycle {
                    full: config.max_notifications_per_publish as usize,
                    asked: config.max_notifications_per_publish as usize,
                    interval: config.publishing_interval,
                    bound,
                    held: Collected::default(),
                    since: None,
                    stamp: 0,
                    last: Instant::now(),
                    changes: 0,
                    slowest: Duration::ZERO,
                    told: held.clone(),
                    handed: None,
                    parted: Every::new(WARN_EVERY),
                    strangers: Every::new(WARN_EVERY),
                },
            },
        })),
        missing: Arc::new(Notify::new()),
        items,
        failed,
        held,
        republishes: Arc::new(Mutex::new(Republishes::new(Instant::now()))),
    }
}

/// Passes each publishing cycle's data changes to the engine in
/// source-time order.
///
/// A server sends the changes of one publish in no particular order; a
/// trigger processed before the change it depends on would leave a timer
/// unarmed. And a cycle with more changes than a publish may carry is
/// split over several, in the server's own order of items (async-opcua's
/// server goes through its items in hash order): a later change of one
/// tag may come a publish before an earlier change of another, and two
/// contacts never closed together would be seen closed together. So a
/// full publish ([`Cycle`]) is held for the rest of its cycle, the
/// library's own dispatch collects the cycle's changes ([`Collector`]),
/// then they are sorted by source timestamp (stable, so equal times keep
/// the server's order).
struct InTimeOrder {
    /// The node of client handle `i + 1`, and its tags.
    monitored: Arc<Monitored>,
    uses: Arc<Uses>,
    tx: SourceSender,
    heard: Arc<Heard>,
    names: Arc<Names>,
    /// The queue size the server granted.
    queue_size: Arc<AtomicU32>,
    /// Changes lost in the server's queues, and the alarm of them.
    overflow: Overflow,
    items: Arc<Mutex<Items>>,
    /// Woken when a monitored item fails.
    failed: Arc<Notify>,
    /// The PLC's own alarms, read from the publishes' events.
    conditions: Arc<Mutex<Conditions>>,
    cycle: Cycle,
}

/// The publishes of a cycle held for the rest of it.
///
/// Servers fill a publish up to `max_notifications_per_publish` and send
/// the rest of the cycle in the next (OPC UA Part 4, 5.13.5: the flag
/// `MoreNotifications`, which async-opcua's server sets only on the last
/// response it sends at once, and its client does not pass on): a full
/// publish may not be the last of its cycle, one with fewer is. A full
/// one is held; the cycle is handed on whole at the first that is not
/// full, before a publish stamped half a publishing interval or more
/// later (async-opcua stamps a cycle's publishes alike, open62541 and
/// node-opcua each as sent, when their order is already the order of
/// time), past `bound` changes held, or when the supervisor finds
/// nothing more of it came for a publishing interval, or four times the
/// longest wait seen between two publishes of a cycle (a last publish that
/// was full too).
struct Cycle {
    /// A publish with this many notifications is full (0: none is).
    full: usize,
    /// `opcua.max_notifications_per_publish`: what the agent asked.
    asked: usize,
    /// The publishing interval the server granted.
    interval: Duration,
    /// The most changes held ([`MAX_CYCLE`], or [`CHANGES_PER_ITEM`] per
    /// monitored item if more).
    bound: usize,
    /// What the held publishes said, read as they came.
    held: Collected,
    /// When the first held publish came, and its publish time (ticks).
    since: Option<Instant>,
    stamp: i64,
    /// When the last held publish came.
    last: Instant,
    /// The changes held.
    changes: usize,
    /// The longest wait seen between two publishes of one cycle, a
    /// sixteenth forgotten with each cycle.
    slowest: Duration,
    /// The supervisor, told when a cycle starts being held.
    told: Arc<Notify>,
    /// The last publish handed on as it came (not full, data in it): its
    /// notifications and publish time, to tell a server that sends fewer
    /// than asked.
    handed: Option<(usize, i64)>,
    /// Cycles judged in parts, warned of once a minute.
    parted: Every,
    /// Notifications for items the agent did not create, warned of once a
    /// minute.
    strangers: Every,
}

/// How often a warning that recurs with each publish is said.
const WARN_EVERY: Duration = Duration::from_secs(60);

/// The changes of one cycle held before they are handed on anyway, in a
/// cell of up to 25,000 monitored items: a 100,000-tag cell's whole cycle
/// at 1,000,000 changes/s and a 100 ms publishing interval.
const MAX_CYCLE: usize = 100_000;

/// A cycle of a cell with many monitored items is held up to this many
/// changes per item, if more than [`MAX_CYCLE`]: a server catching up after
/// falling behind sends several changes of an item in one cycle. Held as
/// readings (40 bytes each), a 100,000-item cell's bound is 16 MB.
const CHANGES_PER_ITEM: usize = 4;
const _: () = assert!(std::mem::size_of::<TagReading>() <= 40);

impl Cycle {
    /// `m` is of the cycle held (if one is).
    fn same(&self, m: &NotificationMessage) -> bool {
        let half = i64::try_from(self.interval.as_nanos() / 200).unwrap_or(i64::MAX);
        m.publish_time.ticks().abs_diff(self.stamp) < half.unsigned_abs()
    }
}

/// How many notifications (data changes and events) a publish carries.
fn notifications(m: &NotificationMessage) -> usize {
    m.notification_data
        .iter()
        .flatten()
        .map(|o| {
            if let Some(d) = o.inner_as::<DataChangeNotification>() {
                d.monitored_items.as_ref().map_or(0, Vec::len)
            } else if let Some(e) = o.inner_as::<EventNotificationList>() {
                e.events.as_ref().map_or(0, Vec::len)
            } else {
                0
            }
        })
        .sum()
}

/// What publishes said, read: their readings in the server's order, and
/// the rest.
#[derive(Default)]
struct Collected {
    /// An item failed.
    failed: bool,
    readings: Vec<TagReading>,
    /// Tags with a value flagged `Overflow`.
    overflowed: BTreeSet<usize>,
    /// Values flagged `Overflow`.
    lost: u64,
    /// A status change that ends the subscription: the server closed it.
    closed: Option<StatusCode>,
    /// Another bad status change, naming no item (Python asyncua's
    /// `BadNodeIdUnknown` for a node deleted under an item): the items
    /// are to be verified now.
    doubted: Option<StatusCode>,
    /// Events (the PLC's alarms), in the server's order.
    events: Vec<EventFieldList>,
    /// Notifications for a client handle the agent did not give: how many,
    /// and the first handle.
    strangers: Option<(u64, u32)>,
}

/// A status change that ends the subscription (Part 4 §7.25.4: `BadTimeout`
/// once its lifetime is over; a subscription, session or server gone).
/// Any other is about items, not the subscription.
fn ends_subscription(status: StatusCode) -> bool {
    matches!(
        status,
        StatusCode::BadTimeout
            | StatusCode::BadSubscriptionIdInvalid
            | StatusCode::BadNoSubscription
            | StatusCode::BadSessionClosed
            | StatusCode::BadSessionIdInvalid
            | StatusCode::BadShutdown
            | StatusCode::BadServerHalted
    )
}

/// Reads one publish into `out`.
fn collect(
    monitored: &Monitored,
    uses: &Uses,
    items: &Mutex<Items>,
    notification: NotificationMessage,
    out: &mut Collected,
) {
    let mut items = items.lock().unwrap_or_else(|e| e.into_inner());
    Collector {
        monitored,
        uses,
        items: &mut items,
        out,
    }
    .notification(notification);
}

/// Reads a publish's notifications.
struct Collector<'a> {
    monitored: &'a Monitored,
    uses: &'a Uses,
    items: &'a mut Items,
    out: &'a mut Collected,
}

impl Collector<'_> {
    fn notification(&mut self, notification: NotificationMessage) {
        for obj in notification.notification_data.into_iter().flatten() {
            if obj.inner_is::<DataChangeNotification>() {
                let Some(change) = obj.into_inner_as::<DataChangeNotification>() else {
                    continue;
                };
                let items = change.monitored_items.unwrap_or_default();
                self.out.readings.reserve(items.len());
                for n in items {
                    self.data_value(n.client_handle, n.value);
                }
            } else if obj.inner_is::<EventNotificationList>() {
                if let Some(list) = obj.into_inner_as::<EventNotificationList>() {
                    self.out.events.extend(list.events.unwrap_or_default());
                }
            } else if obj.inner_is::<StatusChangeNotification>() {
                if let Some(status) = obj.into_inner_as::<StatusChangeNotification>() {
                    if ends_subscription(status.status) {
                        self.out.closed = Some(status.status);
                    } else if status.status.is_bad() {
                        self.out.doubted = Some(status.status);
                    }
                }
            }
        }
    }

    fn data_value(&mut self, handle: u32, value: DataValue) {
        let Some(item) = (handle as usize)
            .checked_sub(1)
            .and_then(|i| self.monitored.items.get(i))
        else {
            let (n, _) = self.out.strangers.get_or_insert((0, handle));
            *n += 1;
            return;
        };
        if self.items.heard(handle as usize - 1, &value) == Standing::Failed {
            let status = value.status.unwrap_or(StatusCode::GoodNoData);
            self.items
                .fail(handle as usize - 1, status, std::time::Instant::now());
            self.out.failed = true;
        }
        let at = source_time(&value);
        let overflow = value.status.is_some_and(|s| s.overflow());
        // The usual node, one tag: its item says the tag and how it is
        // read, one look-up per change.
        if let Some(how) = item.one() {
            let reading = reading(&value, self.uses.kind(how));
            self.push(item.at, reading, at, overflow);
            return;
        }
        for &tag in self.monitored.several(*item) {
            let reading = reading(&value, &self.uses[tag as usize]);
            self.push(tag, reading, at, overflow);
        }
    }

    fn push(&mut self, tag: u32, reading: Reading, source_time: u64, overflow: bool) {
        let tag = tag as usize;
        if overflow {
            self.out.overflowed.insert(tag);
            self.out.lost += 1;
        }
        self.out.readings.push(TagReading {
            tag,
            reading,
            source_time,
        });
    }
}

impl InTimeOrder {
    /// Changes were lost for good: the cell loop is told before what
    /// follows. Said there, once (`cell/gaps.rs`: warned of at most once a
    /// minute, counted by the step in `cellwatch_source_gaps_total`), not
    /// here.
    fn gap(&mut self, why: String) {
        self.flush();
        send_blocking(
            &self.tx,
            SourceEvent::Gap {
                tags: None,
                values: 0,
                why,
            },
        );
    }

    /// A publish, in sequence: held if full (more of its cycle may
    /// follow), else handed on with the cycle held before it.
    fn publish(&mut self, notification: NotificationMessage) {
        // Keep-alives (no data) come here too: the subscription is alive.
        self.heard.beat();
        if self.cycle.since.is_some() {
            if self.cycle.same(&notification) {
                let waited = self.cycle.last.elapsed();
                self.cycle.slowest = self.cycle.slowest.max(waited);
            } else {
                self.flush();
            }
        }
        let count = notifications(&notification);
        let stamp = notification.publish_time.ticks();
        self.fewer_than_asked(stamp);
        let full = self.cycle.full > 0 && count >= self.cycle.full;
        let bound = self.cycle.bound;
        if full && self.cycle.changes + count >= bound {
            if let Some(cycles) = self.cycle.parted.happened(Instant::now()) {
                tracing::warn!(
                    held = self.cycle.changes,
                    "a publishing cycle of more than {bound} changes: judged in parts, \
                     their order across the parts not assured ({cycles} such since the \
                     last warning, said at most once a minute)"
                );
            }
        }
        if full && self.cycle.changes + count < bound {
            self.cycle.changes += count;
            self.cycle.last = Instant::now();
            if self.cycle.since.is_none() {
                self.cycle.since = Some(self.cycle.last);
                self.cycle.stamp = stamp;
                self.cycle.told.notify_one();
            }
            collect(
                &self.monitored,
                &self.uses,
                &self.items,
                notification,
                &mut self.cycle.held,
            );
            return;
        }
        self.cycle.handed = (!full && count > 0).then_some((count, stamp));
        self.hand_on(Some(notification));
    }

    /// A publish stamped `stamp` exactly as the one before, which was
    /// handed on as not full: the two are one cycle (a server stamps a
    /// cycle's publishes with one time, or each as it sends it), and the
    /// server sends fewer notifications a publish than the agent asked
    /// (the response does not say how many it grants). From now on a
    /// publish of that many is held for the rest of its cycle; the cycle
    /// that showed it was judged in parts.
    fn fewer_than_asked(&mut self, stamp: i64) {
        let Some((n, at)) = self.cycle.handed.take() else {
            return;
        };
        if at == stamp && n < self.cycle.full {
            tracing::warn!(
                "the server sends at most {n} notifications a publish, fewer than the {} asked \
                 (opcua.max_notifications_per_publish): a publish of {n} is held for the rest \
                 of its cycle from now on, and one cycle was judged in parts",
                self.cycle.asked
            );
            self.cycle.full = n;
        }
    }

    /// Hands on the cycle held, if one is (the rest of it will not come).
    fn flush(&mut self) {
        if self.cycle.since.is_some() {
            self.hand_on(None);
        }
    }

    /// Hands on the cycle held and `last`, their changes together.
    fn hand_on(&mut self, last: Option<NotificationMessage>) {
        // The start of the agent's own latency: the cycle's first publish
        // is decoded, its values not yet looked at.
        let received = self.cycle.since.take().unwrap_or_else(Instant::now);
        let mut c = std::mem::take(&mut self.cycle.held);
        if self.cycle.changes > 0 {
            self.cycle.changes = 0;
            self.cycle.slowest -= self.cycle.slowest / 16;
        }
        if let Some(m) = last {
            collect(&self.monitored, &self.uses, &self.items, m, &mut c);
        }
        if c.failed {
            self.failed.notify_one();
        }
        let Collected {
            mut readings,
            overflowed,
            lost,
            closed,
            doubted,
            events,
            strangers,
            ..
        } = c;
        if let Some((n, handle)) = strangers {
            if let Some(publishes) = self.cycle.strangers.happened(Instant::now()) {
                tracing::warn!(
                    handle,
                    "{n} notifications for monitored items this agent did not create, \
                     ignored ({publishes} publishes with such since the last warning, said \
                     at most once a minute)"
                );
            }
        }
        // The PLC's alarms after the values of the same publish.
        let conditions = (!events.is_empty()).then(|| {
            self.conditions
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .events(events, crate::clock::now_ms())
        });
        if let Some(status) = closed {
            // The supervisor sees it and subscribes again.
            tracing::warn!(%status, "the server closed the subscription");
            self.heard.closed.store(status.bits(), Ordering::Relaxed);
        } else if let Some(status) = doubted {
            // The subscription goes on; which item it means, a
            // verification finds.
            tracing::info!(%status, "a status change for no item in particular: verifying the items now");
            self.heard.doubted.store(true, Ordering::Relaxed);
            self.failed.notify_one();
        }
        // Overflow bookkeeping only while changes are being lost: the usual
        // publish costs one test here. Keep-alives count, so the alarm
        // clears on a quiet subscription too.
        let say = (lost > 0 || self.overflow.said.is_some())
            && self.overflow.publish(&overflowed, lost, received);
        let problem = say.then(|| {
            let problem = self.overflow.say(
                &self.names,
                self.queue_size.load(Ordering::Relaxed),
                received,
            );
            match &problem {
                Some(text) => tracing::warn!("{text}"),
                None => tracing::info!("no change lost in the server's queues for a while"),
            }
            SourceEvent::Problem {
                id: OVERFLOW_ALARM.into(),
                problem,
            }
        });
        if readings.is_empty() {
            for e in problem.into_iter().chain(conditions.into_iter().flatten()) {
                send_blocking(&self.tx, e);
            }
            return;
        }
        readings.sort_by_key(|r| r.source_time);
        self.heard.busy.store(true, Ordering::Relaxed);
        if lost > 0 {
            // The values behind the loss are judged knowing it.
            let tags: Vec<usize> = overflowed.iter().copied().collect();
            let mut names: Vec<&str> = tags.iter().take(5).map(|&t| &self.names[t][..]).collect();
            if tags.len() > names.len() {
                names.push("...");
            }
            send_blocking(
                &self.tx,
                SourceEvent::Gap {
                    why: format!(
                        "the server's queue dropped changes before this value ({})",
                        names.join(", ")
                    ),
                    tags: Some(tags),
                    values: lost,
                },
            );
        }
        send_blocking(
            &self.tx,
            SourceEvent::Readings(crate::sources::Batch { readings, received }),
        );
        for e in problem.into_iter().chain(conditions.into_iter().flatten()) {
            send_blocking(&self.tx, e);
        }
        self.heard.beat();
        self.heard.busy.store(false, Ordering::Relaxed);
    }
}

/// Sends from the session's (synchronous) notification callback. When the
/// cell loop is behind and the channel full, the callback waits: the
/// session's event loop stops taking publishes, and the server's queues
/// hold the changes. Nothing is dropped here.
fn send_blocking(tx: &SourceSender, event: SourceEvent) {
    let event = match tx.try_send(event) {
        Ok(()) | Err(TrySendError::Closed(_)) => return,
        Err(TrySendError::Full(event)) => event,
    };
    match tokio::runtime::Handle::try_current().map(|h| h.runtime_flavor()) {
        Ok(tokio::runtime::RuntimeFlavor::CurrentThread) => {
            // A single-threaded runtime cannot block here without stopping
            // the loop that would empty the channel.
            tracing::error!(
                "the cell loop is behind on a single-threaded runtime; a publish is dropped"
            );
        }
        Ok(_) => {
            let _ = tokio::task::block_in_place(|| tx.blocking_send(event));
        }
        Err(_) => {
            let _ = tx.blocking_send(event);
        }
    }
}

#[cfg(test)]
pub(super) mod tests;
