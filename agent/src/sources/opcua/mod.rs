//! The OPC UA source: one session, one subscription, one monitored item per
//! tag.
//!
//! - Security by default: the configured policy and mode, the agent's own
//!   key pair in the PKI directory (created on first start), and a server
//!   certificate accepted only if it is in `trusted/` (an unknown one lands
//!   in `rejected/`, where an engineer can review and move it).
//! - Monitored items are created in chunks no larger than the server's
//!   `MaxMonitoredItemsPerCall`.
//! - Every publish becomes one [`SourceEvent::Readings`], in source-time
//!   order (`subscription`); a bad or uncertain status, or a value that
//!   is not a boolean, is [`Reading::Bad`](cellwatch_models::engine::Reading::Bad).
//! - The channel to the cell loop is bounded: when the loop falls behind,
//!   the session's event loop waits, and the server's queues hold the
//!   changes.
//! - Connection lost: one [`SourceEvent::Disconnected`]; async-opcua
//!   reconnects with exponential backoff; on a new session the source
//!   recreates its subscription, then [`SourceEvent::Connected`]. Values delivered again after the
//!   re-creation are filtered by the engine (same value, same timestamp).

use std::collections::HashMap;
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

mod subscription;

pub use subscription::reading;

use futures_util::future::BoxFuture;
use futures_util::{FutureExt, StreamExt};
use opcua::client::{ClientBuilder, IdentityToken, SessionConnectMode, SessionPollResult};
use opcua::crypto::SecurityPolicy as UaPolicy;
use opcua::types::{MessageSecurityMode, NodeId, UserTokenPolicy};

use super::{Source, SourceError, SourceEvent, SourceSender};
use crate::config::{
    Identity, OpcUaConfig, PasswordSource, SecurityMode, SecurityPolicy, TagConfig,
};

/// The OPC UA client of one cell.
pub struct OpcUaSource {
    cell: String,
    config: OpcUaConfig,
    tags: Vec<TagConfig>,
}

impl OpcUaSource {
    /// A source for `cell` reading `tags` from the server in `config`.
    pub fn new(cell: &str, config: OpcUaConfig, tags: Vec<TagConfig>) -> OpcUaSource {
        OpcUaSource {
            cell: cell.into(),
            config,
            tags,
        }
    }
}

impl Source for OpcUaSource {
    fn describe(&self) -> String {
        format!("opcua {}", self.config.endpoint)
    }

    fn run(
        self: Box<Self>,
        tx: SourceSender,
        shutdown: BoxFuture<'static, ()>,
    ) -> BoxFuture<'static, Result<(), SourceError>> {
        async move { run(&self.cell, &self.config, &self.tags, tx, shutdown).await }.boxed()
    }
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
    tx: SourceSender,
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
    // Subscriptions being created beside the session's event loop; owned
    // here so that none outlives the source.
    let mut subscribing = tokio::task::JoinSet::new();
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
                        let _ = tx.send(SourceEvent::Disconnected(format!("cannot connect to {}: {e}", config.endpoint))).await;
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
                        let _ = tx.send(SourceEvent::Disconnected(format!("session ended: {status}"))).await;
                        said_down = true;
                        break;
                    }
                    Some(Ok(SessionPollResult::ConnectionLost(status))) => {
                        let _ = tx.send(SourceEvent::Disconnected(format!("connection lost: {status}"))).await;
                        said_down = true;
                    }
                    Some(Ok(SessionPollResult::ReconnectFailed(status))) => {
                        if !said_down {
                            let _ = tx.send(SourceEvent::Disconnected(format!("cannot connect to {}: {status}", config.endpoint))).await;
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
                            subscribing.spawn(async move {
                                if subscription::subscribe(&session, &config, &by_node, &tx).await {
                                    let _ = tx.send(SourceEvent::Connected(config.endpoint.clone())).await;
                                }
                            });
                        } else {
                            // The server kept the session and its subscription.
                            let _ = tx.send(SourceEvent::Connected(config.endpoint.clone())).await;
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
