//! Reading the journal for the history service: bounded pages of rows, oldest first.

use rusqlite::{params, Connection};
use serde::Serialize;

use super::JournalError;

/// A history row as served to queries.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct HistoryRow {
    /// Row number in the journal.
    pub seq: i64,
    /// `alarm`, `state`, `command` or `recording`.
    pub table: &'static str,
    /// When, ms since the epoch.
    pub at: u64,
    /// The row's fields.
    pub fields: serde_json::Map<String, serde_json::Value>,
}

/// Why a history query failed.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    /// The query asks for a kind of row there is none of.
    #[error("unknown kind '{0}': use alarm, state, command, recording, kpi or production")]
    UnknownKind(String),
    /// The journal cannot be read.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// SQLite failed while reading.
    #[error("journal: {0}")]
    Sqlite(#[from] rusqlite::Error),
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
    /// At most this many rows, default [`DEFAULT_ROWS`], at most
    /// [`MAX_ROWS`].
    pub limit: Option<usize>,
    /// Page forward: only rows after this sequence number, oldest first.
    /// Without it, the newest rows are returned.
    pub after: Option<i64>,
}

/// Rows returned when a query gives no limit.
pub const DEFAULT_ROWS: usize = 1000;

/// The most rows one reply carries.
pub const MAX_ROWS: usize = 10_000;

/// The most bytes of rows one reply carries (JSON); more rows come with
/// `after` paging.
pub const MAX_REPLY_BYTES: usize = 1 << 20;

/// A text field longer than this, read from the journal, is cut (with `…`):
/// one row never fills a reply.
pub const MAX_FIELD_BYTES: usize = 16 * 1024;

/// One bounded piece of history.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct HistoryPage {
    /// [`HISTORY_SCHEMA`].
    pub schema: &'static str,
    /// The rows, oldest first.
    pub rows: Vec<HistoryRow>,
    /// More rows match than were returned: newer ones when paging with
    /// `after`, older ones otherwise.
    pub more: bool,
    /// With `after` paging: the `after` of the next page (the last row's
    /// sequence number) when there is more.
    pub next: Option<i64>,
}

/// Schema name of history replies.
pub const HISTORY_SCHEMA: &str = "cellwatch.history.v1";

/// The SQL and columns of one table.
fn table_query(table: &str, forward: bool) -> (String, &'static [&'static str], &'static str) {
    let (name, cols, label): (&str, &[&str], &str) = match table {
        "alarm" => (
            "alarm_events",
            &["alarm", "kind", "severity", "transition", "payload"],
            "alarm",
        ),
        "recording" => ("recordings", &["alarm", "payload"], "recording"),
        "state" => (
            "state_history",
            &["kind", "state", "fault_type", "element"],
            "state",
        ),
        _ => (
            "commands",
            &[
                "operator", "action", "alarm", "nonce", "accepted", "detail", "stage", "source",
                "count",
            ],
            "command",
        ),
    };
    let order = if forward { "seq ASC" } else { "seq DESC" };
    let sql = format!(
        "SELECT seq, at_ms, {} FROM {name} WHERE at_ms >= ?1 AND at_ms < ?2 AND seq > ?3 ORDER BY {order} LIMIT ?4",
        cols.join(", ")
    );
    (sql, cols, label)
}

/// Runs a history query: at most `limit` rows and [`MAX_REPLY_BYTES`] of
/// them, oldest first. Memory stays bounded whatever the journal holds.
///
/// # Errors
/// An unknown `kind`, or SQLite failing.
pub fn history(conn: &Connection, q: &HistoryQuery) -> Result<HistoryPage, HistoryError> {
    let tables: &[&str] = match q.kind.as_deref() {
        None => &["alarm", "state", "command"],
        Some("alarm") => &["alarm"],
        Some("state") => &["state"],
        Some("command") => &["command"],
        // Recordings are large: asked for by name only.
        Some("recording") => &["recording"],
        Some(other) => return Err(HistoryError::UnknownKind(other.to_string())),
    };
    let since = q.since.unwrap_or(0) as i64;
    let until = q.until.map_or(i64::MAX, |u| u as i64);
    let limit = q.limit.unwrap_or(DEFAULT_ROWS).clamp(1, MAX_ROWS);
    let forward = q.after.is_some();
    let after = q.after.unwrap_or(-1);
    // Each table gives at most `limit + 1` rows and the reply's byte budget:
    // enough to fill the reply and to know whether there is more.
    let mut rows: Vec<(HistoryRow, usize)> = Vec::new();
    for &t in tables {
        let (sql, cols, table) = table_query(t, forward);
        let mut stmt = conn.prepare_cached(&sql)?;
        let mut found = stmt.query(params![since, until, after, (limit + 1) as i64])?;
        let mut bytes = 0;
        while let Some(r) = found.next()? {
            let row = history_row(r, cols, table)?;
            let size = serde_json::to_string(&row).map_or(0, |s| s.len()) + 1;
            bytes += size;
            rows.push((row, size));
            if bytes > MAX_REPLY_BYTES {
                break;
            }
        }
    }
    // Merge in journal order (the sequence is shared by the tables), keep
    // the first rows when paging forward, the newest otherwise.
    rows.sort_by_key(|(r, _)| (r.seq, r.table));
    if !forward {
        rows.reverse();
    }
    let mut kept = Vec::new();
    let mut bytes = 0;
    let mut more = false;
    for (row, size) in rows {
        if kept.len() == limit || bytes + size > MAX_REPLY_BYTES {
            more = true;
            break;
        }
        bytes += size;
        kept.push(row);
    }
    if !forward {
        kept.reverse();
    }
    let next = (forward && more).then(|| kept.last().map_or(after, |r| r.seq));
    Ok(HistoryPage {
        schema: HISTORY_SCHEMA,
        rows: kept,
        more,
        next,
    })
}

/// The payload of alarm `alarm`'s flight recording raised last at or
/// before `at` (ms; `None`: the newest), if the journal has one.
///
/// # Errors
/// SQLite failing.
pub fn recording(
    conn: &Connection,
    alarm: &str,
    at: Option<u64>,
) -> Result<Option<String>, HistoryError> {
    let at = at.map_or(i64::MAX, |t| t.min(i64::MAX as u64) as i64);
    let mut stmt = conn.prepare_cached(
        "SELECT payload FROM recordings WHERE alarm = ?1 AND at_ms <= ?2 ORDER BY at_ms DESC, seq DESC LIMIT 1",
    )?;
    let mut rows = stmt.query(params![alarm, at])?;
    Ok(match rows.next()? {
        Some(r) => Some(r.get(0)?),
        None => None,
    })
}

fn history_row(
    r: &rusqlite::Row<'_>,
    cols: &[&str],
    table: &'static str,
) -> rusqlite::Result<HistoryRow> {
    let mut fields = serde_json::Map::new();
    for (i, c) in cols.iter().enumerate() {
        let v: rusqlite::types::Value = r.get(i + 2)?;
        let json = match v {
            rusqlite::types::Value::Null => serde_json::Value::Null,
            rusqlite::types::Value::Integer(n) if *c == "accepted" => {
                serde_json::Value::Bool(n != 0)
            }
            rusqlite::types::Value::Integer(n) => n.into(),
            // A recording is bounded by the recorder (`recorder.max_changes`)
            // and the reply's bytes, not cut: cut, it would be no JSON.
            rusqlite::types::Value::Text(s) if table == "recording" && *c == "payload" => {
                serde_json::from_str(&s).unwrap_or(serde_json::Value::String(s))
            }
            rusqlite::types::Value::Text(s) if s.len() > MAX_FIELD_BYTES => {
                crate::operator::clip(&s, MAX_FIELD_BYTES).into()
            }
            rusqlite::types::Value::Text(s) if *c == "payload" => {
                serde_json::from_str(&s).unwrap_or(serde_json::Value::String(s))
            }
            rusqlite::types::Value::Text(s) => s.into(),
            rusqlite::types::Value::Real(x) => x.into(),
            rusqlite::types::Value::Blob(b) => format!("<{} bytes>", b.len()).into(),
        };
        fields.insert((*c).to_string(), json);
    }
    Ok(HistoryRow {
        seq: r.get(0)?,
        table,
        at: r.get::<_, i64>(1)? as u64,
        fields,
    })
}
