//! The edge node's MQTT session: one task that owns the client and the
//! node's sequence numbers, and one beside it that drives the connection
//! (rumqttc's event loop), reconnects with a growing wait, and sets the
//! next connection's will (NDEATH with the next bdSeq, kept in the store
//! before the CONNECT so the count goes on after a restart) before it.
//!
//! Each time the broker takes the session the node subscribes to its
//! commands (and its primary host's `STATE`), then, once the primary host
//! is online (at once without one), publishes NBIRTH (sequence 0, bdSeq,
//! `Node Control/Rebirth`), DBIRTH (every metric) and the changes held
//! while it could not publish, flagged historical, oldest first: those in
//! the store, then those still in memory; then each change as DDATA.
//! While it cannot publish, every change goes to the store (`store.rs`) as
//! it comes, so a restart or a kill loses none. When the primary host says
//! it is offline (a `STATE` not older than its last online one) the node
//! publishes its NDEATH, disconnects and connects again, to be born when
//! the host is back. A rebirth is the same births again on the same
//! session: asked by NCMD `Node Control/Rebirth`, or needed because an
//! alarm the device had not declared appeared. A clean stop says NDEATH
//! before it disconnects; anything else leaves the broker to say the will.
//!
//! The device lives while the cell's PLC link is up. When a step says the
//! link went down, the changes that came before (the machine state
//! `offline`) go out as DDATA, then DDEATH with the next sequence number;
//! while it is dead no DDATA is sent for it and its changes are held.
//! When the link is back, DBIRTH with every current value, then what was
//! held as history. A node born while its device is dead sends NBIRTH
//! alone.
//!
//! DDATA goes at QoS 0, as Sparkplug says: a change handed to the
//! connection in the moment the broker goes away, before the loss is
//! seen, is lost with it.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use prost::Message as _;
use rumqttc::{
    AsyncClient, ConnectReturnCode, Event, EventLoop, LastWill, MqttOptions, Outgoing, Packet,
    Publish, QoS, TlsConfiguration, Transport,
};
use tokio::sync::{mpsc, watch};

use super::book::{asks_rebirth, device_death, node_death, MetricChange};
use super::config::SparkplugConfig;
use super::events::SparkplugEvent;
use super::files::{password, tls};
use super::host::{HostSaid, HostState, PrimaryHost};
use super::shared::{Shared, SparkplugError};
use super::store::{HeldStore, StoreError};
use super::tahu::Payload;
use super::topics::Topics;
use crate::backoff::Backoff;
use crate::metrics::Metrics;

/// How often the session is kept alive (the broker says the will after
/// one and a half of these without a word).
const KEEP_ALIVE: Duration = Duration::from_secs(30);

/// The waits between connection attempts.
const FIRST_RETRY: Duration = Duration::from_secs(1);
const MAX_RETRY: Duration = Duration::from_secs(30);

/// The most metrics one DDATA carries.
const METRICS_PER_MESSAGE: usize = 500;

/// How long a message may wait to be taken by the connection.
const PUBLISH_TIMEOUT: Duration = Duration::from_secs(5);

/// Messages waiting for the connection.
const REQUESTS: usize = 256;

/// Commands and host states waiting for the session; more are dropped.
const INCOMING: usize = 64;

/// The largest message taken from the broker (commands and host states
/// are small) and sent to it (a birth of many alarms is not).
const MAX_INCOMING: usize = 256 * 1024;
const MAX_OUTGOING: usize = 64 * 1024 * 1024;

/// What the connection's task says of the connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Link {
    /// The broker holds the session.
    connected: bool,
    /// Counts the sessions the broker took.
    generation: u64,
    /// The session's bdSeq (its will's).
    bd_seq: u64,
}

/// The edge node's session, ready to run.
pub(crate) struct Session {
    options: MqttOptions,
    /// `host:port`, for logs.
    broker: String,
    topics: Topics,
    primary_host: Option<String>,
    /// The bdSeq of the first CONNECT: one past the last one kept.
    first_bd_seq: u64,
    shared: Arc<Shared>,
    metrics: Arc<Metrics>,
}

/// The node's standing in the current session.
struct Node {
    client: AsyncClient,
    connected: bool,
    generation: u64,
    bd_seq: u64,
    /// The primary host is online (always, without one).
    host_online: bool,
    /// The primary host's `STATE` timestamps, across sessions.
    host: PrimaryHost,
    /// NBIRTH was published in this session and nothing since asks for it
    /// again.
    born: bool,
    /// DBIRTH was published after it, and no DDEATH since.
    device_born: bool,
    /// The next message's sequence number, 0–255.
    seq: u64,
}

impl Node {
    fn next_seq(&mut self) -> u64 {
        let seq = self.seq;
        self.seq = (self.seq + 1) % 256;
        seq
    }
}

impl Session {
    pub(super) fn new(
        config: &SparkplugConfig,
        shared: Arc<Shared>,
        metrics: Arc<Metrics>,
    ) -> Result<Session, SparkplugError> {
        let topics = Topics::of(config);
        let first_bd_seq = shared
            .store()
            .last_bd_seq()?
            .map_or(0, |last| (last + 1) % 256);
        let mut options = MqttOptions::new(
            format!("cellwatch-{}-{}", config.group_id, config.edge_node_id),
            config.broker.host.clone(),
            config.broker.port,
        );
        options
            .set_keep_alive(KEEP_ALIVE)
            .set_clean_session(true)
            .set_max_packet_size(MAX_INCOMING, MAX_OUTGOING)
            .set_request_channel_capacity(REQUESTS)
            .set_last_will(will(&topics.ndeath, first_bd_seq));
        if let Some(c) = &config.credentials {
            let password = match &c.password_file {
                Some(f) => password(f)?,
                None => String::new(),
            };
            options.set_credentials(c.username.clone(), password);
        }
        if config.broker.secure {
            let tls = tls(config.tls.as_ref())?;
            options.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(
                Arc::new(tls),
            )));
        }
        Ok(Session {
            options,
            broker: format!("{}:{}", config.broker.host, config.broker.port),
            topics,
            primary_host: config.primary_host.clone(),
            first_bd_seq,
            shared,
            metrics,
        })
    }

    /// Runs until the sink closes: then says NDEATH and disconnects.
    pub(crate) async fn run(self) {
        let (client, eventloop) = AsyncClient::new(self.options.clone(), REQUESTS);
        let (link_tx, mut link) = watch::channel(Link {
            connected: false,
            generation: 0,
            bd_seq: 0,
        });
        let (in_tx, mut incoming) = mpsc::channel(INCOMING);
        let connection = tokio::spawn(connect(
            eventloop,
            Will {
                ndeath: self.topics.ndeath.clone(),
                first_bd_seq: self.first_bd_seq,
            },
            self.broker.clone(),
            link_tx,
            in_tx,
            self.shared.clone(),
            self.metrics.clone(),
        ));
        let mut node = Node {
            client,
            connected: false,
            generation: 0,
            bd_seq: 0,
            host_online: self.primary_host.is_none(),
            host: PrimaryHost::default(),
            born: false,
            device_born: false,
            seq: 0,
        };
        while !self.shared.closed.load(Ordering::Acquire) {
            tokio::select! {
                changed = link.changed() => {
                    if changed.is_err() {
                        break;
                    }
                    let now = *link.borrow_and_update();
                    self.on_link(&mut node, now).await;
                }
                Some(message) = incoming.recv() => self.on_message(&mut node, &message).await,
                () = self.shared.wake.notified() => {}
            }
            if node.connected && node.host_online {
                self.catch_up(&mut node).await;
            } else {
                self.spill().await;
            }
        }
        if node.connected && node.host_online && node.born {
            self.catch_up(&mut node).await;
        }
        self.spill().await;
        if node.connected {
            let death = node_death(node.bd_seq, crate::clock::now_ms());
            self.publish(&node, &self.topics.ndeath, "ndeath", &death)
                .await;
            let _ = node.client.disconnect().await;
        }
        drop(node);
        if tokio::time::timeout(PUBLISH_TIMEOUT, connection)
            .await
            .is_err()
        {
            tracing::warn!("sparkplug: the MQTT connection did not close in time");
        }
    }

    /// The connection changed.
    async fn on_link(&self, node: &mut Node, link: Link) {
        if !link.connected {
            node.connected = false;
            node.born = false;
            return;
        }
        if link.generation == node.generation {
            return;
        }
        node.generation = link.generation;
        node.bd_seq = link.bd_seq;
        node.connected = true;
        node.born = false;
        node.host_online = self.primary_host.is_none();
        let mut topics = vec![self.topics.ncmd.clone(), self.topics.dcmd.clone()];
        topics.extend(self.topics.state.clone());
        for topic in topics {
            if let Err(e) = node.client.subscribe(topic, QoS::AtLeastOnce).await {
                tracing::warn!("sparkplug: cannot subscribe: {e}");
            }
        }
    }

    /// A command or the primary host's state arrived.
    async fn on_message(&self, node: &mut Node, message: &Publish) {
        let m = &self.metrics.sparkplug;
        let topic = message.topic.as_str();
        if topic == self.topics.ncmd {
            match Payload::decode(message.payload.as_ref()) {
                Ok(command) if asks_rebirth(&command) => {
                    SparkplugEvent::Rebirth {
                        why: "NCMD Node Control/Rebirth",
                    }
                    .emit(m);
                    node.born = false;
                }
                _ => SparkplugEvent::CommandIgnored { topic }.emit(m),
            }
        } else if let (Some(host), true) = (
            self.primary_host.as_deref(),
            Some(topic) == self.topics.state.as_deref(),
        ) {
            let heard = match HostState::parse(&message.payload) {
                Some(state) => node.host.heard(state),
                None => HostSaid::Stale,
            };
            SparkplugEvent::PrimaryHost { host, heard }.emit(m);
            match heard {
                HostSaid::Online => {
                    if !node.host_online {
                        node.born = false;
                    }
                    node.host_online = true;
                }
                HostSaid::Offline => {
                    node.host_online = false;
                    if node.born {
                        self.leave(node).await;
                    }
                }
                HostSaid::Stale => {}
            }
        } else {
            SparkplugEvent::CommandIgnored { topic }.emit(m);
        }
    }

    /// Publishes what the node owes the host, in order, until only data is
    /// left (then sent) or a message is not taken: the births, the
    /// device's death or its birth again.
    async fn catch_up(&self, node: &mut Node) {
        loop {
            let (up, died, grown) = {
                let book = self.shared.book();
                (book.device_up(), book.died(), book.grown())
            };
            let done = if !node.born || (grown && node.device_born) {
                self.birth(node).await
            } else if node.device_born && died {
                self.device_death(node).await
            } else if !node.device_born && up {
                self.device_birth(node).await
            } else {
                if node.device_born {
                    self.data(node).await;
                }
                return;
            };
            if !done {
                return;
            }
        }
    }

    /// NBIRTH, then the device's birth when it is alive; whether all was
    /// taken.
    async fn birth(&self, node: &mut Node) -> bool {
        let now = crate::clock::now_ms();
        node.seq = 0;
        node.device_born = false;
        let nbirth = self.shared.book().node_birth(node.bd_seq, now);
        node.next_seq();
        if !self
            .publish(node, &self.topics.nbirth, "nbirth", &nbirth)
            .await
        {
            return false;
        }
        node.born = true;
        if !self.shared.book().device_up() {
            return true;
        }
        self.device_birth(node).await
    }

    /// DBIRTH and the held changes as history; whether all was taken.
    async fn device_birth(&self, node: &mut Node) -> bool {
        let now = crate::clock::now_ms();
        let seq = node.next_seq();
        let (dbirth, held) = self.shared.book().device_birth(seq, now);
        if !self
            .publish(node, &self.topics.dbirth, "dbirth", &dbirth)
            .await
        {
            self.shared.book().hold_again(held);
            node.born = false;
            return false;
        }
        node.device_born = true;
        if !self.stored_history(node, now).await {
            self.shared.book().hold_again(held);
            return false;
        }
        self.send_all(node, held, now, true).await
    }

    /// The changes from before the device's death as DDATA, then DDEATH;
    /// whether all was taken.
    async fn device_death(&self, node: &mut Node) -> bool {
        let now = crate::clock::now_ms();
        let before = self.shared.book().take_before_death();
        if !self.send_all(node, before, now, false).await {
            return false;
        }
        SparkplugEvent::DeviceDeath { seq: node.seq }.emit(&self.metrics.sparkplug);
        let death = device_death(node.next_seq(), now);
        node.device_born = false;
        if !self
            .publish(node, &self.topics.ddeath, "ddeath", &death)
            .await
        {
            // Its sequence number is spent: the host would see a gap.
            node.born = false;
            return false;
        }
        true
    }

    /// `changes` as DDATA, flagged historical or not, in messages of at
    /// most [`METRICS_PER_MESSAGE`]; those not taken are held again.
    /// Whether all were taken.
    async fn send_all(
        &self,
        node: &mut Node,
        mut changes: Vec<MetricChange>,
        now: u64,
        historical: bool,
    ) -> bool {
        while !changes.is_empty() {
            let rest = changes.split_off(changes.len().min(METRICS_PER_MESSAGE));
            if !self.ddata(node, changes.clone(), now, historical).await {
                changes.extend(rest);
                self.shared.book().hold_again(changes);
                return false;
            }
            changes = rest;
        }
        true
    }

    /// The node's primary host said it is offline: NDEATH, then the
    /// connection is closed; the connection's task connects again.
    async fn leave(&self, node: &mut Node) {
        SparkplugEvent::HostOffline {
            bd_seq: node.bd_seq,
        }
        .emit(&self.metrics.sparkplug);
        let death = node_death(node.bd_seq, crate::clock::now_ms());
        self.publish(node, &self.topics.ndeath, "ndeath", &death)
            .await;
        if let Err(e) = node.client.disconnect().await {
            tracing::warn!("sparkplug: cannot disconnect: {e}");
        }
        node.connected = false;
        node.born = false;
        node.device_born = false;
    }

    /// The changes in the store as history, oldest first, each forgotten
    /// once handed to the connection; whether all were.
    async fn stored_history(&self, node: &mut Node, now: u64) -> bool {
        loop {
            let rows = match self.with_store(|s| s.oldest(METRICS_PER_MESSAGE)).await {
                Ok(rows) => rows,
                Err(e) => {
                    SparkplugEvent::StoreFailed {
                        why: &e.to_string(),
                    }
                    .emit(&self.metrics.sparkplug);
                    return true;
                }
            };
            let Some(last) = rows.last().map(|r| r.id) else {
                return true;
            };
            let (changes, unknown) = self.shared.book().changes_of(rows);
            if unknown > 0 {
                SparkplugEvent::Undeclared { count: unknown }.emit(&self.metrics.sparkplug);
            }
            if !changes.is_empty() && !self.ddata(node, changes, now, true).await {
                return false;
            }
            if let Err(e) = self.with_store(move |s| s.forget_through(last)).await {
                SparkplugEvent::StoreFailed {
                    why: &e.to_string(),
                }
                .emit(&self.metrics.sparkplug);
                return true;
            }
            self.count_held();
        }
    }

    /// The waiting changes into the store: the node cannot publish them.
    async fn spill(&self) {
        let rows = {
            let mut book = self.shared.book();
            let changes = book.take_all();
            if changes.is_empty() {
                return;
            }
            book.to_rows(changes)
        };
        let kept = rows.clone();
        match self.with_store(move |s| s.append(&rows)).await {
            Ok(0) => {}
            Ok(count) => SparkplugEvent::Dropped { count }.emit(&self.metrics.sparkplug),
            Err(e) => {
                SparkplugEvent::StoreFailed {
                    why: &e.to_string(),
                }
                .emit(&self.metrics.sparkplug);
                let mut book = self.shared.book();
                let (changes, _) = book.changes_of(kept);
                book.hold_again(changes);
            }
        }
        self.count_held();
    }

    /// Runs `f` on the store on a blocking thread; then notes how many
    /// rows it holds.
    async fn with_store<T: Send + 'static>(
        &self,
        f: impl FnOnce(&mut HeldStore) -> Result<T, StoreError> + Send + 'static,
    ) -> Result<T, StoreError> {
        let shared = self.shared.clone();
        tokio::task::spawn_blocking(move || {
            let mut store = shared.store();
            let out = f(&mut store);
            shared.stored.store(store.rows(), Ordering::Release);
            out
        })
        .await
        .unwrap_or_else(|e| std::panic::resume_unwind(e.into_panic()))
    }

    /// Sets the held gauge: in memory and in the store.
    fn count_held(&self) {
        self.metrics.sparkplug.held.set(self.shared.held() as i64);
    }

    /// The waiting changes as DDATA.
    async fn data(&self, node: &mut Node) {
        loop {
            let changes = self.shared.book().take_changes(METRICS_PER_MESSAGE);
            self.count_held();
            if changes.is_empty() {
                return;
            }
            if !self
                .ddata(node, changes.clone(), crate::clock::now_ms(), false)
                .await
            {
                self.shared.book().hold_again(changes);
                self.count_held();
                return;
            }
        }
    }

    async fn ddata(
        &self,
        node: &mut Node,
        changes: Vec<MetricChange>,
        now: u64,
        historical: bool,
    ) -> bool {
        let seq = node.next_seq();
        let payload = self.shared.book().data(changes, seq, now, historical);
        let sent = self
            .publish(node, &self.topics.ddata, "ddata", &payload)
            .await;
        if !sent {
            // Its sequence number is spent: the host would see a gap.
            node.born = false;
        }
        sent
    }

    /// Hands `payload` to the connection; whether it took it. A message
    /// lost asks for a rebirth (the host sees a gap in the sequence).
    async fn publish(
        &self,
        node: &Node,
        topic: &str,
        kind: &'static str,
        payload: &Payload,
    ) -> bool {
        let sent = tokio::time::timeout(
            PUBLISH_TIMEOUT,
            node.client
                .publish(topic, QoS::AtMostOnce, false, payload.encode_to_vec()),
        )
        .await;
        let m = &self.metrics.sparkplug;
        match sent {
            Ok(Ok(())) => {
                SparkplugEvent::Published { kind }.emit(m);
                true
            }
            Ok(Err(e)) => {
                SparkplugEvent::Failed {
                    kind,
                    why: &e.to_string(),
                }
                .emit(m);
                false
            }
            Err(_) => {
                SparkplugEvent::Failed {
                    kind,
                    why: "the connection did not take it in time",
                }
                .emit(m);
                false
            }
        }
    }
}

/// The node's will as the connection's task sets it.
struct Will {
    /// The NDEATH topic.
    ndeath: String,
    /// The bdSeq of the first CONNECT.
    first_bd_seq: u64,
}

/// Drives the connection: reconnects with a growing wait, the next
/// session's will carrying the next bdSeq; says each session taken and
/// lost on `link`, and hands commands and host states to `incoming`.
async fn connect(
    mut eventloop: EventLoop,
    will_of: Will,
    broker: String,
    link: watch::Sender<Link>,
    incoming: mpsc::Sender<Publish>,
    shared: Arc<Shared>,
    metrics: Arc<Metrics>,
) {
    let m = &metrics.sparkplug;
    let ndeath = will_of.ndeath;
    let mut bd_seq = will_of.first_bd_seq;
    keep_bd_seq(&shared, bd_seq, m).await;
    let mut generation = 0;
    let mut backoff = Backoff::new(FIRST_RETRY, MAX_RETRY);
    // Attempts failed in a row since the last connection.
    let mut failures = 0u32;
    loop {
        match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(ack))) if ack.code == ConnectReturnCode::Success => {
                backoff.reset();
                failures = 0;
                generation += 1;
                SparkplugEvent::Connected {
                    broker: &broker,
                    bd_seq,
                }
                .emit(m);
                link.send_replace(Link {
                    connected: true,
                    generation,
                    bd_seq,
                });
            }
            Ok(Event::Incoming(Packet::Publish(p))) => {
                if incoming.try_send(p).is_err() {
                    m.commands_ignored.inc();
                }
            }
            Ok(Event::Outgoing(Outgoing::Disconnect)) => {
                if shared.closed.load(Ordering::Acquire) {
                    break;
                }
                // The node left (its primary host is offline). The broker
                // closes the connection once it has read the DISCONNECT
                // (and dropped the will); a new CONNECT under the same
                // client id before that would make it say the will.
                let closed = tokio::time::timeout(PUBLISH_TIMEOUT, async {
                    while eventloop.poll().await.is_ok() {}
                })
                .await;
                if closed.is_err() {
                    eventloop.clean();
                }
                link.send_replace(Link {
                    connected: false,
                    generation,
                    bd_seq,
                });
                m.connected.set(0);
                bd_seq = (bd_seq + 1) % 256;
                keep_bd_seq(&shared, bd_seq, m).await;
                eventloop.mqtt_options.set_last_will(will(&ndeath, bd_seq));
            }
            Ok(_) => {}
            Err(e) => {
                failures += 1;
                SparkplugEvent::Disconnected {
                    broker: &broker,
                    why: &e.to_string(),
                    failures,
                }
                .emit(m);
                link.send_replace(Link {
                    connected: false,
                    generation,
                    bd_seq,
                });
                if link.is_closed() {
                    break;
                }
                bd_seq = (bd_seq + 1) % 256;
                keep_bd_seq(&shared, bd_seq, m).await;
                eventloop.mqtt_options.set_last_will(will(&ndeath, bd_seq));
                tokio::time::sleep(backoff.next_wait()).await;
            }
        }
    }
    m.connected.set(0);
}

/// Keeps `bd_seq` in the store before the CONNECT that carries it.
async fn keep_bd_seq(shared: &Arc<Shared>, bd_seq: u64, m: &crate::metrics::SparkplugMetrics) {
    let shared = shared.clone();
    let kept = tokio::task::spawn_blocking(move || shared.store().keep_bd_seq(bd_seq)).await;
    match kept {
        Ok(Ok(())) => {}
        Ok(Err(e)) => SparkplugEvent::StoreFailed {
            why: &e.to_string(),
        }
        .emit(m),
        Err(e) => std::panic::resume_unwind(e.into_panic()),
    }
}

/// The node's will: NDEATH with `bd_seq`.
fn will(ndeath: &str, bd_seq: u64) -> LastWill {
    LastWill::new(
        ndeath,
        node_death(bd_seq, crate::clock::now_ms()).encode_to_vec(),
        QoS::AtLeastOnce,
        false,
    )
}
