//! The agent's query services on Zenoh:
//! - `<prefix>/history?since=1h;until=...;kind=state|alarm|command;limit=N`:
//!   journal rows as a JSON array, oldest first, read from the journal file
//!   on a blocking thread, never holding up the cell loop;
//! - `<prefix>/snapshot`: tag values with quality, active alarms, and the
//!   values at the last fault ([`crate::payload::SnapshotPayload`]), asked
//!   of the cell loop;
//! - `<prefix>/command`: a signed [`crate::operator::Command`], carried out
//!   (or refused) by the cell loop; the reply is a
//!   [`crate::cell::CommandOutcome`].
//!
//! Queries are answered concurrently, at most [`MAX_CONCURRENT`] at a time;
//! more are told the agent is busy. A command payload larger than
//! [`MAX_COMMAND_BYTES`] is refused before it is read.

use std::collections::HashMap;
use std::future::Future;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use tokio::sync::{mpsc, oneshot, Semaphore};
use tokio::task::JoinSet;
use zenoh::query::Query;
use zenoh::Session;

use super::ZenohError;
use crate::cell::{CommandOutcome, Request};
use crate::clock::{now_ms, parse_time};
use crate::metrics::Metrics;
use crate::operator::Command;
use crate::sinks::journal::{self, HistoryQuery};

/// Queries answered at the same time; more are refused as busy.
pub const MAX_CONCURRENT: usize = 16;
/// The largest command payload read.
pub const MAX_COMMAND_BYTES: usize = 4096;

type Queryable = zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<Query>>;

/// The declared queryables and what answering needs.
pub struct Services {
    history: Queryable,
    snapshot: Queryable,
    command: Queryable,
    journal: PathBuf,
    /// Requests to the cell loop (snapshot, command), answered on a
    /// one-shot channel each.
    requests: mpsc::Sender<Request>,
    /// Bounds the queries being answered at once.
    permits: Arc<Semaphore>,
    metrics: Arc<Metrics>,
}

impl Services {
    /// Declares `history`, `snapshot` and `command` under `prefix`.
    ///
    /// # Errors
    /// Zenoh refuses a declaration.
    pub async fn declare(
        session: &Session,
        prefix: &str,
        journal: &Path,
        requests: mpsc::Sender<Request>,
        metrics: Arc<Metrics>,
    ) -> Result<Services, ZenohError> {
        let declare = |name: &'static str| {
            let key = format!("{prefix}/{name}");
            async move {
                session
                    .declare_queryable(key.clone())
                    .await
                    .map_err(|e| ZenohError::Declare {
                        key,
                        reason: e.to_string(),
                    })
            }
        };
        Ok(Services {
            history: declare("history").await?,
            snapshot: declare("snapshot").await?,
            command: declare("command").await?,
            journal: journal.to_path_buf(),
            requests,
            permits: Arc::new(Semaphore::new(MAX_CONCURRENT)),
            metrics,
        })
    }

    /// Answers queries until `shutdown` completes; then waits for the
    /// answers under way and undeclares the queryables.
    pub async fn run(self, shutdown: impl Future<Output = ()>) {
        tokio::pin!(shutdown);
        let mut answering = JoinSet::new();
        loop {
            let (kind, q) = tokio::select! {
                _ = &mut shutdown => break,
                Ok(q) = self.history.recv_async() => (Kind::History, q),
                Ok(q) = self.snapshot.recv_async() => (Kind::Snapshot, q),
                Ok(q) = self.command.recv_async() => (Kind::Command, q),
                Some(_) = answering.join_next(), if !answering.is_empty() => continue,
            };
            let Ok(permit) = self.permits.clone().try_acquire_owned() else {
                reply(&self.metrics, q, Err("the agent is busy: try again".into())).await;
                continue;
            };
            let (journal, requests, metrics) = (
                self.journal.clone(),
                self.requests.clone(),
                self.metrics.clone(),
            );
            answering.spawn(async move {
                let _permit = permit;
                let result = match kind {
                    Kind::History => history(&journal, q.parameters().as_str()).await,
                    Kind::Snapshot => snapshot(&requests).await,
                    Kind::Command => command(&requests, &q).await,
                };
                reply(&metrics, q, result).await;
            });
        }
        answering.shutdown().await;
    }
}

#[derive(Clone, Copy)]
enum Kind {
    History,
    Snapshot,
    Command,
}

async fn history(journal: &Path, parameters: &str) -> Result<String, String> {
    let query = history_query(parameters, now_ms())?;
    let path = journal.to_path_buf();
    let rows = tokio::task::spawn_blocking(move || {
        let conn = journal::open_read(&path)?;
        journal::history(&conn, &query)
    })
    .await
    .map_err(|e| format!("history query failed: {e}"))?
    .map_err(|e| e.to_string())?;
    Ok(serde_json::to_string(&rows).unwrap_or_default())
}

/// Parses a history selector's parameters at `now`.
///
/// # Errors
/// A time or limit that does not parse.
pub fn history_query(parameters: &str, now: u64) -> Result<HistoryQuery, String> {
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
        limit: params
            .get("limit")
            .map(|l| {
                l.parse()
                    .map_err(|_| format!("limit '{l}' is not a number"))
            })
            .transpose()?,
    })
}

async fn snapshot(requests: &mpsc::Sender<Request>) -> Result<String, String> {
    let (tx, rx) = oneshot::channel();
    requests
        .send(Request::Snapshot(tx))
        .await
        .map_err(|_| "the agent is stopping".to_string())?;
    let snap = rx.await.map_err(|_| "the agent is stopping".to_string())?;
    Ok(serde_json::to_string(&snap).unwrap_or_default())
}

async fn command(requests: &mpsc::Sender<Request>, q: &Query) -> Result<String, String> {
    let parsed = match q.payload() {
        None => Err("no payload".to_string()),
        Some(p) if p.len() > MAX_COMMAND_BYTES => Err(format!(
            "payload of {} bytes; a command is at most {MAX_COMMAND_BYTES}",
            p.len()
        )),
        Some(p) => match p.try_to_string() {
            Err(_) => Err("payload is not UTF-8".to_string()),
            Ok(text) => serde_json::from_str::<Command>(&text).map_err(|e| e.to_string()),
        },
    };
    let (tx, rx) = oneshot::channel();
    requests
        .send(Request::Command {
            command: parsed,
            reply: tx,
        })
        .await
        .map_err(|_| "the agent is stopping".to_string())?;
    let outcome: CommandOutcome = rx.await.map_err(|_| "the agent is stopping".to_string())?;
    Ok(serde_json::to_string(&outcome).unwrap_or_default())
}

/// Answers a query with JSON, or with an error text.
async fn reply(metrics: &Metrics, q: Query, result: Result<String, String>) {
    let key = q.key_expr().clone();
    let sent = match result {
        Ok(json) => q.reply(key, json).await,
        Err(e) => q.reply_err(e).await,
    };
    if let Err(e) = sent {
        tracing::warn!(error = %e, "reply failed");
        metrics.zenoh_publish_errors.inc();
    }
}

/// Selector parameters (`since=1h;kind=state`, `&` also accepted).
fn selector_parameters(text: &str) -> HashMap<String, String> {
    text.split([';', '&'])
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .collect()
}
