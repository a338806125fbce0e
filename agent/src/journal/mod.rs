//! The SQLite journal: alarm events, machine-state history and operator
//! commands, for the history service and the reports.
//!
//! One writer thread owns the write connection and commits in batches (one
//! transaction for whatever has queued up), in WAL mode with
//! `synchronous=FULL`, so a committed row survives a killed process and a
//! power cut. [`Journal::commit`] returns once its rows are on disk;
//! [`Journal::write`] and [`Journal::queue_staged`] do not wait. After each
//! commit the writer also publishes the number of rows committed so far
//! ([`Journal::committed`]). Every row handed to the journal and not yet
//! committed — staged, queued, or in the writer's batch — is counted, and
//! the count reported ([`CommitObserver::pending`]) as it changes.
//!
//! [`crate::sinks::journal::JournalSink`] is the cell loop's side: it turns each step into
//! rows, [`Journal::stage`]s them before the step goes on the bus and
//! queues them once the bus has it ([`Journal::queue_staged`]), so the
//! writer thread is not woken on the alarm's path. A [`Barrier`] waits for
//! staged rows to be queued, then for everything queued to be committed:
//! whoever sees an alarm on the bus finds it in `history`.
//! Readers (history queries, reports) open their own connections; WAL lets
//! them read while the writer writes. Rows older than the retention are
//! deleted at start and every hour.
//!
//! What the writer says and reports goes through its events
//! (`events.rs`: each one's log line and its report to the
//! [`CommitObserver`], `observer.rs`, together).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Weak};
use std::time::{Duration, Instant};

pub(crate) mod backup;
pub(crate) mod chain;
pub(crate) mod config;
mod events;
mod history;
mod observer;
mod reports;
mod saved;
mod schema;

use events::JournalEvent;
pub use history::{
    history, recording, HistoryError, HistoryPage, HistoryQuery, HistoryRow, DEFAULT_ROWS,
    HISTORY_SCHEMA, MAX_FIELD_BYTES, MAX_REPLY_BYTES, MAX_ROWS,
};
pub use observer::CommitObserver;
pub use reports::{alarm_events, report_input, AlarmEvents, ReportInput};
pub use saved::{saved, Saved, SavedOutcome, SavedState};
pub use schema::{open, open_read, JournalError, NotCommitted};

use schema::{last_seq, purge, TABLES};

use crate::journal::config::Keep;

use rusqlite::{params, Connection};
use tokio::sync::{mpsc, oneshot, watch};

/// One row to write.
#[derive(Debug, Clone, PartialEq)]
pub enum Entry {
    /// An alarm transition, with its JSON payload as published.
    Alarm {
        /// When, ms since the epoch.
        at: u64,
        /// Alarm id.
        alarm: String,
        /// `switching`, `communication`, ...
        kind: String,
        /// Severity name.
        severity: String,
        /// `raised`, `cleared`, `acknowledged`, `updated`.
        transition: String,
        /// The payload as published on Zenoh.
        payload: String,
        /// The alarm is not back to normal (active, latched or not yet
        /// acknowledged): it is kept in `alarm_current` to be restored at
        /// the next start.
        open: bool,
    },
    /// A machine-state history row (paper 000, Fig. 13).
    State {
        /// When.
        at: u64,
        /// `normal`, `fault`, `recovery`, `offline`.
        kind: String,
        /// `running`, `idle`, `fault`, `offline`.
        state: String,
        /// Fault type (`ESE`), for faults.
        fault_type: Option<String>,
        /// Faulty element (`X0.06`), when known.
        element: Option<String>,
    },
    /// Parts done: a rising edge of the part-done tag (one), or a
    /// counter's increment.
    Part {
        /// When.
        at: u64,
        /// How many.
        count: u64,
    },
    /// Parts rejected: a rising edge of the reject signal (one), or the
    /// reject counter's increment (`[oee]`).
    Reject {
        /// When.
        at: u64,
        /// How many.
        count: u64,
    },
    /// The work order changed: item (mould) code, target quantity.
    Order {
        /// When.
        at: u64,
        /// The item code.
        item: Option<String>,
        /// The target quantity.
        target: Option<u64>,
    },
    /// A machine mode began (`entered`) or ended (`[[state.modes]]`).
    Mode {
        /// When.
        at: u64,
        /// The mode's id.
        mode: String,
        /// Whether it began.
        entered: bool,
    },
    /// An alarm's flight recording: the signals its check reads around
    /// its raise ([`cellwatch_models::engine::Recording`]).
    Recording {
        /// When its alarm was raised, ms since the epoch.
        at: u64,
        /// The alarm.
        alarm: String,
        /// The recording as published on Zenoh (JSON).
        payload: String,
    },
    /// An operator command, accepted or refused.
    Command {
        /// When.
        at: u64,
        /// Who signed it (as claimed, for refused ones).
        operator: String,
        /// `ack` or `reset`.
        action: String,
        /// The alarm it names.
        alarm: String,
        /// The request's nonce.
        nonce: String,
        /// Whether it was carried out.
        accepted: bool,
        /// Whether its signature was verified (its nonce is then used up,
        /// across restarts).
        verified: bool,
        /// Why it was refused, or what it did.
        detail: String,
        /// Which row of its command (`command`, or `request`, `check`,
        /// `write`, `result` of a write, force or stop; `refused` before a
        /// signature was verified).
        stage: String,
        /// Where the query came from, as it said (refused rows), or empty.
        source: String,
        /// How many refusals the row stands for; 1 for other rows.
        count: u64,
        /// SHA-256 of the command as signed (hex), in the rows of a
        /// command; not chained (rows before it have none).
        digest: Option<String>,
    },
}

/// Rows for the writer, and who waits for their commit.
struct Batch {
    entries: Vec<Entry>,
    /// Told the outcome once the rows are committed (or not).
    done: Option<oneshot::Sender<Result<(), NotCommitted>>>,
}

/// The handle the engine writes through.
#[derive(Clone)]
pub struct Journal {
    /// Batches for the writer thread; bounded so that a stuck disk slows
    /// the engine instead of eating memory.
    tx: mpsc::Sender<Batch>,
    /// Rows committed so far (including those found at start).
    committed: watch::Receiver<u64>,
    /// `Some(why)` while the journal cannot write.
    health: watch::Receiver<Option<String>>,
    /// The end of the command rows' hash chain, as committed.
    chain: watch::Receiver<chain::Link>,
    path: PathBuf,
    /// Steps whose rows are promised but not yet queued.
    staging: Arc<Staging>,
    /// Rows handed over and not yet committed.
    uncommitted: Arc<Uncommitted>,
    /// The writer thread, joined by [`Journal::close`].
    thread: Arc<std::sync::Mutex<Option<std::thread::JoinHandle<()>>>>,
}

/// Steps staged ([`Journal::stage`]) and queued so far: a barrier taken
/// after a step was staged waits for its rows to be in the writer's
/// channel before it goes there itself.
struct Staging {
    /// Steps staged so far.
    staged: AtomicU64,
    /// The number of staged steps whose rows are queued.
    queued: watch::Sender<u64>,
}

/// Rows handed to the journal and not yet committed (staged, queued, or
/// in the writer's batch), reported at every change; the lock keeps the
/// reports in the order of the changes, so the last one is the count.
struct Uncommitted {
    rows: std::sync::Mutex<u64>,
    observer: Arc<dyn CommitObserver>,
}

impl Uncommitted {
    fn add(&self, n: usize) {
        self.change(|rows| rows.saturating_add(n as u64), n);
    }

    fn remove(&self, n: usize) {
        self.change(|rows| rows.saturating_sub(n as u64), n);
    }

    fn change(&self, f: impl FnOnce(u64) -> u64, n: usize) {
        if n == 0 {
            return;
        }
        let mut rows = self.rows.lock().unwrap_or_else(|e| e.into_inner());
        *rows = f(*rows);
        JournalEvent::Pending {
            rows: *rows as usize,
        }
        .emit(&*self.observer);
    }
}

/// Waits until every row queued before the call is committed, or known
/// unwritable (the journal is failing and keeps them for its retries):
/// answers that follow it (history, snapshots, command outcomes) never
/// show what a crash would forget.
#[derive(Clone)]
pub struct Barrier {
    tx: mpsc::WeakSender<Batch>,
    staging: Weak<Staging>,
}

impl Barrier {
    /// Returns once the rows staged or queued so far are committed (at
    /// once when the journal is closed).
    pub async fn settled(&self) {
        if let Some(staging) = self.staging.upgrade() {
            let staged = staging.staged.load(Ordering::SeqCst);
            let mut queued = staging.queued.subscribe();
            drop(staging);
            // Ends early only when the journal is gone (the sender with it).
            let _ = queued.wait_for(|&q| q >= staged).await;
        }
        let Some(tx) = self.tx.upgrade() else {
            return;
        };
        let (done, committed) = oneshot::channel();
        let sent = tx
            .send(Batch {
                entries: Vec::new(),
                done: Some(done),
            })
            .await;
        drop(tx);
        if sent.is_ok() {
            let _ = committed.await;
        }
    }
}

impl Journal {
    /// Opens the journal at `path`, deletes what its tables no longer keep
    /// (`keep`: again every hour), and starts the writer thread.
    ///
    /// # Errors
    /// The database cannot be opened.
    pub fn start(
        path: &Path,
        keep: &[Keep],
        observer: impl CommitObserver,
    ) -> Result<Journal, JournalError> {
        let conn = open(path)?;
        let existing: u64 = TABLES
            .iter()
            .map(|t| {
                conn.query_row(&format!("SELECT count(*) FROM {t}"), [], |r| {
                    r.get::<_, i64>(0)
                })
                .unwrap_or(0) as u64
            })
            .sum();
        let (tx, rx) = mpsc::channel(1024);
        let (committed_tx, committed) = watch::channel(existing);
        let (health_tx, health) = watch::channel(None);
        let (chain_tx, chain) = watch::channel(chain::Link::last(&conn).unwrap_or_default());
        let p = path.to_path_buf();
        let keep = keep.to_vec();
        let observer: Arc<dyn CommitObserver> = Arc::new(observer);
        let uncommitted = Arc::new(Uncommitted {
            rows: std::sync::Mutex::new(0),
            observer: observer.clone(),
        });
        let counted = uncommitted.clone();
        let thread = std::thread::Builder::new()
            .name("journal-writer".into())
            .spawn(move || {
                let reports = Reports {
                    committed: committed_tx,
                    health: health_tx,
                    chain: chain_tx,
                    observer,
                    uncommitted: counted,
                };
                writer(conn, rx, reports, existing, keep, p)
            })
            .map_err(|source| JournalError::Thread {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(Journal {
            tx,
            committed,
            health,
            chain,
            path: path.to_path_buf(),
            staging: Arc::new(Staging {
                staged: AtomicU64::new(0),
                queued: watch::Sender::new(0),
            }),
            uncommitted,
            thread: Arc::new(std::sync::Mutex::new(Some(thread))),
        })
    }

    /// Promises `rows` rows to come with [`Journal::queue_staged`]: a
    /// barrier taken from now on waits for them, and they count as not
    /// yet committed. Returns the step's number, to hand to
    /// `queue_staged`. Wakes no one: the cell loop stages its rows before
    /// the step goes on the bus and queues them after.
    pub fn stage(&self, rows: usize) -> u64 {
        self.uncommitted.add(rows);
        self.staging.staged.fetch_add(1, Ordering::SeqCst) + 1
    }

    /// Queues the rows of the steps staged up to `step` (see
    /// [`Journal::stage`]), in order, without waiting for their commit.
    ///
    /// # Errors
    /// The writer has stopped (the staged steps count as queued: no
    /// barrier waits for them).
    pub async fn queue_staged(&self, entries: Vec<Entry>, step: u64) -> Result<(), JournalError> {
        let sent = self.send(entries, None, true).await;
        self.staging.queued.send_if_modified(|q| {
            let later = step > *q;
            *q = (*q).max(step);
            later
        });
        sent
    }

    /// Queues an entry without waiting for its commit. Waits if the writer
    /// is far behind.
    ///
    /// # Errors
    /// The writer has stopped.
    pub async fn write(&self, entry: Entry) -> Result<(), JournalError> {
        self.send(vec![entry], None, false).await
    }

    /// Writes `entries` and returns once they are committed.
    ///
    /// # Errors
    /// The commit failed or the writer has stopped.
    pub async fn commit(&self, entries: Vec<Entry>) -> Result<(), JournalError> {
        let (done, committed) = oneshot::channel();
        self.send(entries, Some(done), false).await?;
        match committed.await {
            Ok(Ok(())) => Ok(()),
            Ok(Err(source)) => Err(JournalError::Commit {
                path: self.path.clone(),
                source,
            }),
            Err(_) => Err(self.stopped()),
        }
    }

    /// Hands `entries` to the writer; `staged`: they are counted already
    /// ([`Journal::stage`]).
    async fn send(
        &self,
        entries: Vec<Entry>,
        done: Option<oneshot::Sender<Result<(), NotCommitted>>>,
        staged: bool,
    ) -> Result<(), JournalError> {
        let rows = entries.len();
        if !staged {
            self.uncommitted.add(rows);
        }
        let sent = self.tx.send(Batch { entries, done }).await;
        if sent.is_err() {
            // Never to be committed: no longer waiting.
            self.uncommitted.remove(rows);
        }
        sent.map_err(|_| self.stopped())
    }

    fn stopped(&self) -> JournalError {
        JournalError::Stopped {
            path: self.path.clone(),
        }
    }

    /// Closes the journal: every queued row is committed, then the writer
    /// thread ends. Other clones of this handle keep it open until they
    /// are closed or dropped too.
    pub async fn close(self) {
        let thread = self.thread.lock().ok().and_then(|mut t| t.take());
        drop(self.tx);
        if let Some(thread) = thread {
            let _ = tokio::task::spawn_blocking(move || thread.join()).await;
        }
    }

    /// A handle that waits for the rows queued so far to be committed; it
    /// does not keep the journal open.
    pub fn barrier(&self) -> Barrier {
        Barrier {
            tx: self.tx.downgrade(),
            staging: Arc::downgrade(&self.staging),
        }
    }

    /// Rows committed so far; changes after every commit.
    pub fn committed(&self) -> watch::Receiver<u64> {
        self.committed.clone()
    }

    /// `Some(why)` while the journal cannot write (its rows wait in a
    /// bounded queue and are retried), `None` when it writes.
    pub fn health(&self) -> watch::Receiver<Option<String>> {
        self.health.clone()
    }

    /// The end of the command rows' hash chain, as committed; changes
    /// after every commit that chains a row.
    pub fn command_chain(&self) -> watch::Receiver<chain::Link> {
        self.chain.clone()
    }

    /// The database file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Rows kept in memory while the journal cannot write; beyond that the
/// oldest are dropped (and counted), so memory stays bounded.
pub const MAX_PENDING_ROWS: usize = 100_000;
/// How often a failing journal is retried when nothing new arrives.
pub const RETRY: Duration = Duration::from_secs(1);
/// How long a closed journal keeps retrying rows it could not write yet.
pub const CLOSE_GRACE: Duration = Duration::from_secs(5);

/// What the writer thread reports on.
struct Reports<O> {
    /// Rows committed so far.
    committed: watch::Sender<u64>,
    /// `Some(why)` while nothing can be written.
    health: watch::Sender<Option<String>>,
    /// The end of the command rows' hash chain, once committed.
    chain: watch::Sender<chain::Link>,
    observer: O,
    /// Rows not yet committed, less those it commits or drops.
    uncommitted: Arc<Uncommitted>,
}

fn writer(
    mut conn: Connection,
    mut rx: mpsc::Receiver<Batch>,
    reports: Reports<Arc<dyn CommitObserver>>,
    mut total: u64,
    keep: Vec<Keep>,
    path: PathBuf,
) {
    let Reports {
        committed,
        health,
        chain: head,
        observer,
        uncommitted,
    } = reports;
    let mut last_purge = Instant::now();
    purge(&conn, &keep, &path);
    let mut seq = last_seq(&conn);
    let mut chain = chain::Link::last(&conn).unwrap_or_else(|error| {
        let path = &path;
        JournalEvent::ChainUnreadable {
            path,
            error: &error,
        }
        .emit(&*observer);
        chain::Link::default()
    });
    let mut last_attempt = Instant::now();
    // Rows not yet committed, oldest first: a batch, or everything since
    // the journal stopped being writable.
    let mut pending: std::collections::VecDeque<Entry> = std::collections::VecDeque::new();
    let mut waiting = Vec::new();
    // When the journal was closed with rows still to write.
    let mut closing: Option<Instant> = None;
    loop {
        // Failing: retry at least every RETRY; otherwise wait for rows.
        let first = if pending.is_empty() {
            match rx.blocking_recv() {
                Some(b) => Some(b),
                None => break,
            }
        } else {
            // Closed or not, the next attempt waits for its time.
            let deadline = Instant::now() + RETRY;
            loop {
                match rx.try_recv() {
                    Ok(b) => break Some(b),
                    Err(_) if Instant::now() >= deadline => break None,
                    Err(_) => std::thread::sleep(Duration::from_millis(20)),
                }
            }
        };
        let mut take = |b: Batch, pending: &mut std::collections::VecDeque<Entry>| {
            pending.extend(b.entries);
            waiting.extend(b.done);
        };
        let closed = first.is_none() && rx.is_closed() && rx.is_empty();
        if let Some(b) = first {
            take(b, &mut pending);
        }
        while pending.len() < 1024 {
            match rx.try_recv() {
                Ok(b) => take(b, &mut pending),
                Err(_) => break,
            }
        }
        if pending.len() > MAX_PENDING_ROWS {
            let lost = pending.len() - MAX_PENDING_ROWS;
            pending.drain(..lost);
            let (path, rows) = (&path, lost);
            JournalEvent::Dropped { path, rows }.emit(&*observer);
            uncommitted.remove(lost);
        }
        let failing = health.borrow().is_some();
        if failing && last_attempt.elapsed() < RETRY {
            // Retried at its pace, not at every step's.
            let why = health.borrow().clone().unwrap_or_default();
            for done in waiting.drain(..) {
                let _ = done.send(Err(NotCommitted::Queued(why.clone())));
            }
        } else if !pending.is_empty() {
            last_attempt = Instant::now();
            let started = Instant::now();
            let rows = pending.make_contiguous();
            let outcome = match write_batch(&mut conn, rows, &mut seq, &mut chain) {
                Ok(()) => {
                    total += rows.len() as u64;
                    JournalEvent::Committed {
                        path: &path,
                        rows: rows.len(),
                        took: started.elapsed(),
                        again: health.borrow().is_some(),
                    }
                    .emit(&*observer);
                    // The count before the commit and the health are
                    // told: whoever sees either sees none of these rows
                    // pending.
                    uncommitted.remove(rows.len());
                    head.send_if_modified(|h| {
                        let moved = *h != chain;
                        if moved {
                            *h = chain.clone();
                        }
                        moved
                    });
                    let _ = committed.send(total);
                    pending.clear();
                    if health.borrow().is_some() {
                        let _ = health.send(None);
                    }
                    Ok(())
                }
                Err(e) => {
                    let why = e.to_string();
                    // The metrics before the health: whoever sees the
                    // journal alarm sees the failure (and the rows kept,
                    // counted when they came).
                    let new = health.borrow().as_deref() != Some(why.as_str());
                    JournalEvent::Failed {
                        path: &path,
                        why: &why,
                        rows: pending.len(),
                        new,
                    }
                    .emit(&*observer);
                    if new {
                        let _ = health.send(Some(why.clone()));
                    }
                    Err(NotCommitted::Failed(why))
                }
            };
            for done in waiting.drain(..) {
                let _ = done.send(outcome.clone());
            }
        } else {
            // Nothing pending: every row queued before these is committed.
            for done in waiting.drain(..) {
                let _ = done.send(Ok(()));
            }
        }
        if closed {
            // Closing: rows it could not write yet are retried for a
            // while (a journal busy for a moment when the agent is told
            // to stop).
            let since = *closing.get_or_insert_with(Instant::now);
            if pending.is_empty() || since.elapsed() >= CLOSE_GRACE {
                break;
            }
        }
        if last_purge.elapsed() > Duration::from_secs(3600) {
            purge(&conn, &keep, &path);
            last_purge = Instant::now();
        }
    }
    if !pending.is_empty() {
        let (path, rows) = (&path, pending.len());
        JournalEvent::ClosedUnwritten { path, rows }.emit(&*observer);
    }
}

/// Writes `batch` in one transaction, numbering rows from `*seq + 1` and
/// chaining command rows after `*chain`; `*seq` and `*chain` move only if
/// the transaction commits.
fn write_batch(
    conn: &mut Connection,
    batch: &[Entry],
    seq: &mut i64,
    chain: &mut chain::Link,
) -> rusqlite::Result<()> {
    let tx = conn.transaction()?;
    let mut next = *seq;
    let mut link = chain.clone();
    for e in batch {
        next += 1;
        match e {
            Entry::Alarm {
                at,
                alarm,
                kind,
                severity,
                transition,
                payload,
                open,
            } => {
                tx.prepare_cached(
                    "INSERT INTO alarm_events (seq, at_ms, alarm, kind, severity, transition, payload) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                )?
                .execute(params![next, *at as i64, alarm, kind, severity, transition, payload])?;
                if *open {
                    tx.prepare_cached(
                        "INSERT OR REPLACE INTO alarm_current (alarm, at_ms, payload) VALUES (?1, ?2, ?3)",
                    )?
                    .execute(params![alarm, *at as i64, payload])?;
                } else {
                    tx.prepare_cached("DELETE FROM alarm_current WHERE alarm = ?1")?
                        .execute(params![alarm])?;
                }
            }
            Entry::State {
                at,
                kind,
                state,
                fault_type,
                element,
            } => {
                tx.prepare_cached(
                    "INSERT INTO state_history (seq, at_ms, kind, state, fault_type, element) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                )?
                .execute(params![next, *at as i64, kind, state, fault_type, element])?;
            }
            Entry::Part { at, count } => {
                tx.prepare_cached(
                    "INSERT INTO production (seq, at_ms, parts) VALUES (?1, ?2, ?3)",
                )?
                .execute(params![
                    next,
                    *at as i64,
                    i64::try_from(*count).unwrap_or(i64::MAX)
                ])?;
            }
            Entry::Reject { at, count } => {
                tx.prepare_cached(
                    "INSERT INTO production (seq, at_ms, parts, rejects) VALUES (?1, ?2, 0, ?3)",
                )?
                .execute(params![
                    next,
                    *at as i64,
                    i64::try_from(*count).unwrap_or(i64::MAX)
                ])?;
            }
            Entry::Recording { at, alarm, payload } => {
                tx.prepare_cached(
                    "INSERT INTO recordings (seq, at_ms, alarm, payload) VALUES (?1, ?2, ?3, ?4)",
                )?
                .execute(params![next, *at as i64, alarm, payload])?;
            }
            Entry::Mode { at, mode, entered } => {
                tx.prepare_cached(
                    "INSERT INTO modes (seq, at_ms, mode, entered) VALUES (?1, ?2, ?3, ?4)",
                )?
                .execute(params![next, *at as i64, mode, entered])?;
            }
            Entry::Order { at, item, target } => {
                tx.prepare_cached(
                    "INSERT INTO orders (seq, at_ms, item, target) VALUES (?1, ?2, ?3, ?4)",
                )?
                .execute(params![
                    next,
                    *at as i64,
                    item,
                    target.map(|t| i64::try_from(t).unwrap_or(i64::MAX))
                ])?;
            }
            Entry::Command {
                at,
                operator,
                action,
                alarm,
                nonce,
                accepted,
                verified,
                detail,
                stage,
                source,
                count,
                digest,
            } => {
                let row = chain::ChainedRow {
                    seq: next,
                    at_ms: *at as i64,
                    operator,
                    action,
                    alarm,
                    nonce,
                    accepted: *accepted,
                    verified: *verified,
                    detail,
                    stage,
                    source,
                    count: i64::try_from(*count).unwrap_or(i64::MAX),
                };
                link = chain::insert(&tx, &row, digest.as_deref(), &link)?;
            }
        }
    }
    tx.commit()?;
    *seq = next;
    *chain = link;
    Ok(())
}

#[cfg(test)]
mod tests;
