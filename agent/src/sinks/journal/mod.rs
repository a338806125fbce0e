//! The SQLite journal: alarm events, machine-state history and operator
//! commands, for the history service and the reports.
//!
//! One writer thread owns the write connection and commits in batches (one
//! transaction for whatever has queued up), in WAL mode with
//! `synchronous=FULL`, so a committed row survives a killed process and a
//! power cut. [`Journal::commit`] returns once its rows are on disk: the
//! cell loop publishes an alarm only after that, so whoever sees an alarm on
//! the bus finds it in `history`. After each commit the writer also
//! publishes the number of rows committed so far ([`Journal::committed`]).
//!
//! [`sink::JournalSink`] is the cell loop's side: it turns each step into
//! rows.
//! Readers (history queries, reports) open their own connections; WAL lets
//! them read while the writer writes. Rows older than the retention are
//! deleted at start and every hour.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub mod sink;

use rusqlite::{params, Connection, OpenFlags};
use serde::Serialize;
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
    /// One part done (a rising edge of the part-done tag).
    Part {
        /// When.
        at: u64,
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
        /// Why it was refused, or what it did.
        detail: String,
    },
}

/// A history row as served to queries.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct HistoryRow {
    /// Row number in the journal.
    pub seq: i64,
    /// `alarm`, `state` or `command`.
    pub table: &'static str,
    /// When, ms since the epoch.
    pub at: u64,
    /// The row's fields.
    pub fields: serde_json::Map<String, serde_json::Value>,
}

/// Why the journal failed.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// SQLite said no.
    #[error("journal {path}: {source}")]
    Sqlite {
        /// The file.
        path: PathBuf,
        /// The error.
        source: rusqlite::Error,
    },
    /// The writer thread could not be started.
    #[error("journal {path}: cannot start the writer thread: {source}")]
    Thread {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A batch could not be committed; its rows are lost.
    #[error("journal {path}: commit failed: {message}")]
    Commit {
        /// The file.
        path: PathBuf,
        /// SQLite's message.
        message: String,
    },
    /// The writer thread has stopped.
    #[error("journal {path}: the writer has stopped")]
    Stopped {
        /// The file.
        path: PathBuf,
    },
}

/// Why a history query failed.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    /// The query asks for a kind of row there is none of.
    #[error("unknown kind '{0}': use alarm, state or command")]
    UnknownKind(String),
    /// The journal cannot be read.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// SQLite failed while reading.
    #[error("journal: {0}")]
    Sqlite(#[from] rusqlite::Error),
}

/// Rows for the writer, and who waits for their commit.
struct Batch {
    entries: Vec<Entry>,
    /// Told the outcome once the rows are committed (or not).
    done: Option<oneshot::Sender<Result<(), String>>>,
}

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS alarm_events (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms INTEGER NOT NULL,
    alarm TEXT NOT NULL,
    kind TEXT NOT NULL,
    severity TEXT NOT NULL,
    transition TEXT NOT NULL,
    payload TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS alarm_events_at ON alarm_events (at_ms);
CREATE TABLE IF NOT EXISTS state_history (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms INTEGER NOT NULL,
    kind TEXT NOT NULL,
    state TEXT NOT NULL,
    fault_type TEXT,
    element TEXT
);
CREATE INDEX IF NOT EXISTS state_history_at ON state_history (at_ms);
CREATE TABLE IF NOT EXISTS commands (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms INTEGER NOT NULL,
    operator TEXT NOT NULL,
    action TEXT NOT NULL,
    alarm TEXT NOT NULL,
    nonce TEXT NOT NULL,
    accepted INTEGER NOT NULL,
    detail TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS commands_at ON commands (at_ms);
CREATE TABLE IF NOT EXISTS production (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS production_at ON production (at_ms);
";

/// Opens (creating if needed) the journal for writing.
///
/// # Errors
/// The file cannot be opened or is not a cellwatch journal.
pub fn open(path: &Path) -> Result<Connection, JournalError> {
    let err = |source| JournalError::Sqlite {
        path: path.to_path_buf(),
        source,
    };
    let conn = Connection::open(path).map_err(err)?;
    conn.pragma_update(None, "journal_mode", "WAL")
        .map_err(err)?;
    conn.pragma_update(None, "synchronous", "FULL")
        .map_err(err)?;
    conn.busy_timeout(Duration::from_secs(5)).map_err(err)?;
    conn.execute_batch(SCHEMA).map_err(err)?;
    Ok(conn)
}

/// Opens the journal read-only, for queries and reports.
///
/// # Errors
/// The file does not exist or cannot be read.
pub fn open_read(path: &Path) -> Result<Connection, JournalError> {
    let err = |source| JournalError::Sqlite {
        path: path.to_path_buf(),
        source,
    };
    let conn = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(err)?;
    conn.busy_timeout(Duration::from_secs(5)).map_err(err)?;
    Ok(conn)
}

/// The handle the engine writes through.
#[derive(Clone)]
pub struct Journal {
    /// Batches for the writer thread; bounded so that a stuck disk slows
    /// the engine instead of eating memory.
    tx: mpsc::Sender<Batch>,
    /// Rows committed so far (including those found at start).
    committed: watch::Receiver<u64>,
    path: PathBuf,
    /// The writer thread, joined by [`Journal::close`].
    thread: std::sync::Arc<std::sync::Mutex<Option<std::thread::JoinHandle<()>>>>,
}

/// What the writer thread reports after each batch.
pub trait CommitObserver: Send + 'static {
    /// A batch of `rows` rows was committed in `took`.
    fn committed(&self, rows: usize, took: Duration);
    /// A batch failed; its rows are lost.
    fn failed(&self, error: &str);
}

impl Journal {
    /// Opens the journal at `path`, deletes rows older than `retention`, and
    /// starts the writer thread.
    ///
    /// # Errors
    /// The database cannot be opened.
    pub fn start(
        path: &Path,
        retention: Duration,
        observer: impl CommitObserver,
    ) -> Result<Journal, JournalError> {
        let conn = open(path)?;
        let existing: u64 = ["alarm_events", "state_history", "commands", "production"]
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
        let p = path.to_path_buf();
        let thread = std::thread::Builder::new()
            .name("journal-writer".into())
            .spawn(move || writer(conn, rx, committed_tx, existing, retention, observer, p))
            .map_err(|source| JournalError::Thread {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(Journal {
            tx,
            committed,
            path: path.to_path_buf(),
            thread: std::sync::Arc::new(std::sync::Mutex::new(Some(thread))),
        })
    }

    /// Queues an entry without waiting for its commit. Waits if the writer
    /// is far behind.
    ///
    /// # Errors
    /// The writer has stopped.
    pub async fn write(&self, entry: Entry) -> Result<(), JournalError> {
        self.send(vec![entry], None).await
    }

    /// Writes `entries` and returns once they are committed.
    ///
    /// # Errors
    /// The commit failed or the writer has stopped.
    pub async fn commit(&self, entries: Vec<Entry>) -> Result<(), JournalError> {
        let (done, committed) = oneshot::channel();
        self.send(entries, Some(done)).await?;
        match committed.await {
            Ok(Ok(())) => Ok(()),
            Ok(Err(message)) => Err(JournalError::Commit {
                path: self.path.clone(),
                message,
            }),
            Err(_) => Err(self.stopped()),
        }
    }

    async fn send(
        &self,
        entries: Vec<Entry>,
        done: Option<oneshot::Sender<Result<(), String>>>,
    ) -> Result<(), JournalError> {
        self.tx
            .send(Batch { entries, done })
            .await
            .map_err(|_| self.stopped())
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

    /// Rows committed so far; changes after every commit.
    pub fn committed(&self) -> watch::Receiver<u64> {
        self.committed.clone()
    }

    /// The database file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

fn writer(
    mut conn: Connection,
    mut rx: mpsc::Receiver<Batch>,
    committed: watch::Sender<u64>,
    mut total: u64,
    retention: Duration,
    observer: impl CommitObserver,
    path: PathBuf,
) {
    let mut last_purge = Instant::now();
    purge(&conn, retention, &path);
    let mut batch = Vec::with_capacity(256);
    let mut waiting = Vec::new();
    while let Some(first) = rx.blocking_recv() {
        let mut take = |b: Batch, batch: &mut Vec<Entry>| {
            batch.extend(b.entries);
            waiting.extend(b.done);
        };
        take(first, &mut batch);
        while batch.len() < 1024 {
            match rx.try_recv() {
                Ok(b) => take(b, &mut batch),
                Err(_) => break,
            }
        }
        let started = Instant::now();
        let outcome = match write_batch(&mut conn, &batch) {
            Ok(()) => {
                total += batch.len() as u64;
                observer.committed(batch.len(), started.elapsed());
                let _ = committed.send(total);
                Ok(())
            }
            Err(e) => {
                tracing::error!(path = %path.display(), error = %e, rows = batch.len(), "journal write failed");
                observer.failed(&e.to_string());
                Err(e.to_string())
            }
        };
        for done in waiting.drain(..) {
            let _ = done.send(outcome.clone());
        }
        batch.clear();
        if last_purge.elapsed() > Duration::from_secs(3600) {
            purge(&conn, retention, &path);
            last_purge = Instant::now();
        }
    }
}

fn write_batch(conn: &mut Connection, batch: &[Entry]) -> rusqlite::Result<()> {
    let tx = conn.transaction()?;
    for e in batch {
        match e {
            Entry::Alarm {
                at,
                alarm,
                kind,
                severity,
                transition,
                payload,
            } => {
                tx.prepare_cached(
                    "INSERT INTO alarm_events (at_ms, alarm, kind, severity, transition, payload) VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                )?
                .execute(params![*at as i64, alarm, kind, severity, transition, payload])?;
            }
            Entry::State {
                at,
                kind,
                state,
                fault_type,
                element,
            } => {
                tx.prepare_cached(
                    "INSERT INTO state_history (at_ms, kind, state, fault_type, element) VALUES (?1, ?2, ?3, ?4, ?5)",
                )?
                .execute(params![*at as i64, kind, state, fault_type, element])?;
            }
            Entry::Part { at } => {
                tx.prepare_cached("INSERT INTO production (at_ms) VALUES (?1)")?
                    .execute(params![*at as i64])?;
            }
            Entry::Command {
                at,
                operator,
                action,
                alarm,
                nonce,
                accepted,
                detail,
            } => {
                tx.prepare_cached(
                    "INSERT INTO commands (at_ms, operator, action, alarm, nonce, accepted, detail) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                )?
                .execute(params![*at as i64, operator, action, alarm, nonce, *accepted as i64, detail])?;
            }
        }
    }
    tx.commit()
}

fn purge(conn: &Connection, retention: Duration, path: &Path) {
    let cutoff = crate::clock::now_ms().saturating_sub(retention.as_millis() as u64) as i64;
    for table in ["alarm_events", "state_history", "commands", "production"] {
        if let Err(e) = conn.execute(&format!("DELETE FROM {table} WHERE at_ms < ?1"), [cutoff]) {
            tracing::warn!(path = %path.display(), error = %e, "journal retention purge failed");
        }
    }
}

/// What a history query asks for.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct HistoryQuery {
    /// From this time (ms), inclusive.
    pub since: Option<u64>,
    /// Until this time (ms), exclusive.
    pub until: Option<u64>,
    /// Only `alarm`, `state` or `command` rows.
    pub kind: Option<String>,
    /// At most this many rows (newest kept), default 1000.
    pub limit: Option<usize>,
}

/// Runs a history query; rows oldest first.
///
/// # Errors
/// An unknown `kind`, or SQLite failing.
pub fn history(conn: &Connection, q: &HistoryQuery) -> Result<Vec<HistoryRow>, HistoryError> {
    let tables: &[&str] = match q.kind.as_deref() {
        None => &["alarm", "state", "command"],
        Some("alarm") => &["alarm"],
        Some("state") => &["state"],
        Some("command") => &["command"],
        Some(other) => return Err(HistoryError::UnknownKind(other.to_string())),
    };
    let since = q.since.unwrap_or(0) as i64;
    let until = q.until.map_or(i64::MAX, |u| u as i64);
    let limit = q.limit.unwrap_or(1000).min(100_000);
    let mut rows = Vec::new();
    for &t in tables {
        let (sql, cols): (&str, &[&str]) = match t {
            "alarm" => (
                "SELECT seq, at_ms, alarm, kind, severity, transition, payload FROM alarm_events WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms DESC, seq DESC LIMIT ?3",
                &["alarm", "kind", "severity", "transition", "payload"],
            ),
            "state" => (
                "SELECT seq, at_ms, kind, state, fault_type, element FROM state_history WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms DESC, seq DESC LIMIT ?3",
                &["kind", "state", "fault_type", "element"],
            ),
            _ => (
                "SELECT seq, at_ms, operator, action, alarm, nonce, accepted, detail FROM commands WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms DESC, seq DESC LIMIT ?3",
                &["operator", "action", "alarm", "nonce", "accepted", "detail"],
            ),
        };
        let mut stmt = conn.prepare_cached(sql)?;
        let table = match t {
            "alarm" => "alarm",
            "state" => "state",
            _ => "command",
        };
        let mapped = stmt.query_map(params![since, until, limit as i64], |r| {
            let mut fields = serde_json::Map::new();
            for (i, c) in cols.iter().enumerate() {
                let v: rusqlite::types::Value = r.get(i + 2)?;
                let json = match v {
                    rusqlite::types::Value::Null => serde_json::Value::Null,
                    rusqlite::types::Value::Integer(n) if *c == "accepted" => {
                        serde_json::Value::Bool(n != 0)
                    }
                    rusqlite::types::Value::Integer(n) => n.into(),
                    rusqlite::types::Value::Text(s) if *c == "payload" => {
                        serde_json::from_str(&s).unwrap_or(serde_json::Value::String(s))
                    }
                    rusqlite::types::Value::Text(s) => s.into(),
                    other => format!("{other:?}").into(),
                };
                fields.insert((*c).to_string(), json);
            }
            Ok(HistoryRow {
                seq: r.get(0)?,
                table,
                at: r.get::<_, i64>(1)? as u64,
                fields,
            })
        })?;
        for row in mapped {
            rows.push(row?);
        }
    }
    rows.sort_by_key(|r| (r.at, r.table, r.seq));
    if rows.len() > limit {
        rows.drain(..rows.len() - limit);
    }
    Ok(rows)
}

/// Machine-state rows and part times between `since` and `until` (ms), plus
/// the last state row before `since`, for reports.
///
/// # Errors
/// SQLite failing.
pub fn report_input(
    conn: &Connection,
    since: u64,
    until: u64,
) -> rusqlite::Result<(Vec<cellwatch_models::report::StateChange>, Vec<u64>)> {
    let mut changes = Vec::new();
    let row = |r: &rusqlite::Row<'_>| {
        Ok(cellwatch_models::report::StateChange {
            at: r.get::<_, i64>(0)? as u64,
            state: r.get(1)?,
            fault_type: r.get(2)?,
        })
    };
    let before = conn
        .query_row(
            "SELECT at_ms, state, fault_type FROM state_history WHERE at_ms < ?1 ORDER BY at_ms DESC, seq DESC LIMIT 1",
            [since as i64],
            row,
        )
        .ok();
    changes.extend(before);
    let mut stmt = conn.prepare("SELECT at_ms, state, fault_type FROM state_history WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms, seq")?;
    for c in stmt.query_map([since as i64, until as i64], row)? {
        changes.push(c?);
    }
    let mut stmt = conn
        .prepare("SELECT at_ms FROM production WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms")?;
    let parts = stmt
        .query_map([since as i64, until as i64], |r| {
            Ok(r.get::<_, i64>(0)? as u64)
        })?
        .collect::<Result<Vec<_>, _>>()?;
    Ok((changes, parts))
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Quiet;
    impl CommitObserver for Quiet {
        fn committed(&self, _: usize, _: Duration) {}
        fn failed(&self, _: &str) {}
    }

    #[tokio::test]
    async fn writes_commit_and_query_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("j.sqlite");
        let now = crate::clock::now_ms();
        let j = Journal::start(&path, Duration::from_secs(3600), Quiet).unwrap();
        j.write(Entry::State {
            at: now,
            kind: "fault".into(),
            state: "fault".into(),
            fault_type: Some("ESE".into()),
            element: Some("X0.06".into()),
        })
        .await
        .unwrap();
        j.write(Entry::Command {
            at: now + 1,
            operator: "kim".into(),
            action: "ack".into(),
            alarm: "ese".into(),
            nonce: "n1".into(),
            accepted: false,
            detail: "bad signature".into(),
        })
        .await
        .unwrap();
        let mut c = j.committed();
        c.wait_for(|n| *n >= 2).await.unwrap();
        let conn = open_read(&path).unwrap();
        let rows = history(&conn, &HistoryQuery::default()).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].fields["element"], "X0.06");
        assert_eq!(rows[1].fields["accepted"], false);
        let only = history(
            &conn,
            &HistoryQuery {
                kind: Some("command".into()),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(only.len(), 1);
        assert_eq!(
            history(
                &conn,
                &HistoryQuery {
                    kind: Some("x".into()),
                    ..Default::default()
                }
            )
            .unwrap_err()
            .to_string(),
            "unknown kind 'x': use alarm, state or command"
        );
        // Old rows go at the next start.
        drop(j);
        let conn = open(&path).unwrap();
        conn.execute("UPDATE state_history SET at_ms = 5", [])
            .unwrap();
        drop(conn);
        let j = Journal::start(&path, Duration::from_secs(3600), Quiet).unwrap();
        let conn = open_read(&path).unwrap();
        // The purge runs on the writer thread: wait for it through a write.
        j.write(Entry::Alarm {
            at: now,
            alarm: "ese".into(),
            kind: "switching".into(),
            severity: "critical".into(),
            transition: "raised".into(),
            payload: "{}".into(),
        })
        .await
        .unwrap();
        let mut c = j.committed();
        c.wait_for(|n| *n >= 3).await.unwrap();
        let rows = history(
            &conn,
            &HistoryQuery {
                kind: Some("state".into()),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(rows.is_empty());
    }
}
