//! The edge node's MQTT session: one task that owns the client and the
//! node's sequence numbers, and one beside it that drives the connection
//! (rumqttc's event loop), reconnects with a growing wait, and sets the
//! next connection's will (NDEATH with the next bdSeq) before it.
//!
//! Each time the broker takes the session the node subscribes to its
//! commands (and its primary host's `STATE`), then, once the primary host
//! is online (at once without one), publishes NBIRTH (sequence 0, bdSeq,
//! `Node Control/Rebirth`), DBIRTH (every metric) and the changes held
//! while it could not publish, flagged historical; then each change as
//! DDATA. A rebirth is the same births again on the same session: asked by
//! NCMD `Node Control/Rebirth`, or needed because an alarm the device had
//! not declared appeared. A clean stop says NDEATH before it disconnects;
//! anything else leaves the broker to say the will.

use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use prost::Message as _;
use rumqttc::{
    AsyncClient, ConnectReturnCode, Event, EventLoop, LastWill, MqttOptions, Outgoing, Packet,
    Publish, QoS, TlsConfiguration, Transport,
};
use tokio::sync::{mpsc, watch};

use super::book::{asks_rebirth, node_death, Change};
use super::config::{SparkplugConfig, SparkplugTls};
use super::events::SparkplugEvent;
use super::shared::{Shared, SparkplugError};
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
pub struct Session {
    options: MqttOptions,
    /// `host:port`, for logs.
    broker: String,
    topics: Topics,
    primary_host: Option<String>,
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
    /// NBIRTH and DBIRTH were published in this session and nothing since
    /// asks for them again.
    born: bool,
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
            .set_last_will(will(&topics.ndeath, 0));
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
            shared,
            metrics,
        })
    }

    /// Runs until the sink closes: then says NDEATH and disconnects.
    pub async fn run(self) {
        let (client, eventloop) = AsyncClient::new(self.options.clone(), REQUESTS);
        let (link_tx, mut link) = watch::channel(Link {
            connected: false,
            generation: 0,
            bd_seq: 0,
        });
        let (in_tx, mut incoming) = mpsc::channel(INCOMING);
        let connection = tokio::spawn(connect(
            eventloop,
            self.topics.ndeath.clone(),
            self.broker.clone(),
            link_tx,
            in_tx,
            self.metrics.clone(),
        ));
        let mut node = Node {
            client,
            connected: false,
            generation: 0,
            bd_seq: 0,
            host_online: self.primary_host.is_none(),
            born: false,
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
                Some(message) = incoming.recv() => self.on_message(&mut node, &message),
                () = self.shared.wake.notified() => {}
            }
            if node.connected && node.host_online {
                if !node.born || self.shared.book().grown() {
                    self.birth(&mut node).await;
                } else {
                    self.data(&mut node).await;
                }
            }
        }
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
    fn on_message(&self, node: &mut Node, message: &Publish) {
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
        } else if Some(topic) == self.topics.state.as_deref() {
            let online = host_online(&message.payload);
            if let Some(host) = &self.primary_host {
                SparkplugEvent::PrimaryHost { host, online }.emit(m);
            }
            if online && !node.host_online {
                node.born = false;
            }
            node.host_online = online;
        } else {
            SparkplugEvent::CommandIgnored { topic }.emit(m);
        }
    }

    /// NBIRTH, DBIRTH and the held changes as history.
    async fn birth(&self, node: &mut Node) {
        let now = crate::clock::now_ms();
        node.seq = 0;
        let nbirth = self.shared.book().node_birth(node.bd_seq, now);
        node.next_seq();
        if !self
            .publish(node, &self.topics.nbirth, "nbirth", &nbirth)
            .await
        {
            return;
        }
        let seq = node.next_seq();
        let (dbirth, held) = self.shared.book().device_birth(seq, now);
        if !self
            .publish(node, &self.topics.dbirth, "dbirth", &dbirth)
            .await
        {
            return;
        }
        node.born = true;
        let mut held = held;
        while !held.is_empty() {
            let rest = held.split_off(held.len().min(METRICS_PER_MESSAGE));
            if !self.ddata(node, held, now, true).await {
                return;
            }
            held = rest;
        }
        self.data(node).await;
    }

    /// The waiting changes as DDATA.
    async fn data(&self, node: &mut Node) {
        loop {
            let changes = self.shared.book().take_changes(METRICS_PER_MESSAGE);
            self.metrics
                .sparkplug
                .held
                .set(self.shared.book().held() as i64);
            if changes.is_empty()
                || !self
                    .ddata(node, changes, crate::clock::now_ms(), false)
                    .await
            {
                return;
            }
        }
    }

    async fn ddata(
        &self,
        node: &mut Node,
        changes: Vec<Change>,
        now: u64,
        historical: bool,
    ) -> bool {
        let seq = node.next_seq();
        let payload = self.shared.book().data(changes, seq, now, historical);
        self.publish(node, &self.topics.ddata, "ddata", &payload)
            .await
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

/// Drives the connection: reconnects with a growing wait, the next
/// session's will carrying the next bdSeq; says each session taken and
/// lost on `link`, and hands commands and host states to `incoming`.
async fn connect(
    mut eventloop: EventLoop,
    ndeath: String,
    broker: String,
    link: watch::Sender<Link>,
    incoming: mpsc::Sender<Publish>,
    metrics: Arc<Metrics>,
) {
    let m = &metrics.sparkplug;
    let mut bd_seq = 0;
    let mut generation = 0;
    let mut backoff = Backoff::new(FIRST_RETRY, MAX_RETRY);
    loop {
        match eventloop.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(ack))) if ack.code == ConnectReturnCode::Success => {
                backoff.reset();
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
            Ok(Event::Outgoing(Outgoing::Disconnect)) => break,
            Ok(_) => {}
            Err(e) => {
                SparkplugEvent::Disconnected {
                    broker: &broker,
                    why: &e.to_string(),
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
                eventloop.mqtt_options.set_last_will(will(&ndeath, bd_seq));
                tokio::time::sleep(backoff.next_wait()).await;
            }
        }
    }
    m.connected.set(0);
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

/// Whether a primary host's `STATE` says online: Sparkplug 3.0's JSON
/// (`{"online": true, "timestamp": …}`) or the older `ONLINE`.
fn host_online(payload: &[u8]) -> bool {
    #[derive(serde::Deserialize)]
    struct State {
        online: bool,
    }
    match serde_json::from_slice::<State>(payload) {
        Ok(s) => s.online,
        Err(_) => payload == b"ONLINE",
    }
}

/// The first line of the password file (owner-only).
fn password(path: &Path) -> Result<String, SparkplugError> {
    crate::bus::envelope::check_private(path)?;
    let text = std::fs::read_to_string(path).map_err(|source| SparkplugError::Password {
        path: path.display().to_string(),
        source,
    })?;
    Ok(text.lines().next().unwrap_or_default().to_string())
}

/// TLS trusting `tls`'s CA, presenting its client certificate if any.
fn tls(tls: Option<&SparkplugTls>) -> Result<tokio_rustls::rustls::ClientConfig, SparkplugError> {
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let bad = |path: &Path, why: String| SparkplugError::Tls {
        path: path.display().to_string(),
        why,
    };
    let mut roots = rustls::RootCertStore::empty();
    let mut identity = None;
    if let Some(t) = tls {
        let cas: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(&t.ca)
            .and_then(Iterator::collect)
            .map_err(|e| bad(&t.ca, e.to_string()))?;
        if cas.is_empty() {
            return Err(bad(&t.ca, "no certificate in the file".into()));
        }
        for ca in cas {
            roots.add(ca).map_err(|e| bad(&t.ca, e.to_string()))?;
        }
        if let Some((cert, key)) = &t.client {
            crate::bus::envelope::check_private(key)?;
            let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(cert)
                .and_then(Iterator::collect)
                .map_err(|e| bad(cert, e.to_string()))?;
            let key = PrivateKeyDer::from_pem_file(key).map_err(|e| bad(key, e.to_string()))?;
            identity = Some((chain, key));
        }
    }
    let builder = rustls::ClientConfig::builder_with_provider(Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .map_err(|e| SparkplugError::TlsConfig(e.to_string()))?
    .with_root_certificates(roots);
    match identity {
        Some((chain, key)) => builder
            .with_client_auth_cert(chain, key)
            .map_err(|e| SparkplugError::TlsConfig(e.to_string())),
        None => Ok(builder.with_no_client_auth()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_primary_host_is_online_as_sparkplug_3_or_2_says() {
        assert!(host_online(br#"{"online": true, "timestamp": 1}"#));
        assert!(!host_online(br#"{"online": false, "timestamp": 2}"#));
        assert!(host_online(b"ONLINE"));
        assert!(!host_online(b"OFFLINE"));
        assert!(!host_online(b"garbage"));
    }
}
