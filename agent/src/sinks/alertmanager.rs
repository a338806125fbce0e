//! The cell's alarms to people, through Prometheus Alertmanager (API v2:
//! `POST /api/v2/alerts`), the notification engine plants already run
//! (e-mail, chat, paging; silences, inhibition, grouping).
//!
//! Each agent pushes its own alarms: it knows their state first-hand, no
//! plant-side process stands between an alarm and a person, and
//! Alertmanager is made to be pushed to by many senders (every Prometheus
//! does). Every active alarm that is not shelved, in service and no
//! suppressed consequence is an alert (a consequence announced carries
//! its cause and first-out as labels, for Alertmanager's inhibition); it is sent when it is raised or changes, again every
//! `resend_interval`, each time saying it ends four intervals later unless
//! sent again (as Prometheus does: an agent that dies stops renewing its
//! alerts rather than leaving them firing for ever; its `up` and health
//! alerts say why). A clear, a shelf or a removal from service sends the
//! alert once more with `endsAt`, the time it happened, until every
//! Alertmanager has taken it.
//!
//! The sink only writes into the [`Book`] (a lock held for a map update)
//! and wakes the [`Pusher`], a task of its own: a slow or dead
//! Alertmanager never holds up the cell loop. Failed sends are retried
//! with backoff (1 s doubling to the resend interval), per Alertmanager,
//! counted in `cellwatch_alertmanager_sends_total{result="failed"}`.
//! Memory is bounded by the alarms the cell can raise: one entry per
//! alarm, active or ended.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use cellwatch_models::alarm::AlarmState;
use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use serde::Serialize;
use tokio::sync::Notify;

use super::Sink;
use crate::backoff::Backoff;
use crate::clock::rfc3339;
use crate::config::{AlertmanagerConfig, AlertmanagerTls};
use crate::metrics::Metrics;
use crate::payload::AlarmPayload;
use crate::step::CellStep;

/// How long one send may take.
const SEND_TIMEOUT: Duration = Duration::from_secs(10);

/// The most of an error answer's body read (its first 300 bytes are
/// logged): an Alertmanager, or whatever answers in its place, cannot make
/// the agent hold more.
const MAX_ERROR_BODY: usize = 64 * 1024;

/// The first retry after a failed send; doubled up to the resend interval.
const FIRST_RETRY: Duration = Duration::from_secs(1);

/// An alert as Alertmanager's API v2 takes it (`postableAlert`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Alert {
    /// What identifies it: `alertname`, `alarm`, `cell`, `area`,
    /// `priority`, `kind`.
    pub labels: BTreeMap<&'static str, String>,
    /// What people read: `summary`, `culprits` (each culprit's line, as
    /// the CLI prints it, joined by `; `), `acknowledged`, `console`.
    pub annotations: BTreeMap<&'static str, String>,
    /// When the occurrence was raised (RFC 3339).
    #[serde(rename = "startsAt")]
    pub starts_at: String,
    /// When it ended, or until when it holds unless sent again.
    #[serde(rename = "endsAt")]
    pub ends_at: String,
    /// The alarm's page on the console.
    #[serde(rename = "generatorURL", skip_serializing_if = "Option::is_none")]
    pub generator_url: Option<String>,
}

/// The labels and links every alert of the cell carries.
#[derive(Debug, Clone)]
pub struct Labels {
    cell: String,
    area: Option<String>,
    console: Option<String>,
}

impl Labels {
    /// For `cell`, from its configuration.
    pub fn new(cell: &str, config: &AlertmanagerConfig) -> Labels {
        Labels {
            cell: cell.into(),
            area: config.area.clone(),
            console: config.console.clone(),
        }
    }

    /// The alert for `alarm` (its `endsAt` set when it is sent or ended).
    fn alert(&self, alarm: &AlarmPayload) -> Alert {
        let mut labels = BTreeMap::from([
            ("alertname", alarm.id.clone()),
            ("alarm", alarm.id.clone()),
            ("cell", self.cell.clone()),
            ("priority", alarm.severity.as_str().to_string()),
            ("kind", alarm.kind.as_str().to_string()),
        ]);
        if let Some(area) = &self.area {
            labels.insert("area", area.clone());
        }
        if let Some(c) = &alarm.consequence {
            labels.insert("consequence_of", c.cause.clone());
            labels.insert("first_out", c.first_out.clone());
        }
        let mut annotations = BTreeMap::from([("summary", alarm.message.clone())]);
        if let Some(c) = &alarm.consequence {
            annotations.insert("consequence", c.why());
        }
        // The same line the CLI and the console show for each culprit.
        let culprits: Vec<String> = alarm
            .culprits
            .iter()
            .map(|c| c.line().trim_end().to_string())
            .collect();
        if !culprits.is_empty() {
            annotations.insert("culprits", culprits.join("; "));
        }
        if let Some(by) = &alarm.acked_by {
            let said = alarm
                .ack_comment
                .as_ref()
                .map_or_else(String::new, |c| format!(": {c}"));
            annotations.insert("acknowledged", format!("by {by}{said}"));
        }
        let generator_url = self
            .console
            .as_ref()
            .map(|c| format!("{c}/#/alarm/{}/{}", self.cell, alarm.id));
        if let Some(link) = &generator_url {
            annotations.insert("console", link.clone());
        }
        Alert {
            labels,
            annotations,
            starts_at: alarm.raised_at.clone(),
            ends_at: String::new(),
            generator_url,
        }
    }
}

/// What is to be sent, per alarm: active alerts, and ended ones until
/// every Alertmanager has taken them. Pure: no I/O, no clock.
#[derive(Debug, Default)]
pub struct Book {
    active: BTreeMap<String, Alert>,
    /// Ended alerts and the Alertmanagers (bits by index) still owed them.
    ended: BTreeMap<String, (Alert, u64)>,
    /// The Alertmanagers (bits) with a change they have not been sent.
    changed: u64,
    /// Every Alertmanager's bit.
    all: u64,
}

/// One send's content for one Alertmanager.
#[derive(Debug)]
pub struct Batch {
    /// The Alertmanager's index.
    pub to: usize,
    /// The alerts, active ones with `endsAt` set.
    pub alerts: Vec<Alert>,
    /// The ended alerts in it (their ids).
    ended: Vec<String>,
}

impl Book {
    /// A book for `alertmanagers` Alertmanagers (at most 64).
    pub fn new(alertmanagers: usize) -> Book {
        let all = if alertmanagers >= 64 {
            u64::MAX
        } else {
            (1u64 << alertmanagers) - 1
        };
        Book {
            all,
            ..Book::default()
        }
    }

    /// Takes `alarm`'s latest payload: whether anything is to be sent.
    pub fn take(&mut self, labels: &Labels, alarm: &AlarmPayload) -> bool {
        let alerting = matches!(
            alarm.state,
            AlarmState::ActiveUnacknowledged | AlarmState::ActiveAcknowledged
        ) && alarm.shelved.is_none()
            && alarm.out_of_service.is_none()
            && !alarm.consequence.as_ref().is_some_and(|c| c.suppressed);
        if alerting {
            let alert = labels.alert(alarm);
            if self.active.get(&alarm.id) == Some(&alert) {
                return false;
            }
            self.ended.remove(&alarm.id);
            self.active.insert(alarm.id.clone(), alert);
        } else {
            let Some(mut alert) = self.active.remove(&alarm.id) else {
                return false;
            };
            // It ended when it cleared, was shelved or taken out of
            // service: this payload's time.
            alert.ends_at = alarm.at.clone();
            self.ended.insert(alarm.id.clone(), (alert, self.all));
        }
        self.changed = self.all;
        true
    }

    /// Whether Alertmanager `to` has a change it was not sent.
    pub fn changed(&self, to: usize) -> bool {
        self.changed & (1 << to) != 0
    }

    /// What to send to Alertmanager `to`: every active alert, holding
    /// until `holds_until` (RFC 3339), and the ended ones it is owed.
    pub fn batch(&self, to: usize, holds_until: &str) -> Batch {
        let bit = 1 << to;
        let mut alerts: Vec<Alert> = self
            .active
            .values()
            .map(|a| Alert {
                ends_at: holds_until.to_string(),
                ..a.clone()
            })
            .collect();
        let mut ended = Vec::new();
        for (id, (alert, owed)) in &self.ended {
            if owed & bit != 0 {
                alerts.push(alert.clone());
                ended.push(id.clone());
            }
        }
        Batch { to, alerts, ended }
    }

    /// Alertmanager `batch.to` took `batch`.
    pub fn sent(&mut self, batch: &Batch) {
        let bit = 1 << batch.to;
        for id in &batch.ended {
            if let Some((_, owed)) = self.ended.get_mut(id) {
                *owed &= !bit;
                if *owed == 0 {
                    self.ended.remove(id);
                }
            }
        }
        // A change after the batch was made is in the book, not in the
        // batch: only a batch with everything clears the flag (the caller
        // makes and sends batches with the book's lock released, so it
        // marks the change again if one came: see `Pusher`).
        self.changed &= !bit;
    }

    /// Alerts active now.
    pub fn active(&self) -> usize {
        self.active.len()
    }

    /// Changes not yet taken by every Alertmanager: ended alerts owed,
    /// plus the active ones while any Alertmanager has a change unsent.
    pub fn unsent(&self) -> usize {
        let active = if self.changed == 0 {
            0
        } else {
            self.active.len()
        };
        self.ended.len() + active
    }
}

/// The state the sink and the pusher share.
struct Shared {
    book: Mutex<Book>,
    /// Counts changes, so the pusher knows whether one came while a batch
    /// was on its way.
    generation: std::sync::atomic::AtomicU64,
    wake: Notify,
    /// The sink is gone (the cell loop ended): the pusher sends what is
    /// owed once more and ends.
    closed: std::sync::atomic::AtomicBool,
}

impl Shared {
    fn book(&self) -> std::sync::MutexGuard<'_, Book> {
        self.book
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// Hands the cell's alarms to the [`Pusher`].
pub struct AlertmanagerSink {
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
                changed |= book.take(&self.labels, &a.payload);
            }
            if changed {
                self.metrics.alertmanager_alerts.set(book.active() as i64);
                self.metrics.alertmanager_unsent.set(book.unsent() as i64);
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
pub struct Pusher {
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
pub struct TlsError(String);

/// The sink for the cell loop and the pusher to run beside it.
///
/// # Errors
/// A TLS file cannot be read or used.
pub fn start(
    cell: &str,
    config: &AlertmanagerConfig,
    metrics: Arc<Metrics>,
) -> Result<(AlertmanagerSink, Pusher), TlsError> {
    let shared = Arc::new(Shared {
        book: Mutex::new(Book::new(config.urls.len())),
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
pub fn check(config: &AlertmanagerConfig) -> Result<(), TlsError> {
    client(config.tls.as_ref()).map(drop)
}

/// An HTTP(S) client trusting `tls`'s CA (and presenting its client
/// certificate); HTTP only without it.
fn client(tls: Option<&AlertmanagerTls>) -> Result<Client, TlsError> {
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let bad = |what: &std::path::Path, e: String| TlsError(format!("{}: {e}", what.display()));
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
            crate::bus::envelope::check_private(key).map_err(|e| TlsError(e.to_string()))?;
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
    .map_err(|e| TlsError(e.to_string()))?
    .with_root_certificates(roots);
    let config = match identity {
        Some((chain, key)) => builder
            .with_client_auth_cert(chain, key)
            .map_err(|e| TlsError(e.to_string()))?,
        None => builder.with_no_client_auth(),
    };
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
    pub async fn run(self) {
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
            {
                let book = self.shared.book();
                for (i, d) in due.iter_mut().enumerate() {
                    // A change goes out at once, unless that Alertmanager
                    // is failing (its retry is due by backoff).
                    if book.changed(i) && !d.failing {
                        d.at = d.at.min(now);
                    }
                }
            }
            let next = due.iter().map(|d| d.at).min().unwrap_or(now + self.resend);
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
        let outcome = self.post(url, &batch.alerts).await;
        self.metrics.alertmanager_sent(outcome.is_ok());
        match outcome {
            Ok(()) => {
                let mut book = self.shared.book();
                book.sent(&batch);
                // A change while the batch was on its way is still to go.
                if self.shared.generation.load(Ordering::Acquire) != generation {
                    book.changed |= 1 << to;
                }
                self.metrics.alertmanager_unsent.set(book.unsent() as i64);
                (to, true)
            }
            Err(why) => {
                tracing::warn!(alertmanager = %url, %why, "cannot send alerts; retrying");
                (to, false)
            }
        }
    }

    async fn post(&self, url: &str, alerts: &[Alert]) -> Result<(), String> {
        let body = serde_json::to_vec(alerts).map_err(|e| e.to_string())?;
        let request = hyper::Request::post(format!("{url}/api/v2/alerts"))
            .header(hyper::header::CONTENT_TYPE, "application/json")
            .header(
                hyper::header::USER_AGENT,
                concat!("cellwatch/", env!("CARGO_PKG_VERSION")),
            )
            .body(http_body_util::Full::new(bytes::Bytes::from(body)))
            .map_err(|e| e.to_string())?;
        let response = tokio::time::timeout(SEND_TIMEOUT, self.client.request(request))
            .await
            .map_err(|_| format!("no answer within {} s", SEND_TIMEOUT.as_secs()))?
            .map_err(|e| error_chain(&e))?;
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
        Err(format!("{status}: {}", said.trim()))
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

#[cfg(test)]
mod tests {
    use super::*;
    use cellwatch_models::alarm::{AlarmKind, Severity, Transition};

    fn payload(id: &str, state: AlarmState, at: &str) -> AlarmPayload {
        let mut p: AlarmPayload = serde_json::from_value(serde_json::json!({
            "schema": "cellwatch.alarm.v1", "cell": "m01", "id": id,
            "kind": "switching", "severity": "high", "state": "normal",
            "transition": "raised", "at": at, "raised_at": "2026-11-26T10:00:00.000Z",
            "cleared_at": null, "acked_by": null, "fault_type": "ESE", "fault_step": 3,
            "culprits": [{"address": "X0.06", "value": false, "expected": true,
                          "comment": "Emergency stop", "trigger": true}],
            "message": "Emergency stop error",
        }))
        .unwrap();
        p.state = state;
        p.kind = AlarmKind::Switching;
        p.severity = Severity::High;
        p.transition = Transition::Raised;
        p
    }

    fn labels() -> Labels {
        Labels {
            cell: "m01".into(),
            area: Some("press shop".into()),
            console: Some("https://console:8470".into()),
        }
    }

    #[test]
    fn a_consequence_is_an_alert_naming_its_cause_unless_suppressed() {
        let mut book = Book::new(1);
        let l = labels();
        let mut csd = payload(
            "csd",
            AlarmState::ActiveUnacknowledged,
            "2026-11-26T10:00:00.000Z",
        );
        csd.consequence = Some(crate::payload::ConsequencePayload {
            cause: "ese".into(),
            first_out: "ese".into(),
            suppressed: false,
            through: vec![crate::payload::ThroughPayload {
                signal: "G8.02".into(),
                value: true,
            }],
        });
        assert!(book.take(&l, &csd));
        let b = book.batch(0, "2026-11-26T10:04:00.000Z");
        assert_eq!(b.alerts[0].labels["consequence_of"], "ese");
        assert_eq!(b.alerts[0].labels["first_out"], "ese");
        assert_eq!(
            b.alerts[0].annotations["consequence"],
            "follows from ese: G8.02 = 1 (0 without ese's fault)"
        );
        // Suppressed: no alert (and the one sent ends).
        let mut book = Book::new(1);
        if let Some(c) = csd.consequence.as_mut() {
            c.suppressed = true;
        }
        assert!(!book.take(&l, &csd));
        assert!(book.batch(0, "2026-11-26T10:04:00.000Z").alerts.is_empty());
    }

    #[test]
    fn an_alarm_is_an_alert_while_active_unshelved_and_in_service() {
        let mut book = Book::new(2);
        let l = labels();
        let raised = payload(
            "ese",
            AlarmState::ActiveUnacknowledged,
            "2026-11-26T10:00:00.000Z",
        );
        assert!(book.take(&l, &raised));
        assert!(book.changed(0) && book.changed(1));
        let b = book.batch(0, "2026-11-26T10:04:00.000Z");
        assert_eq!(b.alerts.len(), 1);
        let a = &b.alerts[0];
        assert_eq!(a.labels["alertname"], "ese");
        assert_eq!(a.labels["cell"], "m01");
        assert_eq!(a.labels["area"], "press shop");
        assert_eq!(a.labels["priority"], "high");
        assert_eq!(a.labels["kind"], "switching");
        assert_eq!(
            a.annotations["culprits"],
            "X0.06 = 0 (expected 1): Emergency stop   <- trigger"
        );
        assert_eq!(a.annotations["summary"], "Emergency stop error");
        assert_eq!(a.starts_at, "2026-11-26T10:00:00.000Z");
        assert_eq!(a.ends_at, "2026-11-26T10:04:00.000Z");
        assert_eq!(
            a.generator_url.as_deref(),
            Some("https://console:8470/#/alarm/m01/ese")
        );
        book.sent(&b);
        assert!(!book.changed(0) && book.changed(1));
        // The same payload again changes nothing; an acknowledgement does.
        assert!(!book.take(&l, &raised));
        let mut acked = payload(
            "ese",
            AlarmState::ActiveAcknowledged,
            "2026-11-26T10:01:00.000Z",
        );
        acked.acked_by = Some("kim".into());
        acked.ack_comment = Some("tool changed".into());
        assert!(book.take(&l, &acked));
        assert_eq!(
            book.batch(0, "x").alerts[0].annotations["acknowledged"],
            "by kim: tool changed"
        );

        // Shelved: ended at the shelf's time, owed to both.
        let mut shelved = acked.clone();
        shelved.at = "2026-11-26T10:02:00.000Z".into();
        shelved.shelved = Some(serde_json::from_value(serde_json::json!({
            "by": "kim", "reason": "sensor swap", "at": "2026-11-26T10:02:00.000Z", "until": null
        })).unwrap());
        assert!(book.take(&l, &shelved));
        assert_eq!(book.active(), 0);
        let b0 = book.batch(0, "x");
        assert_eq!(b0.alerts.len(), 1);
        assert_eq!(b0.alerts[0].ends_at, "2026-11-26T10:02:00.000Z");
        book.sent(&b0);
        // Owed to the second Alertmanager until it takes it.
        assert!(book.batch(0, "x").alerts.is_empty());
        assert_eq!(book.unsent(), 1);
        let b1 = book.batch(1, "x");
        assert_eq!(b1.alerts.len(), 1);
        book.sent(&b1);
        assert_eq!(book.unsent(), 0);

        // Unshelved while active: an alert again; cleared: ended again.
        assert!(book.take(&l, &acked));
        assert_eq!(book.active(), 1);
        let cleared = payload(
            "ese",
            AlarmState::ClearedUnacknowledged,
            "2026-11-26T10:05:00.000Z",
        );
        assert!(book.take(&l, &cleared));
        assert_eq!(
            book.batch(1, "x").alerts[0].ends_at,
            "2026-11-26T10:05:00.000Z"
        );
        // Out of service: never an alert.
        let mut removed = raised.clone();
        removed.id = "door".into();
        removed.out_of_service = Some(
            serde_json::from_value(serde_json::json!({
                "by": "kim", "reason": "rebuild", "at": "2026-11-26T10:06:00.000Z"
            }))
            .unwrap(),
        );
        assert!(!book.take(&l, &removed));
        assert_eq!(book.active(), 0);
    }
}
