//! The journal's file: its tables and their schema (migrated at open),
//! opening it for writing or reading, and what the writer does to the
//! tables as a whole (the shared sequence, the retention purge). Rows are
//! written by the writer thread (`mod.rs`).

use std::path::{Path, PathBuf};
use std::time::Duration;

use rusqlite::{Connection, OpenFlags};

use crate::journal::config::Keep;

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
    #[error("journal {path}: commit failed: {source}")]
    Commit {
        /// The file.
        path: PathBuf,
        /// Why.
        source: NotCommitted,
    },
    /// The writer thread has stopped.
    #[error("journal {path}: the writer has stopped")]
    Stopped {
        /// The file.
        path: PathBuf,
    },
}

/// Why rows handed to the writer are not committed (yet): they are kept
/// and retried. SQLite's words for why the journal cannot write.
#[derive(Debug, Clone, thiserror::Error)]
pub enum NotCommitted {
    /// An earlier write failed, and the next try is not due yet.
    #[error("{0} (rows queued)")]
    Queued(String),
    /// This write failed.
    #[error("{0}")]
    Failed(String),
}

/// The tables of journal rows (one sequence across them).
pub(super) const TABLES: [&str; 7] = crate::journal::config::JOURNAL_TABLES;

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
    at_ms INTEGER NOT NULL,
    parts INTEGER NOT NULL DEFAULT 1,
    rejects INTEGER NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS production_at ON production (at_ms);
CREATE TABLE IF NOT EXISTS orders (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms INTEGER NOT NULL,
    item TEXT,
    target INTEGER
);
CREATE INDEX IF NOT EXISTS orders_at ON orders (at_ms);
CREATE TABLE IF NOT EXISTS recordings (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms INTEGER NOT NULL,
    alarm TEXT NOT NULL,
    payload TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS recordings_at ON recordings (at_ms);
CREATE INDEX IF NOT EXISTS recordings_alarm ON recordings (alarm, at_ms);
CREATE TABLE IF NOT EXISTS modes (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    at_ms INTEGER NOT NULL,
    mode TEXT NOT NULL,
    entered INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS modes_at ON modes (at_ms);
CREATE TABLE IF NOT EXISTS alarm_current (
    alarm TEXT PRIMARY KEY,
    at_ms INTEGER NOT NULL,
    payload TEXT NOT NULL
);
";

/// How long the writer waits for a lock held by another connection.
const WRITE_BUSY_TIMEOUT: Duration = Duration::from_secs(1);

/// Columns added after the first release, added to older journals at open.
const MIGRATIONS: &[(&str, &str, &str)] = &[
    ("commands", "verified", "INTEGER NOT NULL DEFAULT 0"),
    ("production", "parts", "INTEGER NOT NULL DEFAULT 1"),
    // Rejects (`[oee]`): a row of rejects has 0 parts.
    ("production", "rejects", "INTEGER NOT NULL DEFAULT 0"),
    ("commands", "stage", "TEXT NOT NULL DEFAULT 'command'"),
    ("commands", "source", "TEXT NOT NULL DEFAULT ''"),
    ("commands", "count", "INTEGER NOT NULL DEFAULT 1"),
    // The hash chain (`chain`): empty in rows written before it.
    ("commands", "chain_index", "INTEGER"),
    ("commands", "prev_hash", "TEXT"),
    ("commands", "hash", "TEXT"),
    // The command's digest (`Command::digest`): empty in rows before it.
    ("commands", "digest", "TEXT"),
];

fn migrate(conn: &Connection) -> rusqlite::Result<()> {
    for (table, column, decl) in MIGRATIONS {
        let exists: bool = conn.query_row(
            &format!("SELECT count(*) FROM pragma_table_info('{table}') WHERE name = ?1"),
            [column],
            |r| r.get::<_, i64>(0).map(|n| n > 0),
        )?;
        if !exists {
            conn.execute_batch(&format!("ALTER TABLE {table} ADD COLUMN {column} {decl}"))?;
        }
    }
    Ok(())
}

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
    // Short: a journal locked by someone else is reported (and its rows
    // queued) within a second rather than stalling the cell loop.
    conn.busy_timeout(WRITE_BUSY_TIMEOUT).map_err(err)?;
    conn.execute_batch(SCHEMA).map_err(err)?;
    migrate(&conn).map_err(err)?;
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

/// The last sequence number used by any table: rows share one sequence,
/// so that history pages in journal order across tables.
pub(super) fn last_seq(conn: &Connection) -> i64 {
    TABLES
        .iter()
        .map(|t| {
            conn.query_row(&format!("SELECT coalesce(max(seq), 0) FROM {t}"), [], |r| {
                r.get::<_, i64>(0)
            })
            .unwrap_or(0)
        })
        .max()
        .unwrap_or(0)
}

/// Rows deleted by one statement of the purge: a large purge goes in
/// steps, so the writer's own batches are never held up long.
const PURGE_STEP: i64 = 10_000;

/// Deletes what each table no longer keeps (`keep`): rows older than its
/// age, then the oldest beyond its row limit. A failure is logged, not
/// fatal.
pub(super) fn purge(conn: &Connection, keep: &[Keep], path: &Path) {
    let now = crate::clock::now_ms();
    for k in keep {
        let cutoff = now.saturating_sub(k.age.as_millis() as u64) as i64;
        let by_age = delete_in_steps(
            conn,
            &format!(
                "DELETE FROM {t} WHERE seq IN (SELECT seq FROM {t} WHERE at_ms < ?1 LIMIT {PURGE_STEP})",
                t = k.table
            ),
            cutoff,
        );
        // The seq of the newest row beyond the limit, if there are more.
        let by_rows = match k.max_rows.and_then(|n| i64::try_from(n).ok()) {
            None => Ok(0),
            Some(n) => conn
                .query_row(
                    &format!(
                        "SELECT seq FROM {} ORDER BY seq DESC LIMIT 1 OFFSET ?1",
                        k.table
                    ),
                    [n],
                    |r| r.get::<_, i64>(0),
                )
                .map_or(Ok(0), |last| {
                    delete_in_steps(
                        conn,
                        &format!(
                            "DELETE FROM {t} WHERE seq IN (SELECT seq FROM {t} WHERE seq <= ?1 ORDER BY seq LIMIT {PURGE_STEP})",
                            t = k.table
                        ),
                        last,
                    )
                }),
        };
        match (by_age, by_rows) {
            (Ok(0), Ok(0)) => {}
            (Ok(old), Ok(over)) => tracing::info!(
                path = %path.display(),
                table = k.table,
                older = old,
                beyond_max_rows = over,
                "journal retention: rows deleted"
            ),
            (Err(e), _) | (_, Err(e)) => {
                tracing::warn!(path = %path.display(), table = k.table, error = %e, "journal retention purge failed");
            }
        }
    }
}

/// Runs `statement` with `arg` until it deletes nothing: rows deleted.
fn delete_in_steps(conn: &Connection, statement: &str, arg: i64) -> rusqlite::Result<u64> {
    let mut deleted = 0u64;
    loop {
        let n = conn.execute(statement, [arg])?;
        deleted += n as u64;
        if (n as i64) < PURGE_STEP {
            return Ok(deleted);
        }
    }
}
