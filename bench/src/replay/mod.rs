//! The replay source: an OPC UA server over TCP (binary, security None or
//! Basic256Sha256 + Sign) that serves the load server's tags
//! (`load.rs`: noise `ns=1;i=1..=N`, limit switches `LS_k`) and answers
//! each Publish with notification messages built once and re-sent with
//! only their sequence numbers, timestamps and values patched in place, so
//! that what it costs to send a change is a copy of a few bytes.
//!
//! Everything around the hot path speaks through async-opcua's own
//! crates: the secure channel (asymmetric opening, key derivation,
//! signatures), the chunker and the typed requests and responses. The
//! source runs on one thread of its own, whose CPU time it reads itself.
//!
//! # Layout
//! - `control.rs`: the run ordered, and what the source did.
//! - `wire.rs`: a connection: Hello, chunks in and out, typed answers.
//! - `session.rs`: identity, endpoints, channel, session and reads.
//! - `subscription.rs`: items, the run's changes, messages, publishes.
//! - `stream.rs`: the templates and the patching (the changes' bytes).
//! - `frame.rs`: a publish's bytes and chunks (the hot path).
//! - `bench.rs`: the agent measured against it and against the load
//!   server, in one run.

pub mod bench;
mod control;
mod frame;
mod session;
mod stream;
mod subscription;
mod wire;

#[cfg(test)]
mod tests;

use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context as _};
use opcua::core::RequestMessage;
use opcua::crypto::CertificateStore;
use opcua::sync::RwLock;
use opcua::types::{
    CloseSessionResponse, DeleteMonitoredItemsResponse, DeleteSubscriptionsResponse,
    ModifySubscriptionResponse, ResponseHeader, SetPublishingModeResponse, StatusCode,
    TransferResult, TransferSubscriptionsResponse,
};
use tokio::net::TcpStream;

use crate::load::Fault;
pub use control::{Control, Order};
use session::{fault, Served, Server};
use subscription::Subscription;
use wire::{Request, Wire};

/// The URI in the replay source's certificate.
pub const URI: &str = "urn:cellwatch:bench:replay";

/// What every connection shares.
struct Shared {
    server: Server,
    store: Arc<RwLock<CertificateStore>>,
    control: Arc<Control>,
    /// Secure channel ids handed out.
    channels: AtomicU32,
    /// Subscription ids handed out.
    subscriptions: AtomicU32,
}

/// A running replay source.
pub struct ReplaySource {
    addr: SocketAddr,
    control: Arc<Control>,
    /// Ends the source's thread (its runtime and every connection).
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    /// The source's one thread (its runtime: listener, connections,
    /// publishing), joined once stopped.
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for ReplaySource {
    fn drop(&mut self) {
        self.stop();
    }
}

impl ReplaySource {
    /// Serves `tags` noise tags and the limit switches on `listen`, with
    /// its key pair in `pki` (made there if missing), on a thread of its
    /// own.
    ///
    /// # Errors
    /// The key pair cannot be made or read, or `listen` cannot be bound.
    pub fn start(listen: SocketAddr, pki: &Path, tags: usize) -> anyhow::Result<ReplaySource> {
        cellwatch::sources::pki::own_key_pair(pki, "cellwatch replay source", URI)
            .map_err(|e| anyhow!("{e}"))?;
        let store = CertificateStore::new(pki);
        let cert = store.read_own_cert().map_err(|e| anyhow!(e))?;
        let key = store.read_own_pkey().map_err(|e| anyhow!(e))?;
        let listener = std::net::TcpListener::bind(listen)
            .with_context(|| format!("cannot listen on {listen}"))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let control = Arc::new(Control::default());
        let shared = Arc::new(Shared {
            server: Server {
                cert,
                key,
                uri: URI.into(),
                tags,
            },
            store: Arc::new(RwLock::new(store)),
            control: control.clone(),
            channels: AtomicU32::new(0),
            subscriptions: AtomicU32::new(0),
        });
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        let thread = std::thread::Builder::new()
            .name("replay-source".into())
            .spawn(move || {
                runtime.block_on(async move {
                    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                        return;
                    };
                    let accept = async {
                        while let Ok((stream, _)) = listener.accept().await {
                            let shared = shared.clone();
                            tokio::spawn(async move {
                                if let Err(e) = connection(stream, &shared).await {
                                    eprintln!("replay source: a connection ended: {e:#}");
                                }
                            });
                        }
                    };
                    tokio::select! {
                        _ = accept => {}
                        _ = stopped => {}
                    }
                });
                runtime.shutdown_background();
            })?;
        Ok(ReplaySource {
            addr,
            control,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The endpoint URL.
    pub fn endpoint(&self) -> String {
        format!("opc.tcp://{}/", self.addr)
    }

    /// What it shares with the bench.
    pub fn control(&self) -> &Arc<Control> {
        &self.control
    }

    /// Starts a run: the order holds until [`ReplaySource::end_run`].
    pub fn start_run(&self, order: Order) {
        if let Ok(mut o) = self.control.order.lock() {
            *o = Some(order);
        }
    }

    /// Ends the run: its changes made, the faults it injected.
    pub async fn end_run(&self, interval: Duration) -> (u64, Vec<Fault>) {
        if let Ok(mut e) = self.control.ended.lock() {
            *e = Some(Instant::now());
        }
        if let Ok(mut o) = self.control.order.lock() {
            *o = None;
        }
        // The changes up to now and the switch left open go out at the
        // next publishing interval.
        tokio::time::sleep(interval * 3).await;
        let faults = self
            .control
            .faults
            .lock()
            .map(|f| f.clone())
            .unwrap_or_default();
        (self.control.produced.load(Ordering::Relaxed), faults)
    }

    /// Stops it: its thread and every connection end.
    pub fn stop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// One client, from its Hello to its last byte.
async fn connection(stream: TcpStream, shared: &Shared) -> anyhow::Result<()> {
    let (mut wire, mut incoming) = Wire::accept(stream, shared.store.clone()).await?;
    let mut sub: Option<Subscription> = None;
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    loop {
        tokio::select! {
            raw = incoming.recv() => {
                let Some(raw) = raw else { return Ok(()) };
                if raw.starts_with(b"CLO") {
                    return Ok(());
                }
                let Some(request) = wire.receive(raw)? else { continue };
                let interval = sub.as_ref().map(|s| s.interval);
                if !answer(&mut wire, &mut sub, shared, request).await? {
                    return Ok(());
                }
                if let Some(s) = sub.as_mut() {
                    if Some(s.interval) != interval {
                        tick = tokio::time::interval_at(
                            tokio::time::Instant::now() + s.interval,
                            s.interval,
                        );
                        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
                    }
                    s.flush(&mut wire).await?;
                }
            }
            _ = tick.tick() => {
                if let Some(s) = sub.as_mut() {
                    s.tick(Instant::now(), &shared.control);
                    s.flush(&mut wire).await?;
                }
                shared.control.note_cpu();
            }
        }
    }
}

/// Answers one request; `false` when the channel closes.
async fn answer(
    wire: &mut Wire,
    sub: &mut Option<Subscription>,
    shared: &Shared,
    request: Request,
) -> anyhow::Result<bool> {
    if let Ok(mut asked) = shared.control.asked.lock() {
        *asked.entry(request.message.type_name()).or_default() += 1;
    }
    let id = request.id;
    let server = &shared.server;
    let good = |n: Option<usize>| Some(vec![StatusCode::Good; n.unwrap_or(0)]);
    let response = match request.message {
        RequestMessage::OpenSecureChannel(r) => {
            let channel = match r.request_type {
                opcua::types::SecurityTokenRequestType::Issue => {
                    shared.channels.fetch_add(1, Ordering::Relaxed) + 1
                }
                _ => wire.channel.secure_channel_id(),
            };
            let token = wire.channel.token_id() + 1;
            match server.open(&mut wire.channel, &request.security, &r, channel, token) {
                Ok(response) => response,
                Err(status) => fault(r.request_header.request_handle, status),
            }
        }
        RequestMessage::CloseSecureChannel(_) => return Ok(false),
        RequestMessage::GetEndpoints(r) => server.get_endpoints(&r.request_header, &r.endpoint_url),
        RequestMessage::CreateSession(r) => {
            let n = shared.subscriptions.load(Ordering::Relaxed);
            server.create_session(&wire.channel, &r, n)
        }
        RequestMessage::ActivateSession(r) => server.activate_session(&r),
        RequestMessage::CloseSession(r) => {
            *sub = None;
            CloseSessionResponse {
                response_header: ResponseHeader::new_good(&r.request_header),
            }
            .into()
        }
        RequestMessage::Read(r) => server.read(&r, |s| match &*sub {
            Some(sub) => sub.value(s),
            None => matches!(s, Served::Switch(_)),
        }),
        RequestMessage::CreateSubscription(r) => {
            let n = shared.subscriptions.fetch_add(1, Ordering::Relaxed) + 1;
            let (s, response) = Subscription::create(n, server.tags, &r);
            *sub = Some(s);
            response
        }
        RequestMessage::CreateMonitoredItems(r) => match sub {
            Some(s) if s.id == r.subscription_id => s.create_items(server, &r),
            _ => fault(
                r.request_header.request_handle,
                StatusCode::BadSubscriptionIdInvalid,
            ),
        },
        RequestMessage::Publish(r) => match sub {
            Some(s) => {
                s.publish(id, &r);
                return Ok(true);
            }
            None => fault(
                r.request_header.request_handle,
                StatusCode::BadNoSubscription,
            ),
        },
        RequestMessage::Republish(r) => match sub {
            Some(s) => s.republish(&r),
            None => fault(
                r.request_header.request_handle,
                StatusCode::BadSubscriptionIdInvalid,
            ),
        },
        RequestMessage::DeleteSubscriptions(r) => {
            *sub = None;
            DeleteSubscriptionsResponse {
                response_header: ResponseHeader::new_good(&r.request_header),
                results: good(r.subscription_ids.as_ref().map(Vec::len)),
                diagnostic_infos: None,
            }
            .into()
        }
        RequestMessage::TransferSubscriptions(r) => TransferSubscriptionsResponse {
            response_header: ResponseHeader::new_good(&r.request_header),
            results: r.subscription_ids.as_ref().map(|ids| {
                ids.iter()
                    .map(|_| TransferResult {
                        status_code: StatusCode::BadSubscriptionIdInvalid,
                        available_sequence_numbers: None,
                    })
                    .collect()
            }),
            diagnostic_infos: None,
        }
        .into(),
        RequestMessage::SetPublishingMode(r) => SetPublishingModeResponse {
            response_header: ResponseHeader::new_good(&r.request_header),
            results: good(r.subscription_ids.as_ref().map(Vec::len)),
            diagnostic_infos: None,
        }
        .into(),
        RequestMessage::ModifySubscription(r) => ModifySubscriptionResponse {
            response_header: ResponseHeader::new_good(&r.request_header),
            revised_publishing_interval: r.requested_publishing_interval,
            revised_lifetime_count: r.requested_lifetime_count,
            revised_max_keep_alive_count: r.requested_max_keep_alive_count,
        }
        .into(),
        RequestMessage::DeleteMonitoredItems(r) => DeleteMonitoredItemsResponse {
            response_header: ResponseHeader::new_good(&r.request_header),
            results: good(r.monitored_item_ids.as_ref().map(Vec::len)),
            diagnostic_infos: None,
        }
        .into(),
        other => fault(
            other.request_header().request_handle,
            StatusCode::BadServiceUnsupported,
        ),
    };
    wire.send(id, response).await?;
    Ok(true)
}
