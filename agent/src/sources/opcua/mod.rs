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
//!   order (`subscription`); each value is read as its tag is configured
//!   (a Boolean, a bit of an integer word, a number, a string); a bad or
//!   uncertain status is [`Reading::Bad`](cellwatch_models::engine::Reading::Bad),
//!   a value of another type [`Reading::WrongType`](cellwatch_models::engine::Reading::WrongType).
//! - The channel to the cell loop is bounded: when the loop falls behind,
//!   the session's event loop waits, and the server's queues hold the
//!   changes.
//! - Connection lost: one [`SourceEvent::Disconnected`], and the
//!   subscription's publishes wait; async-opcua reconnects with exponential
//!   backoff; the new session takes the subscription over
//!   (`TransferSubscriptions`), the source says [`SourceEvent::Resumed`]
//!   and asks again for every publish it missed (`Republish`, `resume`),
//!   in sequence-number order (`sequence`), then
//!   [`SourceEvent::Connected`]. What cannot be had again is a
//!   [`SourceEvent::Gap`]; a subscription the server no longer has is
//!   created again. Values delivered twice are filtered by the engine
//!   (same value, same timestamp).
//! - The charts' force and stop switches are the only writes, each a pulse
//!   (on, held, off). None is left on by the agent: on every (re)connected
//!   session every switch found on is written off first (an agent killed
//!   during a pulse, or a session lost during one), and on shutdown a pulse
//!   under way is cut short and every switch found on written off before
//!   the session is closed.

use std::collections::BTreeMap;
use std::future::Future;
use std::sync::atomic::AtomicU32;
use std::sync::Arc;
use std::time::Duration;

mod client;
mod conditions;
pub(crate) mod config;
mod context;
mod delivery;
mod error;
mod items;
mod machinery;
mod names;
pub mod node;
mod once;
mod overflow;
mod redundancy;
mod republishes;
mod requests;
mod resume;
mod reverse;
mod sequence;
mod subscription;
mod switches;
mod tend;
mod watch;

pub use crate::sources::opcua::node::{Namespace, TagNode};
pub use client::client;
use client::{identity, namespace_array, server_endpoint};
use context::{Context, Live, TagTable};
pub use error::OpcUaError;
pub use names::Names;
pub use once::{connect_once, server_identity, ServerIdentity};
use requests::Requests;
use switches::{pulse, reset_switches, Writes};

pub use conditions::EVENTS_ALARM;
pub use subscription::{reading, OVERFLOW_ALARM};
pub use watch::SILENT_KEEP_ALIVES;

use futures_util::future::BoxFuture;
use futures_util::{FutureExt, StreamExt};
use opcua::client::{Session, SessionConnectMode, SessionPollResult};

use tokio::sync::mpsc;

use crate::backoff::Backoff;

use super::{
    Source, SourceError, SourceEvent, SourceSender, Write, WriteError, WriteRequest, WriteSender,
    WRITE_CAPACITY,
};
use crate::sources::opcua::config::OpcUaConfig;
use crate::tags::TagConfig;

/// The OPC UA client of one cell.
pub struct OpcUaSource {
    cell: String,
    config: OpcUaConfig,
    tags: TagTable,
    /// The tags it may write (the charts' force and stop switches), each
    /// with its name and address.
    switches: BTreeMap<usize, String>,
    writes: Option<mpsc::Receiver<WriteRequest>>,
    /// `opcua.reverse_listen` bound when the source was made (`None`:
    /// not configured, or to be bound when it runs).
    reverse: Option<std::net::TcpListener>,
    /// Where the requests made of the server are counted.
    requests: Requests,
}

impl OpcUaSource {
    /// A source for `cell` reading `tags` from the server in `config`, and
    /// pulsing `switches` (the force and stop switches; indices into
    /// `tags`), nothing else. It keeps what it reads of the tags, not the
    /// tags.
    pub fn new(
        cell: &str,
        config: OpcUaConfig,
        tags: Vec<TagConfig>,
        switches: impl IntoIterator<Item = usize>,
    ) -> OpcUaSource {
        let switches = switches
            .into_iter()
            .filter_map(|i| Some((i, format!("{} ({})", tags.get(i)?.name, tags[i].address))))
            .collect();
        // Bound now, so that its address is known before the source runs;
        // a port still held by the source this one replaces is bound when
        // it runs.
        let reverse = config
            .reverse_listen
            .and_then(|addr| match reverse::bind(addr) {
                Ok(l) => Some(l),
                Err(e) => {
                    tracing::warn!(%addr, error = %e, "cannot listen for the OPC UA server yet");
                    None
                }
            });
        OpcUaSource {
            cell: cell.into(),
            tags: TagTable::new(&config, &tags),
            config,
            switches,
            writes: None,
            reverse,
            requests: Requests::default(),
        }
    }
}

impl Source for OpcUaSource {
    fn describe(&self) -> String {
        format!("opcua {}", self.config.endpoint)
    }

    fn delivery_allowance(&self) -> std::time::Duration {
        self.config.publishing_interval
    }

    fn listening(&self) -> Option<std::net::SocketAddr> {
        self.reverse.as_ref().and_then(|l| l.local_addr().ok())
    }

    fn count_requests(&mut self, counter: prometheus::IntCounterVec) {
        self.requests = Requests::new(Some(counter));
    }

    fn writer(&mut self) -> Option<WriteSender> {
        if self.switches.is_empty() && self.config.events.is_empty() {
            return None;
        }
        let (tx, rx) = mpsc::channel(WRITE_CAPACITY);
        self.writes = Some(rx);
        Some(tx)
    }

    fn run(
        self: Box<Self>,
        tx: SourceSender,
        shutdown: BoxFuture<'static, ()>,
    ) -> BoxFuture<'static, Result<(), SourceError>> {
        async move {
            let writes = Writes {
                rx: self.writes,
                switches: self.switches,
            };
            let reverse = match self.config.reverse_listen {
                Some(addr) => Some(reverse::listen(addr, self.reverse).await),
                None => None,
            };
            let setup = Setup {
                cell: &self.cell,
                config: &self.config,
                requests: self.requests,
            };
            run_writing(setup, self.tags, tx, writes, reverse, shutdown).await
        }
        .boxed()
    }
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
    let writes = Writes {
        rx: None,
        switches: BTreeMap::new(),
    };
    let tags = TagTable::new(config, tags);
    let reverse = match config.reverse_listen {
        Some(addr) => Some(reverse::listen(addr, None).await),
        None => None,
    };
    let setup = Setup {
        cell,
        config,
        requests: Requests::default(),
    };
    run_writing(setup, tags, tx, writes, reverse, shutdown).await
}

/// The source's own: its cell, its configuration, and where the requests
/// it makes are counted.
struct Setup<'a> {
    cell: &'a str,
    config: &'a OpcUaConfig,
    requests: Requests,
}

async fn run_writing(
    setup: Setup<'_>,
    tags: TagTable,
    tx: SourceSender,
    mut writes: Writes,
    reverse: Option<Arc<tokio::net::TcpListener>>,
    shutdown: impl Future<Output = ()>,
) -> Result<(), SourceError> {
    let Setup {
        cell,
        config,
        requests,
    } = setup;
    // Pulses under way; each writes its switch off before it ends.
    let mut pulses = tokio::task::JoinSet::new();
    // Every switch it may write, with its node: all written off on each
    // (re)connected session and on shutdown.
    let switch_nodes: Arc<Vec<(String, TagNode)>> = Arc::new(
        writes
            .switches
            .iter()
            .filter_map(|(&tag, name)| {
                Some((name.clone(), tags.nodes.get(tag).cloned().flatten()?))
            })
            .collect(),
    );
    // Taken by a pulse for its whole length and by the writing-off on a
    // (re)connected session, in the order they were started: a switch
    // written off after a reconnection never cuts a later pulse short.
    let switching = Arc::new(tokio::sync::Mutex::new(()));
    let mut client = client(cell, config)?;
    // Anonymous or user name: the server's endpoint says which token
    // policies it accepts.
    let token = identity(config)?;
    let ctx = Arc::new(Context::new(config, tags, tx.clone(), requests));
    // The subscription of the current session, kept across reactivations.
    let current = Arc::new(tokio::sync::Mutex::new(None));
    tokio::pin!(shutdown);
    // The session's supervisor (namespaces, subscription, liveness) beside
    // the session's event loop; owned here so that none outlives the source.
    let mut supervisor = tokio::task::JoinSet::new();
    let mut backoff = Backoff::new(Duration::from_millis(250), Duration::from_secs(10));
    let mut said_down = false;
    // A redundant set: the server read from, and the watch of its level
    // saying to move.
    let redundant = !config.redundant.is_empty();
    let (mut active, move_on) = (0, Arc::new(tokio::sync::Notify::new()));
    loop {
        let attempt = async {
            if redundant {
                let levels = redundancy::levels(cell, config).await;
                active = redundancy::choose(&levels, active);
                tracing::info!(
                    ?levels,
                    server = config.servers()[active],
                    "OPC UA redundant set: the server read from"
                );
                ctx.reading_from(config.servers()[active]);
            }
            let server = config.at(&ctx.endpoint());
            let endpoint = server_endpoint(&client, &server, reverse.as_ref()).await?;
            // An untrusted server certificate is said with what to do, and
            // left in rejected/ for review; it is looked at again on the
            // next attempt, so trusting it while the agent runs is enough.
            if let Some(why) = crate::sources::pki::untrusted(&server, &endpoint) {
                crate::sources::pki::reject(endpoint.server_certificate.as_ref(), &config.pki_dir);
                return Err(opcua::types::Error::new(
                    opcua::types::StatusCode::BadCertificateUntrusted,
                    why,
                ));
            }
            match &reverse {
                Some(listener) => reverse::session(&client, listener, endpoint, token.clone()),
                None => client
                    .connect_to_endpoint_directly(endpoint, token.clone())
                    .map(|(s, l)| (s, Box::pin(l.enter()) as reverse::Events)),
            }
        };
        let (session, event_loop) = tokio::select! {
            _ = &mut shutdown => return Ok(()),
            r = attempt => match r {
                Ok(pair) => pair,
                Err(e) => {
                    if !said_down {
                        let _ = tx.send(SourceEvent::Disconnected(format!("cannot connect to {}: {e}", ctx.endpoint()))).await;
                        said_down = true;
                    }
                    let wait = backoff.next_wait();
                    tracing::warn!(endpoint = %ctx.endpoint(), error = %e, retry_in = ?wait, "OPC UA connect failed");
                    tokio::select! {
                        _ = &mut shutdown => return Ok(()),
                        _ = tokio::time::sleep(wait) => {}
                    }
                    continue;
                }
            }
        };
        backoff.reset();
        let mut events = event_loop;
        let mut subscribed = false;
        // Drive the event loop until the session is usable, then subscribe.
        loop {
            tokio::select! {
                _ = &mut shutdown => {
                    // A pulse under way is cut short, and every switch is
                    // written off, with the event loop polled.
                    pulses.abort_all();
                    supervisor.abort_all();
                    let off = reset_switches(&session, &switch_nodes, "stopping", &ctx.requests);
                    tokio::pin!(off);
                    let limit = tokio::time::sleep(Duration::from_secs(5));
                    tokio::pin!(limit);
                    loop {
                        tokio::select! {
                            () = &mut off => break,
                            _ = &mut limit => {
                                tracing::error!("chart switches not written off within 5 s");
                                break;
                            }
                            item = events.next() => if item.is_none() { break },
                        }
                    }
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
                Some(w) = writes.next() => {
                    if let Write::Acknowledge { alarm, comment } = &w.what {
                        let (session, ctx, alarm, comment) = (session.clone(), ctx.clone(), alarm.clone(), comment.clone());
                        pulses.spawn(async move {
                            let done = conditions::acknowledge(&session, &ctx.conditions, &alarm, &comment, &ctx.requests).await;
                            let _ = w.reply.send(done.map_err(|e| WriteError::Failed(e.into())));
                        });
                        continue;
                    }
                    let node = w.tag.and_then(|t| ctx.nodes.get(t).cloned().flatten());
                    let checked = match (&w.what, w.tag.and_then(|t| writes.switches.get(&t)), node) {
                        (Write::Pulse(held), Some(name), Some(node)) => Ok((*held, name.clone(), node)),
                        (Write::Value(_), _, _) => Err(OpcUaError::OnlySwitches),
                        _ => Err(OpcUaError::NotASwitch),
                    };
                    match checked {
                        Err(why) => { let _ = w.reply.send(Err(WriteError::Refused(why.into()))); }
                        Ok((held, name, node)) => {
                            let session = session.clone();
                            let switching = switching.clone();
                            let requests = ctx.requests.clone();
                            pulses.spawn(async move {
                                let _turn = switching.lock_owned().await;
                                let done = pulse(session, node, name, held, requests).await;
                                match &done {
                                    Ok(d) => tracing::info!(write = %d, "switch pulsed"),
                                    Err(e) => tracing::warn!(error = %e, "switch pulse failed"),
                                }
                                let _ = w.reply.send(done.map_err(|e| WriteError::Failed(e.into())));
                            });
                        }
                    }
                }
                Some(_) = pulses.join_next(), if !pulses.is_empty() => {}
                () = move_on.notified(), if redundant => {
                    supervisor.abort_all();
                    ctx.pause();
                    *current.lock().await = None;
                    let _ = tx.send(SourceEvent::Disconnected(format!("{} degraded: moving to another server of the set", ctx.endpoint()))).await;
                    said_down = true;
                    // The session ends with its event loop, dropped here.
                    break;
                }
                item = events.next() => match item {
                    None => break,
                    Some(Err(status)) => {
                        supervisor.abort_all();
                        ctx.pause();
                        let _ = tx.send(SourceEvent::Disconnected(format!("session ended: {status}"))).await;
                        said_down = true;
                        break;
                    }
                    Some(Ok(SessionPollResult::ConnectionLost(status))) => {
                        supervisor.abort_all();
                        ctx.pause();
                        let _ = tx.send(SourceEvent::Disconnected(format!("connection lost: {status}"))).await;
                        said_down = true;
                        if redundant {
                            // Another server of the set, fresh.
                            *current.lock().await = None;
                            break;
                        }
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
                        // A new session has no subscription on the server; a
                        // reactivated one keeps it, unless the namespaces moved.
                        let new_session = !subscribed || matches!(mode, SessionConnectMode::NewSession(_));
                        subscribed = true;
                        supervisor.abort_all();
                        // Whatever a pulse cut short (this agent's or a
                        // killed one's) left on is written off first.
                        if !switch_nodes.is_empty() {
                            let (session, switches, switching, requests) = (session.clone(), switch_nodes.clone(), switching.clone(), ctx.requests.clone());
                            let turn = switching.clone().try_lock_owned();
                            supervisor.spawn(async move {
                                let _turn = match turn {
                                    Ok(turn) => turn,
                                    Err(_) => switching.lock_owned().await,
                                };
                                reset_switches(&session, &switches, "connected", &requests).await;
                            });
                        }
                        supervisor.spawn(supervise(session.clone(), ctx.clone(), current.clone(), new_session));
                        if redundant {
                            supervisor.spawn(redundancy::watch(session.clone(), cell.to_string(), config.clone(), active, move_on.clone()));
                        }
                    }
                    // The client library's own requests: the publishes it
                    // keeps queued and the keep-alive reads of the server's
                    // state, counted as the source's are.
                    Some(Ok(SessionPollResult::Subscription(activity))) => ctx.requests.publish(&activity),
                    Some(Ok(SessionPollResult::SessionActivity(activity))) => ctx.requests.keep_alive(&activity),
                    Some(Ok(other)) => tracing::debug!(event = ?other, "OPC UA session event"),
                },
            }
        }
        // The event loop ended (retry limit or fatal status): start over.
        supervisor.abort_all();
        tokio::select! {
            _ = &mut shutdown => return Ok(()),
            // A session that ended is not a failed try: the first
            // attempt after it waits as before, the next ones double.
            _ = tokio::time::sleep(backoff.peek()) => {}
        }
    }
}

/// The server's `NamespaceArray` (index → URI).
///
/// # Errors
/// The read fails or the value is not an array of strings.
pub async fn namespaces(session: &Session) -> Result<Vec<String>, OpcUaError> {
    namespace_array(session, &Requests::default()).await
}

/// Deletes subscription `id`, also out of the library's state; an error
/// (the server has it no more) changes nothing.
async fn delete(session: &Session, id: u32, requests: &Requests) {
    let deleted = session.delete_subscription(id).await;
    requests.answered("DeleteSubscriptions", &deleted);
}

/// The alarm a missing namespace raises (kind `system`).
pub const NAMESPACE_ALARM: &str = "opcua-namespace";

/// Supervises one session, beside its event loop: resolves the tags'
/// namespaces against the server's `NamespaceArray`; takes the
/// subscription over from a lost session, or subscribes when there is
/// none or the namespaces moved; says [`SourceEvent::Connected`]; then
/// fills every gap in the publishes (`Republish`) and watches that the
/// subscription keeps publishing (data or keep-alives). A silent one is
/// asked for what it holds, then reported as [`SourceEvent::Disconnected`],
/// deleted and created again.
async fn supervise(
    session: Arc<Session>,
    ctx: Arc<Context>,
    current: Arc<tokio::sync::Mutex<Option<Live>>>,
    new_session: bool,
) {
    let mut live = current.lock_owned().await;
    let mut retry = Backoff::new(Duration::from_millis(500), Duration::from_secs(10));
    // The subscription of the lost connection is to be taken over.
    let mut resuming = live.is_some();
    loop {
        let namespaces = match namespace_array(&session, &ctx.requests).await {
            Ok(n) => {
                ctx.uses.namespaces_are(&n);
                n
            }
            Err(e) => {
                let _ = ctx
                    .tx
                    .send(SourceEvent::Disconnected(format!(
                        "cannot read the namespace array of {}: {e}",
                        ctx.endpoint()
                    )))
                    .await;
                tokio::time::sleep(retry.next_wait()).await;
                continue;
            }
        };
        let resumed = match live
            .as_ref()
            .filter(|l| resuming && l.namespaces == namespaces)
        {
            Some(l) => Some(resume(&session, l, new_session, &ctx.requests).await),
            None => None,
        };
        match (resumed, live.as_ref()) {
            (Some(Err(why)), Some(l)) => {
                let sub = &l.subscription;
                tracing::warn!(subscription = sub.id, %why, "subscribing again");
                resume::give_up(
                    &l.shared,
                    format!("subscription {} could not be taken over ({why}): changes while the connection was down may be lost", sub.id),
                );
                let _ = ctx
                    .tx
                    .send(SourceEvent::Disconnected(format!(
                        "the server dropped subscription {} while the connection was down",
                        sub.id
                    )))
                    .await;
                // Also out of the library's state (the server has it no
                // more, or never will again).
                delete(&session, sub.id, &ctx.requests).await;
                *live = None;
            }
            (Some(Ok(())), Some(l)) => {
                // Silence is counted from here: the connection was down,
                // not the subscription.
                l.heard.beat();
                if !new_session {
                    // Values the server never sent, because they did not
                    // change, were forgotten while the connection was down:
                    // read them after what it held (the engine ignores what
                    // it has).
                    subscription::read_current(
                        &session,
                        &l.nodes,
                        &ctx.uses,
                        &ctx.tx,
                        &ctx.requests,
                    )
                    .await;
                }
            }
            _ => {}
        }
        resuming = false;
        if live.as_ref().is_none_or(|l| l.namespaces != namespaces) {
            if let Some(old) = live.take() {
                tracing::info!(
                    subscription = old.subscription.id,
                    "the server's namespaces changed: subscribing again"
                );
                resume::give_up(
                    &old.shared,
                    format!(
                        "the server's namespaces changed: subscription {} replaced",
                        old.subscription.id
                    ),
                );
                delete(&session, old.subscription.id, &ctx.requests).await;
            }
            match subscribe(&session, &ctx, namespaces).await {
                Some(l) => *live = Some(l),
                None => {
                    tokio::time::sleep(retry.next_wait()).await;
                    continue;
                }
            }
        }
        retry.reset();
        let _ = ctx.tx.send(SourceEvent::Connected(ctx.endpoint())).await;
        let l = live.as_ref().expect("subscribed above");
        let why = watch::watch(&session, &ctx, l).await;
        let l = live.take().expect("subscribed above");
        tracing::warn!(subscription = l.subscription.id, "{why}");
        resume::give_up(
            &l.shared,
            format!(
                "subscription {} replaced ({why}): changes meanwhile may be lost",
                l.subscription.id
            ),
        );
        let _ = ctx.tx.send(SourceEvent::Disconnected(why)).await;
        delete(&session, l.subscription.id, &ctx.requests).await;
    }
}

/// The subscription of a lost connection in this session: taken over
/// into a new session, or still there in a reactivated one, with every
/// publish the server holds sent again.
///
/// # Errors
/// Why it cannot be: the server no longer has it, or refuses.
async fn resume(
    session: &Session,
    l: &Live,
    new_session: bool,
    requests: &requests::Requests,
) -> Result<(), OpcUaError> {
    let sub = &l.subscription;
    if new_session {
        return resume::transfer(session, sub.id, &l.shared, requests).await;
    }
    match resume::catch_up(session, sub.id, &l.shared, requests).await {
        Ok(()) | Err(resume::Unfilled::Failed(_)) => Ok(()),
        Err(resume::Unfilled::Gone(status)) => Err(OpcUaError::Status(status)),
    }
}

/// Resolves every tag against `namespaces` and subscribes to those found.
/// Tags whose namespace the server does not have are reported bad, and
/// the [`NAMESPACE_ALARM`] problem names the URIs (or is cleared).
async fn subscribe(session: &Arc<Session>, ctx: &Context, namespaces: Vec<String>) -> Option<Live> {
    let mut found = Vec::new();
    let mut unread = Vec::new();
    let mut missing: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
    for (tag, node) in ctx.nodes.iter().enumerate() {
        let Some(node) = node else {
            unread.push(tag);
            continue;
        };
        match (node.resolve(&namespaces), &node.namespace) {
            (Some(id), _) => found.push((id, tag)),
            (None, Namespace::Uri(uri)) => missing.entry(uri).or_default().push(tag),
            (None, Namespace::Index(_)) => unread.push(tag),
        }
    }
    let problem = (!missing.is_empty()).then(|| {
        let each: Vec<String> = missing
            .iter()
            .map(|(uri, tags)| {
                let mut names: Vec<&str> = tags.iter().take(5).map(|&t| &ctx.names[t]).collect();
                if tags.len() > names.len() {
                    names.push("...");
                }
                format!(
                    "namespace '{uri}' is not on the server ({} tag{} unknown: {})",
                    tags.len(),
                    if tags.len() == 1 { "" } else { "s" },
                    names.join(", ")
                )
            })
            .collect();
        each.join("; ")
    });
    if let Some(p) = &problem {
        tracing::error!(endpoint = %ctx.endpoint(), problem = %p, "OPC UA namespaces missing");
    }
    let _ = ctx
        .tx
        .send(SourceEvent::Problem {
            id: NAMESPACE_ALARM.into(),
            problem,
        })
        .await;
    unread.extend(missing.into_values().flatten());
    if !unread.is_empty() {
        let _ = ctx.tx.send(subscription::bad(&unread)).await;
    }
    // Silence is counted from the subscription's start.
    let heard = Arc::new(subscription::Heard::new());
    heard.beat();
    let nodes = Arc::new(subscription::Monitored::group(
        found,
        &ctx.uses,
        ctx.nodes.clone(),
        namespaces.clone(),
    ));
    // What the server granted, which may be less than asked.
    let queue_size = Arc::new(AtomicU32::new(ctx.config.queue_size));
    let told = delivery::Told {
        tx: ctx.tx.clone(),
        names: ctx.names.clone(),
        conditions: ctx.conditions.clone(),
    };
    let shared = delivery::delivery(
        nodes.clone(),
        ctx.uses.clone(),
        told,
        heard.clone(),
        queue_size.clone(),
        &ctx.config,
    );
    let subscription = subscription::subscribe(
        session,
        &ctx.config,
        &nodes,
        &ctx.uses,
        &ctx.tx,
        subscription::Granted {
            queue_size: &queue_size,
            items: &shared.items,
            requests: &ctx.requests,
        },
        delivery::Feed(shared.clone()),
    )
    .await?;
    {
        let mut d = shared.lock();
        d.id = subscription.id;
        d.granted(subscription.interval);
    }
    conditions::follow(
        session,
        subscription.id,
        &ctx.conditions,
        &namespaces,
        &ctx.tx,
        &ctx.requests,
    )
    .await;
    *ctx.delivery.lock().unwrap_or_else(|e| e.into_inner()) = Some(shared.clone());
    Some(Live {
        subscription,
        shared,
        nodes,
        namespaces,
        heard,
    })
}
