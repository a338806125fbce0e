//! The cell's alarms to people, through Prometheus Alertmanager (API v2:
//! `POST /api/v2/alerts`), the notification engine plants already run
//! (e-mail, chat, paging; silences, inhibition, grouping).
//!
//! Each agent pushes its own alarms: it knows their state first-hand, no
//! plant-side process stands between an alarm and a person, and
//! Alertmanager is made to be pushed to by many senders (every Prometheus
//! does). Every active alarm that is not shelved, in service, no
//! suppressed consequence and not suppressed by design (a machine mode,
//! `[[state.modes]]`) is an alert (a consequence announced carries
//! its cause and first-out as labels, for Alertmanager's inhibition); it is sent when it is raised or changes, again every
//! `resend_interval`, each time saying it ends four intervals later unless
//! sent again (as Prometheus does: an agent that dies stops renewing its
//! alerts rather than leaving them firing for ever; its `up` and health
//! alerts say why). A clear, a shelf or a removal from service sends the
//! alert once more with `endsAt`, the time it happened, until every
//! Alertmanager has taken it.
//!
//! The sink only writes into the [`AlertBook`] (a lock held for a map update)
//! and wakes the [`Pusher`], a task of its own: a slow or dead
//! Alertmanager never holds up the cell loop. Failed sends are retried
//! with backoff (1 s doubling to the resend interval), per Alertmanager,
//! counted in `cellwatch_alertmanager_sends_total{result="failed"}` and
//! logged, together, by the sink's events (`events.rs`).
//! Memory is bounded by the alarms the cell can raise: one entry per
//! alarm, active or ended.

mod book;
pub(crate) mod config;
mod events;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use tokio::sync::Notify;

use self::config::{AlertmanagerConfig, AlertmanagerTls};
use super::Sink;
use crate::backoff::Backoff;
use crate::clock::rfc3339;
use crate::metrics::Metrics;
use crate::step::CellStep;
use events::AlertmanagerEvent;

pub(crate) use book::{Alert, AlertBook, Labels};

/// How long one send may take.
const SEND_TIMEOUT: Duration = Duration::from_secs(10);

/// The most of an error answer's body read (its first 300 bytes are
/// logged): an Alertmanager, or whatever answers in its place, cannot make
/// the agent hold more.
const MAX_ERROR_BODY: usize = 64 * 1024;

/// The first retry after a failed send; doubled up to the resend interval.
const FIRST_RETRY: Duration = Duration::from_secs(1);

/// The state the sink and the pusher share.
struct Shared {
    book: Mutex<AlertBook>,
    /// Counts changes, so the pusher knows whether one came while a batch
    /// was on its way.
    generation: std::sync::atomic::AtomicU64,
    wake: Notify,
    /// The sink is gone (the cell loop ended): the pusher sends what is
    /// owed once more and ends.
    closed: std::sync::atomic::AtomicBool,
}

impl Shared {
    fn book(&self) -> std::sync::MutexGuard<'_, AlertBook> {
        self.book
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// Hands the cell's alarms to the [`Pusher`].
pub(crate) struct AlertmanagerSink {
    labels: Labels,
    shared: Arc<Shared>,
    metrics: Arc<Metrics>,
}

impl Sink for AlertmanagerSink {
    fn name(&self) -> &'static str {
        "alertmanager"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        if !step.alarms.is_empty() {
            let mut book = self.shared.book();
            let mut changed = false;
            for a in &step.alarms {
                changed |= book.take(&self.labels, &a.payload, step.at);
            }
            if changed {
                AlertmanagerEvent::Booked {
                    active: book.active(),
                    unsent: book.unsent(),
                }
                .emit(&self.metrics);
                drop(book);
                self.shared
                    .generation
                    .fetch_add(1, std::sync::atomic::Ordering::AcqRel);
                self.shared.wake.notify_one();
            }
        }
        async {}.boxed()
    }
}

impl Drop for AlertmanagerSink {
    fn drop(&mut self) {
        self.shared
            .closed
            .store(true, std::sync::atomic::Ordering::Release);
        self.shared.wake.notify_one();
    }
}

/// Sends the book to every Alertmanager: on a change, every resend
/// interval, and again after a failure, with backoff.
pub(crate) struct Pusher {
    urls: Vec<String>,
    resend: Duration,
    client: Client,
    shared: Arc<Shared>,
    metrics: Arc<Metrics>,
}

type Client = hyper_util::client::legacy::Client<
    hyper_rustls::HttpsConnector<hyper_util::client::legacy::connect::HttpConnector>,
    http_body_util::Full<bytes::Bytes>,
>;

/// Why the pusher cannot be made.
#[derive(Debug, thiserror::Error)]
#[error("alertmanager.tls: {0}")]
pub struct TlsError(#[from] crate::bus::client_tls::ClientTlsError);

/// Why a batch of alerts did not reach an Alertmanager (it is sent
/// again).
#[derive(Debug, thiserror::Error)]
pub(crate) enum SendError {
    /// The alerts could not be encoded.
    #[error(transparent)]
    Encode(#[from] serde_json::Error),
    /// The request could not be made (the URL).
    #[error(transparent)]
    Request(#[from] hyper::http::Error),
    /// No answer in time.
    #[error("no answer within {} s", .0.as_secs())]
    Timeout(std::time::Duration),
    /// The connection failed (said with its causes, in one line).
    #[error("{}", error_chain(.0))]
    Connect(#[source] hyper_util::client::legacy::Error),
    /// The Alertmanager answered with an error: its status and what it
    /// said (at most 300 bytes).
    #[error("{status}: {said}")]
    Refused {
        /// The HTTP status.
        status: hyper::StatusCode,
        /// What its body said.
        said: String,
    },
}

/// The sink for the cell loop and the pusher to run beside it.
///
/// # Errors
/// A TLS file cannot be read or used.
pub(crate) fn start(
    cell: &str,
    config: &AlertmanagerConfig,
    metrics: Arc<Metrics>,
) -> Result<(AlertmanagerSink, Pusher), TlsError> {
    let shared = Arc::new(Shared {
        book: Mutex::new(AlertBook::new(config.urls.len(), &config.escalation)),
        generation: std::sync::atomic::AtomicU64::new(0),
        wake: Notify::new(),
        closed: std::sync::atomic::AtomicBool::new(false),
    });
    let client = client(config.tls.as_ref())?;
    Ok((
        AlertmanagerSink {
            labels: Labels::new(cell, config),
            shared: shared.clone(),
            metrics: metrics.clone(),
        },
        Pusher {
            urls: config.urls.clone(),
            resend: config.resend,
            client,
            shared,
            metrics,
        },
    ))
}

/// Checks that `config`'s TLS files can be used (`cellwatch validate`).
///
/// # Errors
/// A TLS file cannot be read or used.
pub(crate) fn check(config: &AlertmanagerConfig) -> Result<(), TlsError> {
    client(config.tls.as_ref()).map(drop)
}

/// An HTTP(S) client trusting `tls`'s CA (and presenting its client
/// certificate); HTTP only without it.
fn client(tls: Option<&AlertmanagerTls>) -> Result<Client, TlsError> {
    let client = tls.and_then(|t| t.client.as_ref());
    let config = crate::bus::client_tls::client_config(
        tls.map(|t| t.ca.as_path()),
        client.map(|(cert, key)| (cert.as_path(), key.as_path())),
    )?;
    let connector = hyper_rustls::HttpsConnectorBuilder::new()
        .with_tls_config(config)
        .https_or_http()
        .enable_http1()
        .build();
    Ok(
        hyper_util::client::legacy::Client::builder(hyper_util::rt::TokioExecutor::new())
            .build(connector),
    )
}

/// One Alertmanager's schedule.
#[derive(Clone, Copy)]
struct Due {
    /// The next send.
    at: tokio::time::Instant,
    /// The wait after the next failure.
    backoff: Backoff,
    /// The last send failed.
    failing: bool,
}

impl Pusher {
    /// Sends until the sink is gone (the cell loop has handed it its last
    /// step), then once more what is owed (bounded by the send timeout).
    pub(crate) async fn run(self) {
        let now = tokio::time::Instant::now();
        let mut due = vec![
            Due {
                at: now,
                backoff: Backoff::new(FIRST_RETRY, self.resend),
                failing: false,
            };
            self.urls.len()
        ];
        loop {
            if self
                .shared
                .closed
                .load(std::sync::atomic::Ordering::Acquire)
            {
                break;
            }
            let now = tokio::time::Instant::now();
            let now_ms = crate::clock::now_ms();
            let escalation = {
                let mut book = self.shared.book();
                if book.escalate(now_ms) {
                    self.shared
                        .generation
                        .fetch_add(1, std::sync::atomic::Ordering::AcqRel);
                }
                for (i, d) in due.iter_mut().enumerate() {
                    // A change goes out at once, unless that Alertmanager
                    // is failing (its retry is due by backoff).
                    if book.changed(i) && !d.failing {
                        d.at = d.at.min(now);
                    }
                }
                book.next_escalation(now_ms)
                    .map(|at| now + Duration::from_millis(at.saturating_sub(now_ms)))
            };
            let next = due
                .iter()
                .map(|d| d.at)
                .min()
                .unwrap_or(now + self.resend)
                .min(escalation.unwrap_or(now + self.resend));
            if next > now {
                tokio::select! {
                    () = self.shared.wake.notified() => continue,
                    () = tokio::time::sleep_until(next) => {}
                }
            }
            let now = tokio::time::Instant::now();
            let sends = due
                .iter()
                .enumerate()
                .filter(|(_, d)| d.at <= now)
                .map(|(i, _)| self.send(i));
            let results = futures_util::future::join_all(sends).await;
            for (i, ok) in results {
                let d = &mut due[i];
                if ok {
                    d.at = tokio::time::Instant::now() + self.resend;
                    d.backoff.reset();
                    d.failing = false;
                } else {
                    d.at = tokio::time::Instant::now() + d.backoff.next_wait();
                    d.failing = true;
                }
            }
        }
        // Stopping: what is owed, once, so that a clear just before the
        // stop is not left to expire.
        let owed: Vec<usize> = {
            let book = self.shared.book();
            (0..self.urls.len()).filter(|i| book.changed(*i)).collect()
        };
        futures_util::future::join_all(owed.into_iter().map(|i| self.send(i))).await;
    }

    /// One send of the book to Alertmanager `to`: `(to, accepted)`.
    async fn send(&self, to: usize) -> (usize, bool) {
        use std::sync::atomic::Ordering;
        let holds_until = crate::clock::now_ms()
            .saturating_add(4 * u64::try_from(self.resend.as_millis()).unwrap_or(u64::MAX / 8));
        let (batch, generation) = {
            let book = self.shared.book();
            (
                book.batch(to, &rfc3339(holds_until)),
                self.shared.generation.load(Ordering::Acquire),
            )
        };
        let url = &self.urls[to];
        match self.post(url, &batch.alerts).await {
            Ok(()) => {
                let mut book = self.shared.book();
                book.sent(&batch);
                // A change while the batch was on its way is still to go.
                if self.shared.generation.load(Ordering::Acquire) != generation {
                    book.mark_changed(to);
                }
                let unsent = book.unsent();
                AlertmanagerEvent::Sent { unsent }.emit(&self.metrics);
                (to, true)
            }
            Err(why) => {
                let why = why.to_string();
                AlertmanagerEvent::SendFailed { url, why: &why }.emit(&self.metrics);
                (to, false)
            }
        }
    }

    async fn post(&self, url: &str, alerts: &[Alert]) -> Result<(), SendError> {
        let body = serde_json::to_vec(alerts)?;
        let request = hyper::Request::post(format!("{url}/api/v2/alerts"))
            .header(hyper::header::CONTENT_TYPE, "application/json")
            .header(
                hyper::header::USER_AGENT,
                concat!("cellwatch/", env!("CARGO_PKG_VERSION")),
            )
            .body(http_body_util::Full::new(bytes::Bytes::from(body)))?;
        let response = tokio::time::timeout(SEND_TIMEOUT, self.client.request(request))
            .await
            .map_err(|_| SendError::Timeout(SEND_TIMEOUT))?
            .map_err(SendError::Connect)?;
        let status = response.status();
        if status.is_success() {
            return Ok(());
        }
        // What it says of the error: at most MAX_ERROR_BODY bytes read,
        // the rest never asked for (the connection is dropped with it).
        use http_body_util::BodyExt;
        let mut body = response.into_body();
        let mut said = Vec::new();
        let read = async {
            while said.len() < MAX_ERROR_BODY {
                match body.frame().await {
                    Some(Ok(frame)) => {
                        if let Ok(data) = frame.into_data() {
                            let room = MAX_ERROR_BODY - said.len();
                            said.extend_from_slice(&data[..data.len().min(room)]);
                        }
                    }
                    _ => break,
                }
            }
        };
        let _ = tokio::time::timeout(SEND_TIMEOUT, read).await;
        let said = String::from_utf8_lossy(&said[..said.len().min(300)]).to_string();
        Err(SendError::Refused {
            status,
            said: said.trim().to_string(),
        })
    }
}

/// An error and its causes, in one line.
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}
