//! The agent's query services on Zenoh:
//! - `<prefix>/history?since=1h;until=...;kind=state|alarm|command;limit=N;after=SEQ`:
//!   one bounded page of journal rows ([`journal::HistoryPage`]: at most
//!   [`journal::MAX_ROWS`] rows and [`journal::MAX_REPLY_BYTES`] bytes,
//!   oldest first; the newest rows, or with `after` the rows after that
//!   sequence number and the `next` one to ask for), read from the journal
//!   file on a blocking thread, never holding up the cell loop;
//!   with `kind=kpi`, instead, the ISA-18.2 alarm figures of `[since,
//!   until)` (default the last 24 h) computed from the journal as
//!   `cellwatch report alarms` computes them; with `kind=production`, the
//!   production day from `since`, as `cellwatch report daily`;
//! - `<prefix>/snapshot`: tag values with quality, active alarms, and the
//!   values at the last fault ([`crate::payload::SnapshotPayload`]), asked
//!   of the cell loop;
//! - `<prefix>/command`: a signed [`crate::operator::Command`], carried out
//!   (or refused) by the cell loop; every reply, "busy" included, is a
//!   [`crate::step::CommandOutcome`] naming the payload it answers
//!   ([`crate::step::command_digest`]), so that an answer to another or a
//!   garbled payload sent with the same query parameters is never taken
//!   for the answer to the command.
//!
//! Queries are answered concurrently, at most [`MAX_CONCURRENT`] at a time
//! and [`MAX_CONCURRENT_HISTORY`] history queries among them; more are told
//! the agent is busy. Each queryable queues at most [`QUEUE`] queries. A
//! command payload larger than [`MAX_COMMAND_BYTES`] is refused before it
//! is parsed, and journaled by size, hash and a short prefix; no reply
//! repeats the request. Refusals are counted
//! (`cellwatch_requests_refused_total`), a reply that cannot be sent logged
//! and counted, through the services' events (`events.rs`).

pub(crate) mod about;
pub mod alarm_server;
mod events;
pub(crate) mod plant_operators;

use std::collections::HashMap;
use std::future::Future;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use tokio::sync::{mpsc, oneshot, Semaphore};
use tokio::task::JoinSet;
use zenoh::query::Query;
use zenoh::Session;

use crate::bus::envelope::{AgentKey, Kind as Sealed};
use crate::bus::keys::{CellKeys, Service};
use crate::bus::ZenohError;
pub use crate::bus::MAX_MESSAGE_BYTES;
use crate::clock::{now_ms, parse_time, NotATime};
use crate::journal::{self, Barrier, HistoryQuery, Journal};
use crate::metrics::Metrics;
use crate::operator::{Command, NotACommand};
use crate::step::{command_digest, CommandOutcome, Request};
use cellwatch_models::kpi::KpiRules;
use events::ServiceEvent;

/// Queries answered at the same time; more are refused as busy.
pub const MAX_CONCURRENT: usize = 16;
/// History queries answered at the same time (each holds up to
/// [`journal::MAX_REPLY_BYTES`]); more are refused as busy.
pub const MAX_CONCURRENT_HISTORY: usize = 4;
/// Queries waiting in each queryable's queue before Zenoh drops more.
pub const QUEUE: usize = 32;
/// The largest command payload read.
pub const MAX_COMMAND_BYTES: usize = 4096;

type Queryable = zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<Query>>;

/// The declared queryables and what answering needs.
pub struct Services {
    history: Queryable,
    snapshot: Queryable,
    command: Queryable,
    about: Queryable,
    /// The plant operators list's side, when the plant signs operators.
    plant: Option<plant_operators::Listener>,
    /// What `about` answers: kept current by the agent.
    about_now: tokio::sync::watch::Receiver<crate::payload::AboutPayload>,
    journal: PathBuf,
    /// The rules the alarm figures (`kind=kpi`) are judged by.
    kpi: KpiRules,
    /// Waits for the journal's queued rows: a history page shows every
    /// alarm already published.
    journal_settled: Barrier,
    /// The end of the journal's command chain, as committed: carried in
    /// the snapshot's answer.
    command_chain: tokio::sync::watch::Receiver<journal::chain::Link>,
    /// Requests to the cell loop (snapshot, command), answered on a
    /// one-shot channel each.
    requests: mpsc::Sender<Request>,
    /// Bounds the queries being answered at once.
    permits: Arc<Semaphore>,
    /// Bounds the history queries among them.
    history_permits: Arc<Semaphore>,
    /// Seals every answer, on the queryable's own key.
    seal: Seal,
    metrics: Arc<Metrics>,
}

/// What sealing an answer needs: the agent's key and its keys.
#[derive(Clone)]
struct Seal {
    key: Arc<AgentKey>,
    keys: CellKeys,
}

impl Services {
    /// Declares `history`, `snapshot` and `command` under `prefix`.
    ///
    /// # Errors
    /// Zenoh refuses a declaration.
    pub async fn declare(
        session: &Session,
        prefix: &str,
        key: Arc<AgentKey>,
        journal: &Journal,
        kpi: KpiRules,
        requests: mpsc::Sender<Request>,
        metrics: Arc<Metrics>,
    ) -> Result<Services, ZenohError> {
        let keys = CellKeys::new(prefix);
        let declare = |service: Service| {
            let key = keys.service(service);
            async move {
                session
                    .declare_queryable(key.clone())
                    .with(zenoh::handlers::FifoChannel::new(QUEUE))
                    .await
                    .map_err(|e| ZenohError::Declare {
                        key,
                        reason: e.to_string(),
                    })
            }
        };
        Ok(Services {
            history: declare(Service::History).await?,
            snapshot: declare(Service::Snapshot).await?,
            command: declare(Service::Command).await?,
            about: declare(Service::About).await?,
            plant: None,
            about_now: tokio::sync::watch::channel(crate::payload::AboutPayload::default()).1,
            journal: journal.path().to_path_buf(),
            kpi,
            journal_settled: journal.barrier(),
            command_chain: journal.command_chain(),
            requests,
            permits: Arc::new(Semaphore::new(MAX_CONCURRENT)),
            history_permits: Arc::new(Semaphore::new(MAX_CONCURRENT_HISTORY)),
            seal: Seal {
                key,
                keys: keys.clone(),
            },
            metrics,
        })
    }

    /// `about` answered from `about`, which the agent keeps current.
    pub fn telling(
        mut self,
        about: tokio::sync::watch::Receiver<crate::payload::AboutPayload>,
    ) -> Services {
        self.about_now = about;
        self
    }

    /// Plant operators lists heard, taken and answered by `listener`.
    pub fn taking_operators(mut self, listener: Option<plant_operators::Listener>) -> Services {
        self.plant = listener;
        self
    }

    /// Answers queries until `shutdown` completes; then waits for the
    /// answers under way and undeclares the queryables.
    pub async fn run(mut self, shutdown: impl Future<Output = ()>) {
        tokio::pin!(shutdown);
        let mut answering = JoinSet::new();
        loop {
            let (kind, q) = tokio::select! {
                _ = &mut shutdown => break,
                Ok(q) = self.history.recv_async() => (Service::History, q),
                Ok(q) = self.snapshot.recv_async() => (Service::Snapshot, q),
                Ok(q) = self.command.recv_async() => (Service::Command, q),
                heard = heard(&mut self.plant) => {
                    if let Some(plant) = self.plant.as_mut() {
                        match heard {
                            plant_operators::Heard::List(bytes) => plant.consider(&bytes, &self.requests).await,
                            plant_operators::Heard::Asked(q) => plant.answer(q).await,
                        }
                    }
                    continue;
                }
                Ok(q) = self.about.recv_async() => {
                    let about = serde_json::to_string(&*self.about_now.borrow()).unwrap_or_default();
                    reply(&self.seal, Service::About, &self.metrics, q, Ok(about)).await;
                    continue;
                }
                Some(_) = answering.join_next(), if !answering.is_empty() => continue,
            };
            let history_permit = match kind {
                Service::History => self.history_permits.clone().try_acquire_owned().ok(),
                _ => None,
            };
            let permit = self.permits.clone().try_acquire_owned().ok();
            if permit.is_none() || (matches!(kind, Service::History) && history_permit.is_none()) {
                ServiceEvent::Refused {
                    service: kind.name(),
                    reason: "busy",
                }
                .emit(&self.metrics);
                let busy = ServiceError::Busy;
                let answer = match kind {
                    Service::Command => Ok(command_answer(
                        &q,
                        CommandOutcome::new(false, busy.to_string()),
                    )),
                    _ => Err(busy),
                };
                reply(&self.seal, kind, &self.metrics, q, answer).await;
                continue;
            }
            let (journal, rules, settled, requests, seal, metrics) = (
                self.journal.clone(),
                self.kpi,
                self.journal_settled.clone(),
                self.requests.clone(),
                self.seal.clone(),
                self.metrics.clone(),
            );
            let chain = self.command_chain.clone();
            answering.spawn(async move {
                let _permits = (permit, history_permit);
                let result = match kind {
                    Service::History => match history_query(q.parameters().as_str(), now_ms()) {
                        Ok(query) => {
                            settled.settled().await;
                            history(&journal, &rules, query).await
                        }
                        Err(e) => {
                            ServiceEvent::Refused {
                                service: kind.name(),
                                reason: "invalid",
                            }
                            .emit(&metrics);
                            Err(e)
                        }
                    },
                    Service::Snapshot => snapshot(&requests, &chain).await,
                    Service::About => Err(ServiceError::AboutAtOnce),
                    Service::Command => Ok(command_answer(
                        &q,
                        command(&requests, &q, &metrics)
                            .await
                            .unwrap_or_else(|why| CommandOutcome::new(false, why.to_string())),
                    )),
                };
                reply(&seal, kind, &metrics, q, result).await;
            });
        }
        answering.shutdown().await;
    }
}

/// Why a query is answered with an error: the text its asker reads.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// As many queries are being answered as may be.
    #[error("the agent is busy: try again")]
    Busy,
    /// `about` has an answer of its own, never queued.
    #[error("about is answered at once")]
    AboutAtOnce,
    /// The agent is stopping: the cell loop no longer answers.
    #[error("the agent is stopping")]
    Stopping,
    /// A history selector's time does not read.
    #[error(transparent)]
    Time(#[from] NotATime),
    /// A history selector's `after` is not a sequence number (the text).
    #[error("after '{0}' is not a sequence number")]
    After(String),
    /// A history selector's `limit` is not a number (the text).
    #[error("limit '{0}' is not a number")]
    Limit(String),
    /// `kind=kpi` over an empty window.
    #[error("kind=kpi: since must be before until")]
    KpiWindow,
    /// The blocking read of the journal did not finish.
    #[error("{what} query failed: {source}")]
    Task {
        /// `history`, `kpi` or `production`.
        what: &'static str,
        /// Why.
        source: tokio::task::JoinError,
    },
    /// The journal cannot be read, or the query asks for nothing it holds.
    #[error(transparent)]
    History(#[from] journal::HistoryError),
}

/// What the plant operators list's listener heard next; never, without one.
async fn heard(plant: &mut Option<plant_operators::Listener>) -> plant_operators::Heard {
    match plant {
        Some(p) => p.next().await,
        None => std::future::pending().await,
    }
}

/// One page of `query` from the journal. A read that fails is logged and
/// answered with the reason; it is not a refusal of the request.
async fn history(
    journal: &Path,
    rules: &KpiRules,
    query: HistoryQuery,
) -> Result<String, ServiceError> {
    match query.kind.as_deref() {
        Some("kpi") => return kpi(journal, rules, &query).await,
        Some("production") => return production(journal, &query).await,
        _ => {}
    }
    let path = journal.to_path_buf();
    let rows = tokio::task::spawn_blocking(move || {
        let conn = journal::open_read(&path)?;
        journal::history(&conn, &query)
    })
    .await
    .map_err(|source| ServiceError::Task {
        what: "history",
        source,
    })?
    .inspect_err(|e| {
        tracing::error!(journal = %journal.display(), error = %e, "cannot read the journal for a history query");
    })?;
    Ok(serde_json::to_string(&rows).unwrap_or_default())
}

/// The ISA-18.2 figures of `[since, until)` (default: the last 24 h, until
/// now) from the journal, with their benchmarks, as `cellwatch report
/// alarms --format json` prints them.
async fn kpi(
    journal: &Path,
    rules: &KpiRules,
    query: &HistoryQuery,
) -> Result<String, ServiceError> {
    let now = now_ms();
    let until = query.until.unwrap_or(now);
    let since = query.since.unwrap_or(until.saturating_sub(24 * 3_600_000));
    if since >= until {
        return Err(ServiceError::KpiWindow);
    }
    let path = journal.to_path_buf();
    let read = tokio::task::spawn_blocking(move || {
        let conn = journal::open_read(&path).map_err(journal::HistoryError::from)?;
        journal::alarm_events(&conn, since, until).map_err(journal::HistoryError::from)
    })
    .await
    .map_err(|source| ServiceError::Task {
        what: "kpi",
        source,
    })?
    .inspect_err(|e| {
        tracing::error!(journal = %journal.display(), error = %e, "cannot read the journal for the alarm figures");
    })?;
    let report =
        cellwatch_models::kpi::alarm_report(&read.events, &read.before, since, until, now, rules);
    let mut v = serde_json::to_value(&report).unwrap_or_default();
    v["benchmarks"] = serde_json::to_value(report.benchmarks()).unwrap_or_default();
    v["unreadable"] = read.unreadable.into();
    Ok(v.to_string())
}

/// The production day that starts at `since` (default: the 24 hours up to
/// now): minutes per state hour by hour, availability, stop causes (named
/// by their fault type), parts and work orders, as `cellwatch report daily
/// --format json` computes them from the same journal rows.
async fn production(journal: &Path, query: &HistoryQuery) -> Result<String, ServiceError> {
    const DAY: u64 = 86_400_000;
    let now = now_ms();
    let start = query.since.unwrap_or(now.saturating_sub(DAY));
    let path = journal.to_path_buf();
    let input = tokio::task::spawn_blocking(move || {
        let conn = journal::open_read(&path).map_err(journal::HistoryError::from)?;
        journal::report_input(&conn, start, start + DAY).map_err(journal::HistoryError::from)
    })
    .await
    .map_err(|source| ServiceError::Task {
        what: "production",
        source,
    })?
    .inspect_err(|e| {
        tracing::error!(journal = %journal.display(), error = %e, "cannot read the journal for the production figures");
    })?;
    let day = cellwatch_models::report::daily(
        &input.changes,
        &input.parts,
        &input.orders,
        start,
        &cellwatch_models::report::StopCauses::default(),
        now,
    );
    Ok(serde_json::to_string(&day).unwrap_or_default())
}

/// Parses a history selector's parameters at `now`.
///
/// # Errors
/// A time or limit that does not parse.
pub fn history_query(parameters: &str, now: u64) -> Result<HistoryQuery, ServiceError> {
    let params = selector_parameters(parameters);
    Ok(HistoryQuery {
        since: params
            .get("since")
            .map(|s| parse_time(s, now))
            .transpose()?,
        until: params
            .get("until")
            .map(|s| parse_time(s, now))
            .transpose()?,
        kind: params.get("kind").cloned(),
        after: params
            .get("after")
            .map(|a| a.parse().map_err(|_| ServiceError::After(a.clone())))
            .transpose()?,
        limit: params
            .get("limit")
            .map(|l| l.parse().map_err(|_| ServiceError::Limit(l.clone())))
            .transpose()?,
    })
}

/// The snapshot as the loop answers it (once the rows staged before it are
/// committed), with the end of the command chain committed by then.
async fn snapshot(
    requests: &mpsc::Sender<Request>,
    chain: &tokio::sync::watch::Receiver<journal::chain::Link>,
) -> Result<String, ServiceError> {
    #[derive(serde::Serialize)]
    struct Answer<'a> {
        #[serde(flatten)]
        snapshot: &'a crate::payload::SnapshotPayload,
        command_chain: crate::payload::CommandChain,
    }
    let (tx, rx) = oneshot::channel();
    requests
        .send(Request::Snapshot(tx))
        .await
        .map_err(|_| ServiceError::Stopping)?;
    let snap = rx.await.map_err(|_| ServiceError::Stopping)?;
    let answer = Answer {
        snapshot: &snap,
        command_chain: chain.borrow().announced(),
    };
    Ok(serde_json::to_string(&answer).unwrap_or_default())
}

/// `outcome` as the answer to the command `q` carries: naming its payload.
fn command_answer(q: &Query, outcome: CommandOutcome) -> String {
    let digest = match q.payload() {
        Some(p) => command_digest(p.slices()),
        None => command_digest(std::iter::empty()),
    };
    serde_json::to_string(&outcome.answering(digest)).unwrap_or_default()
}

async fn command(
    requests: &mpsc::Sender<Request>,
    q: &Query,
    metrics: &Metrics,
) -> Result<CommandOutcome, ServiceError> {
    // As the querier says: anyone may claim any id, which only moves its
    // refusals to another summary row (at most 16 sources a minute).
    let source = q
        .source_info()
        .map(|s| s.source_id().zid().to_string())
        .unwrap_or_else(|| crate::operator::refusals::UNKNOWN_SOURCE.into());
    let parsed = match q.payload() {
        None => {
            refused("invalid", metrics);
            Err(NotACommand {
                reason: "no payload".into(),
                kind: "invalid",
            })
        }
        // Never parsed; identified in the journal by size, hash and prefix.
        Some(p) if p.len() > MAX_COMMAND_BYTES => {
            refused("too_large", metrics);
            Err(NotACommand::payload(
                "too_large",
                &format!("larger than {MAX_COMMAND_BYTES} bytes"),
                p.slices(),
            ))
        }
        Some(p) => {
            let bytes = p.to_bytes();
            serde_json::from_slice::<Command>(&bytes).map_err(|e| {
                refused("invalid", metrics);
                NotACommand::json(&e, &bytes)
            })
        }
    };
    let (tx, rx) = oneshot::channel();
    requests
        .send(Request::Command {
            source,
            command: parsed,
            reply: tx,
        })
        .await
        .map_err(|_| ServiceError::Stopping)?;
    let outcome: CommandOutcome = rx.await.map_err(|_| ServiceError::Stopping)?;
    if let Some(reason) = outcome.refused {
        refused(reason, metrics);
    }
    Ok(outcome)
}

/// A command refused for `reason`.
fn refused(reason: &str, metrics: &Metrics) {
    ServiceEvent::Refused {
        service: "command",
        reason,
    }
    .emit(metrics);
}

/// Answers a query with JSON, or with an error text, sealed: on the
/// queryable's own key (a query on `cellwatch/*/snapshot` is answered on
/// `cellwatch/<cell>/snapshot`, which routers' access control can match to
/// the cell's agent) and bound to the query's parameters.
async fn reply(
    seal: &Seal,
    kind: Service,
    metrics: &Metrics,
    q: Query,
    result: Result<String, ServiceError>,
) {
    let key = seal.keys.service(kind);
    let parameters = q.parameters().as_str().to_string();
    let at = now_ms();
    let sent = match result {
        Ok(json) => {
            let sealed = seal.key.seal(Sealed::Reply, &key, &parameters, at, json);
            q.reply(key, sealed).await
        }
        Err(e) => {
            let sealed = seal
                .key
                .seal(Sealed::Error, &key, &parameters, at, e.to_string());
            q.reply_err(sealed).await
        }
    };
    if let Err(error) = sent {
        ServiceEvent::ReplyFailed { error: &error }.emit(metrics);
    }
}

/// Selector parameters (`since=1h;kind=state`, `&` also accepted).
fn selector_parameters(text: &str) -> HashMap<String, String> {
    text.split([';', '&'])
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .collect()
}
