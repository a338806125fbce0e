//! The OPC UA source: one session, one subscription, one monitored item per
//! tag.
//!
//! - Security by default: the configured policy and mode, the agent's own
//!   key pair in the PKI directory (created on first start), and a server
//!   certificate accepted only if it is in `trusted/` (an unknown one lands
//!   in `rejected/`, where an engineer can review and move it).
//! - Monitored items are created in chunks no larger than the server's
//!   `MaxMonitoredItemsPerCall`.
//! - Every data change becomes a [`SourceEvent::Reading`]; a bad or
//!   uncertain status, or a value that is not a boolean, is
//!   [`Reading::Bad`].
//! - Connection lost: one [`SourceEvent::Disconnected`]; async-opcua
//!   reconnects with exponential backoff; on a new session the source
//!   recreates its subscription, then [`SourceEvent::Connected`]. Values delivered again after the
//!   re-creation are filtered by the engine (same value, same timestamp).

use std::collections::HashMap;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use cellwatch_models::engine::Reading;
use futures_util::StreamExt;
use opcua::client::{
    ClientBuilder, IdentityToken, MonitoredItem, MonitoredItemMap, OnSubscriptionNotification,
    OnSubscriptionNotificationCore, Session, SessionConnectMode, SessionPollResult,
};
use opcua::crypto::SecurityPolicy as UaPolicy;
use opcua::types::{
    DataChangeFilter, DataChangeTrigger, DataValue, ExtensionObject, MessageSecurityMode,
    MonitoredItemCreateRequest, MonitoringMode, MonitoringParameters, NodeId, NotificationMessage,
    ReadValueId, TimestampsToReturn, UserTokenPolicy, Variant,
};
use tokio::sync::mpsc;

use super::SourceEvent;
use crate::config::{
    Identity, OpcUaConfig, PasswordSource, SecurityMode, SecurityPolicy, TagConfig,
};

/// `Server_ServerCapabilities_OperationLimits_MaxMonitoredItemsPerCall`.
const MAX_MONITORED_ITEMS_PER_CALL: u32 = 11714;
/// Used when the server states no limit.
const DEFAULT_CHUNK: usize = 1000;

/// Why the source cannot start.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The client could not be configured (bad PKI directory, ...).
    #[error("OPC UA client: {0}")]
    Client(String),
    /// The password could not be read.
    #[error("OPC UA identity: {0}")]
    Identity(String),
}

fn ua_policy(p: SecurityPolicy) -> UaPolicy {
    match p {
        SecurityPolicy::None => UaPolicy::None,
        SecurityPolicy::Basic256Sha256 => UaPolicy::Basic256Sha256,
        SecurityPolicy::Aes128Sha256RsaOaep => UaPolicy::Aes128Sha256RsaOaep,
        SecurityPolicy::Aes256Sha256RsaPss => UaPolicy::Aes256Sha256RsaPss,
    }
}

fn ua_mode(m: SecurityMode) -> MessageSecurityMode {
    match m {
        SecurityMode::None => MessageSecurityMode::None,
        SecurityMode::Sign => MessageSecurityMode::Sign,
        SecurityMode::SignAndEncrypt => MessageSecurityMode::SignAndEncrypt,
    }
}

fn identity(config: &OpcUaConfig) -> Result<(IdentityToken, UserTokenPolicy), SourceError> {
    match &config.identity {
        Identity::Anonymous => Ok((IdentityToken::Anonymous, UserTokenPolicy::anonymous())),
        Identity::User { user, password } => {
            let secret = match password {
                PasswordSource::Env(var) => std::env::var(var).map_err(|_| {
                    SourceError::Identity(format!("environment variable {var} is not set"))
                })?,
                PasswordSource::File(path) => std::fs::read_to_string(path)
                    .map_err(|e| {
                        SourceError::Identity(format!("cannot read {}: {e}", path.display()))
                    })?
                    .lines()
                    .next()
                    .unwrap_or_default()
                    .to_string(),
            };
            Ok((
                IdentityToken::new_user_name(user.clone(), secret),
                UserTokenPolicy::default(),
            ))
        }
    }
}

/// Builds the client, creating the agent's key pair in the PKI directory if
/// it has none.
///
/// # Errors
/// The client configuration is invalid.
pub fn client(cell: &str, config: &OpcUaConfig) -> Result<opcua::client::Client, SourceError> {
    ClientBuilder::new()
        .application_name(format!("cellwatch {cell}"))
        .application_uri(format!("urn:cellwatch:agent:{cell}"))
        .product_uri("urn:cellwatch")
        .pki_dir(&config.pki_dir)
        .create_sample_keypair(true)
        .trust_server_certs(false)
        .verify_server_certs(true)
        .session_retry_limit(-1)
        .session_retry_initial(Duration::from_millis(500))
        .session_retry_max(Duration::from_secs(10))
        .keep_alive_interval(Duration::from_secs(1))
        .max_failed_keep_alive_count(3)
        .request_timeout(Duration::from_secs(5))
        .session_timeout(30_000)
        // The source recreates its subscription itself after a new session
        // (see `run`); async-opcua 0.19's own re-creation leaves the new
        // subscription without publish requests.
        .recreate_subscriptions(false)
        .client()
        .map_err(|e| SourceError::Client(e.join("; ")))
}

/// Runs the source until `shutdown` completes: connects (retrying with
/// backoff while the server is unreachable), subscribes to `tags`, and
/// sends every event on `tx`.
///
/// # Errors
/// The client cannot be configured or the password read; connection
/// trouble is never an error, it is reported as [`SourceEvent::Disconnected`].
pub async fn run(
    cell: &str,
    config: &OpcUaConfig,
    tags: &[TagConfig],
    tx: mpsc::UnboundedSender<SourceEvent>,
    shutdown: impl Future<Output = ()>,
) -> Result<(), SourceError> {
    let mut client = client(cell, config)?;
    let (token, token_policy) = identity(config)?;
    let policy = ua_policy(config.policy);
    let endpoint: opcua::types::EndpointDescription = (
        config.endpoint.as_str(),
        policy.to_uri(),
        ua_mode(config.mode),
        token_policy,
    )
        .into();
    let by_node: Arc<HashMap<NodeId, usize>> = Arc::new(
        tags.iter()
            .enumerate()
            .filter_map(|(i, t)| t.node_id.parse::<NodeId>().ok().map(|n| (n, i)))
            .collect(),
    );
    tokio::pin!(shutdown);
    let mut backoff = Duration::from_millis(250);
    let mut said_down = false;
    loop {
        let attempt = client.connect_to_matching_endpoint(endpoint.clone(), token.clone());
        let (session, event_loop) = tokio::select! {
            _ = &mut shutdown => return Ok(()),
            r = attempt => match r {
                Ok(pair) => pair,
                Err(e) => {
                    if !said_down {
                        let _ = tx.send(SourceEvent::Disconnected(format!("cannot connect to {}: {e}", config.endpoint)));
                        said_down = true;
                    }
                    tracing::warn!(endpoint = %config.endpoint, error = %e, retry_in = ?backoff, "OPC UA connect failed");
                    tokio::select! {
                        _ = &mut shutdown => return Ok(()),
                        _ = tokio::time::sleep(backoff) => {}
                    }
                    backoff = (backoff * 2).min(Duration::from_secs(10));
                    continue;
                }
            }
        };
        backoff = Duration::from_millis(250);
        let mut events = Box::pin(event_loop.enter());
        let mut subscribed = false;
        // Drive the event loop until the session is usable, then subscribe.
        loop {
            tokio::select! {
                _ = &mut shutdown => {
                    // Closing the session needs the event loop polled too.
                    let disconnect = session.disconnect();
                    tokio::pin!(disconnect);
                    let limit = tokio::time::sleep(Duration::from_secs(2));
                    tokio::pin!(limit);
                    loop {
                        tokio::select! {
                            _ = &mut disconnect => break,
                            _ = &mut limit => break,
                            item = events.next() => if item.is_none() { break },
                        }
                    }
                    return Ok(());
                }
                item = events.next() => match item {
                    None => break,
                    Some(Err(status)) => {
                        let _ = tx.send(SourceEvent::Disconnected(format!("session ended: {status}")));
                        said_down = true;
                        break;
                    }
                    Some(Ok(SessionPollResult::ConnectionLost(status))) => {
                        let _ = tx.send(SourceEvent::Disconnected(format!("connection lost: {status}")));
                        said_down = true;
                    }
                    Some(Ok(SessionPollResult::ReconnectFailed(status))) => {
                        if !said_down {
                            let _ = tx.send(SourceEvent::Disconnected(format!("cannot connect to {}: {status}", config.endpoint)));
                            said_down = true;
                        }
                    }
                    Some(Ok(SessionPollResult::Reconnected(mode))) => {
                        tracing::info!(?mode, "OPC UA session connected");
                        said_down = false;
                        let fresh = !subscribed || matches!(mode, SessionConnectMode::NewSession(_));
                        if fresh {
                            // A new session has no subscription on the server:
                            // create it (and its items, in chunks) beside this
                            // loop, which must keep polling the session.
                            subscribed = true;
                            let (session, config, by_node, tx) = (session.clone(), config.clone(), by_node.clone(), tx.clone());
                            tokio::spawn(async move {
                                if subscribe(&session, &config, &by_node, &tx).await {
                                    let _ = tx.send(SourceEvent::Connected);
                                }
                            });
                        } else {
                            // The server kept the session and its subscription.
                            let _ = tx.send(SourceEvent::Connected);
                        }
                    }
                    Some(Ok(other)) => tracing::debug!(event = ?other, "OPC UA session event"),
                },
            }
        }
        // The event loop ended (retry limit or fatal status): start over.
        tokio::select! {
            _ = &mut shutdown => return Ok(()),
            _ = tokio::time::sleep(backoff) => {}
        }
    }
}

/// Creates the subscription and its monitored items in chunks.
async fn subscribe(
    session: &Arc<Session>,
    config: &OpcUaConfig,
    by_node: &Arc<HashMap<NodeId, usize>>,
    tx: &mpsc::UnboundedSender<SourceEvent>,
) -> bool {
    let callback = InTimeOrder {
        by_node: by_node.clone(),
        tx: tx.clone(),
    };
    let sub = match session
        .create_subscription(config.publishing_interval, 60, 10, 0, 0, true, callback)
        .await
    {
        Ok(id) => id,
        Err(e) => {
            tracing::error!(error = %e, "cannot create the OPC UA subscription");
            let _ = tx.send(SourceEvent::Disconnected(format!(
                "cannot create subscription: {e}"
            )));
            return false;
        }
    };
    let chunk = max_items_per_call(session).await;
    let sampling = config.sampling_interval.as_secs_f64() * 1000.0;
    let requests: Vec<MonitoredItemCreateRequest> = by_node
        .keys()
        .map(|n| {
            // Without a filter a server reports value changes only; quality
            // changes (a broken sensor wire) must be reported too.
            let filter = DataChangeFilter {
                trigger: DataChangeTrigger::StatusValue,
                deadband_type: 0,
                deadband_value: 0.0,
            };
            let params = MonitoringParameters {
                sampling_interval: sampling,
                queue_size: 10,
                discard_oldest: true,
                filter: ExtensionObject::from_message(filter),
                ..Default::default()
            };
            MonitoredItemCreateRequest::new(
                ReadValueId::from(n.clone()),
                MonitoringMode::Reporting,
                params,
            )
        })
        .collect();
    tracing::debug!(
        subscription = sub,
        items = requests.len(),
        chunk,
        "creating monitored items"
    );
    for part in requests.chunks(chunk) {
        match session
            .create_monitored_items(sub, TimestampsToReturn::Both, part.to_vec())
            .await
        {
            Ok(results) => {
                for (r, req) in results.iter().zip(part) {
                    if !r.result.status_code.is_good() {
                        tracing::error!(node = %req.item_to_monitor.node_id, status = %r.result.status_code, "monitored item refused");
                        if let Some(&tag) = by_node.get(&req.item_to_monitor.node_id) {
                            let _ = tx.send(SourceEvent::Reading {
                                tag,
                                reading: Reading::Bad,
                                source_time: crate::clock::now_ms(),
                            });
                        }
                    }
                }
            }
            Err(e) => tracing::error!(error = %e, "cannot create monitored items"),
        }
    }
    true
}

/// Passes each publish's data changes to the engine in source-time order.
///
/// A server sends the changes of one publish in no particular order; a
/// trigger processed before the change it depends on would leave a timer
/// unarmed. The library's own dispatch collects them ([`Collector`]), then
/// they are sorted by source timestamp (stable, so equal times keep the
/// server's order).
struct InTimeOrder {
    by_node: Arc<HashMap<NodeId, usize>>,
    tx: mpsc::UnboundedSender<SourceEvent>,
}

struct Collector<'a> {
    by_node: &'a HashMap<NodeId, usize>,
    readings: Vec<(usize, Reading, u64)>,
}

impl OnSubscriptionNotification for Collector<'_> {
    fn on_data_value(&mut self, value: DataValue, item: &MonitoredItem) {
        if let Some(&tag) = self.by_node.get(&item.item_to_monitor().node_id) {
            self.readings
                .push((tag, reading(&value), source_time(&value)));
        }
    }
}

impl OnSubscriptionNotificationCore for InTimeOrder {
    fn on_subscription_notification(
        &mut self,
        notification: NotificationMessage,
        items: MonitoredItemMap<'_>,
    ) {
        let mut c = Collector {
            by_node: &self.by_node,
            readings: Vec::new(),
        };
        c.on_subscription_notification(notification, items);
        c.readings.sort_by_key(|r| r.2);
        for (tag, reading, source_time) in c.readings {
            let _ = self.tx.send(SourceEvent::Reading {
                tag,
                reading,
                source_time,
            });
        }
    }
}

/// The server's limit on monitored items per call, or [`DEFAULT_CHUNK`].
async fn max_items_per_call(session: &Session) -> usize {
    let node = NodeId::new(0, MAX_MONITORED_ITEMS_PER_CALL);
    match session
        .read(&[ReadValueId::from(node)], TimestampsToReturn::Neither, 0.0)
        .await
    {
        Ok(values) => match values.first().and_then(|v| v.value.as_ref()) {
            Some(Variant::UInt32(n)) if *n > 0 => *n as usize,
            _ => DEFAULT_CHUNK,
        },
        Err(_) => DEFAULT_CHUNK,
    }
}

/// A data value as the engine reads it.
pub fn reading(value: &DataValue) -> Reading {
    let good = value.status.is_none_or(|s| s.is_good());
    match (&value.value, good) {
        (Some(Variant::Boolean(b)), true) => Reading::Good(*b),
        _ => Reading::Bad,
    }
}

fn source_time(value: &DataValue) -> u64 {
    value
        .source_timestamp
        .or(value.server_timestamp)
        .map_or_else(crate::clock::now_ms, |t| {
            t.as_chrono().timestamp_millis().max(0) as u64
        })
}
