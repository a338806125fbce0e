//! The edge node's own store on disk: the changes held while the node
//! cannot publish (broker away, primary host offline), oldest first and
//! bounded, and the bdSeq of its last MQTT CONNECT, so neither is lost
//! when the agent stops or is killed. One SQLite file beside the journal
//! (`<journal>.sparkplug`); the journal itself knows nothing of it.
//!
//! It stores metrics by name, not by alias: aliases are handed out when the
//! agent starts and may differ in the next run. It does not know what the
//! metrics mean (`book.rs` does) nor when to write (`session.rs` does).

use std::path::{Path, PathBuf};

use rusqlite::types::Value as Sql;
use rusqlite::{params, Connection};

use super::value::MetricValue;

/// The store's file for the journal at `journal`.
pub(crate) fn store_path(journal: &Path) -> PathBuf {
    let mut name = journal.as_os_str().to_owned();
    name.push(".sparkplug");
    PathBuf::from(name)
}

/// Why the store cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("sparkplug store {path}: {source}")]
pub struct StoreError {
    /// The store's file.
    pub path: String,
    /// What SQLite said.
    #[source]
    pub source: rusqlite::Error,
}

/// One held change as stored.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct HeldRow {
    /// Its place in the store (0 until stored).
    pub id: i64,
    /// The metric's name (`Alarms/ese/Active`).
    pub metric: String,
    /// The new value; `None`: null.
    pub value: Option<MetricValue>,
    /// When, ms since the epoch.
    pub at: u64,
}

/// The store, open.
#[derive(Debug)]
pub(crate) struct HeldStore {
    connection: Connection,
    path: String,
    /// The most rows held; past it the oldest are dropped.
    max_rows: usize,
    /// How many rows are held now.
    rows: usize,
}

const SCHEMA: &str = "
PRAGMA journal_mode = WAL;
PRAGMA synchronous = NORMAL;
CREATE TABLE IF NOT EXISTS held (
    id     INTEGER PRIMARY KEY AUTOINCREMENT,
    metric TEXT    NOT NULL,
    kind   TEXT,
    value,
    at     INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS node (
    key   TEXT PRIMARY KEY,
    value INTEGER NOT NULL
);
";

impl HeldStore {
    /// Opens (creating it if new) the store at `path`, holding at most
    /// `max_rows`; returns it and how many of its rows were dropped to fit.
    ///
    /// # Errors
    /// The file cannot be opened or is not the store.
    pub(crate) fn open(path: &Path, max_rows: usize) -> Result<(HeldStore, u64), StoreError> {
        let shown = path.display().to_string();
        let bad = |source| StoreError {
            path: shown.clone(),
            source,
        };
        let connection = Connection::open(path).map_err(bad)?;
        connection.execute_batch(SCHEMA).map_err(bad)?;
        let rows: i64 = connection
            .query_row("SELECT count(*) FROM held", [], |r| r.get(0))
            .map_err(bad)?;
        let mut store = HeldStore {
            connection,
            path: shown,
            max_rows,
            rows: usize::try_from(rows).unwrap_or(0),
        };
        let dropped = store.trim()?;
        Ok((store, dropped))
    }

    fn bad(&self, source: rusqlite::Error) -> StoreError {
        StoreError {
            path: self.path.clone(),
            source,
        }
    }

    /// How many changes are held.
    pub(crate) fn rows(&self) -> usize {
        self.rows
    }

    /// Appends `rows` after the held ones; returns how many of the oldest
    /// were dropped to stay within the bound.
    ///
    /// # Errors
    /// SQLite cannot write.
    pub(crate) fn append(&mut self, rows: &[HeldRow]) -> Result<u64, StoreError> {
        if rows.is_empty() {
            return Ok(0);
        }
        let tx = self.connection.transaction().map_err(|e| StoreError {
            path: self.path.clone(),
            source: e,
        })?;
        {
            let mut insert = tx
                .prepare_cached(
                    "INSERT INTO held (metric, kind, value, at) VALUES (?1, ?2, ?3, ?4)",
                )
                .map_err(|e| StoreError {
                    path: self.path.clone(),
                    source: e,
                })?;
            for r in rows {
                let (kind, value) = encode(r.value.as_ref());
                insert
                    .execute(params![r.metric, kind, value, r.at as i64])
                    .map_err(|e| StoreError {
                        path: self.path.clone(),
                        source: e,
                    })?;
            }
        }
        tx.commit().map_err(|e| self.bad(e))?;
        self.rows += rows.len();
        self.trim()
    }

    /// Drops the oldest rows past the bound; how many.
    fn trim(&mut self) -> Result<u64, StoreError> {
        let excess = self.rows.saturating_sub(self.max_rows);
        if excess == 0 {
            return Ok(0);
        }
        self.connection
            .execute(
                "DELETE FROM held WHERE id IN (SELECT id FROM held ORDER BY id LIMIT ?1)",
                [excess as i64],
            )
            .map_err(|e| self.bad(e))?;
        self.rows -= excess;
        Ok(excess as u64)
    }

    /// The oldest `n` held rows, oldest first.
    ///
    /// # Errors
    /// SQLite cannot read.
    pub(crate) fn oldest(&self, n: usize) -> Result<Vec<HeldRow>, StoreError> {
        let mut select = self
            .connection
            .prepare_cached("SELECT id, metric, kind, value, at FROM held ORDER BY id LIMIT ?1")
            .map_err(|e| self.bad(e))?;
        let rows = select
            .query_map([n as i64], |r| {
                let kind: Option<String> = r.get(2)?;
                let value: Sql = r.get(3)?;
                Ok(HeldRow {
                    id: r.get(0)?,
                    metric: r.get(1)?,
                    value: decode(kind.as_deref(), value),
                    at: r.get::<_, i64>(4)? as u64,
                })
            })
            .map_err(|e| self.bad(e))?;
        rows.collect::<Result<_, _>>().map_err(|e| self.bad(e))
    }

    /// Forgets the rows up to `id`, once published.
    ///
    /// # Errors
    /// SQLite cannot write.
    pub(crate) fn forget_through(&mut self, id: i64) -> Result<(), StoreError> {
        let gone = self
            .connection
            .execute("DELETE FROM held WHERE id <= ?1", [id])
            .map_err(|e| self.bad(e))?;
        self.rows = self.rows.saturating_sub(gone);
        Ok(())
    }

    /// The bdSeq of the last MQTT CONNECT, if one was made.
    ///
    /// # Errors
    /// SQLite cannot read.
    pub(crate) fn last_bd_seq(&self) -> Result<Option<u64>, StoreError> {
        let mut select = self
            .connection
            .prepare_cached("SELECT value FROM node WHERE key = 'bd_seq'")
            .map_err(|e| self.bad(e))?;
        let mut rows = select.query([]).map_err(|e| self.bad(e))?;
        match rows.next().map_err(|e| self.bad(e))? {
            Some(r) => Ok(Some(r.get::<_, i64>(0).map_err(|e| self.bad(e))? as u64)),
            None => Ok(None),
        }
    }

    /// Keeps `bd_seq` as the one of the MQTT CONNECT about to be made.
    ///
    /// # Errors
    /// SQLite cannot write.
    pub(crate) fn keep_bd_seq(&mut self, bd_seq: u64) -> Result<(), StoreError> {
        self.connection
            .execute(
                "INSERT INTO node (key, value) VALUES ('bd_seq', ?1)
                 ON CONFLICT (key) DO UPDATE SET value = excluded.value",
                [bd_seq as i64],
            )
            .map_err(|e| self.bad(e))
            .map(drop)
    }
}

fn encode(value: Option<&MetricValue>) -> (Option<&'static str>, Sql) {
    match value {
        None => (None, Sql::Null),
        Some(MetricValue::Boolean(b)) => (Some("b"), Sql::Integer(i64::from(*b))),
        Some(MetricValue::Text(s)) => (Some("s"), Sql::Text(s.clone())),
        Some(MetricValue::UInt64(n)) => (Some("u"), Sql::Integer(*n as i64)),
        Some(MetricValue::Double(x)) => (Some("d"), Sql::Real(*x)),
    }
}

fn decode(kind: Option<&str>, value: Sql) -> Option<MetricValue> {
    match (kind, value) {
        (Some("b"), Sql::Integer(n)) => Some(MetricValue::Boolean(n != 0)),
        (Some("s"), Sql::Text(s)) => Some(MetricValue::Text(s)),
        (Some("u"), Sql::Integer(n)) => Some(MetricValue::UInt64(n as u64)),
        (Some("d"), Sql::Real(x)) => Some(MetricValue::Double(x)),
        (Some("d"), Sql::Integer(n)) => Some(MetricValue::Double(n as f64)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(metric: &str, value: Option<MetricValue>, at: u64) -> HeldRow {
        HeldRow {
            id: 0,
            metric: metric.into(),
            value,
            at,
        }
    }

    #[test]
    fn held_changes_and_bd_seq_outlive_the_process_in_order() {
        let d = tempfile::tempdir().unwrap();
        let path = store_path(&d.path().join("journal.sqlite"));
        assert!(path.ends_with("journal.sqlite.sparkplug"));
        let written = vec![
            row("Machine/State", Some(MetricValue::Text("fault".into())), 1),
            row("Alarms/ese/Active", Some(MetricValue::Boolean(true)), 2),
            row(
                "Production/Parts Produced",
                Some(MetricValue::UInt64(u64::MAX)),
                3,
            ),
            row("Tags/t", Some(MetricValue::Double(1.5)), 4),
            row("Machine/Fault Type", None, 5),
        ];
        {
            let (mut store, dropped) = HeldStore::open(&path, 10).unwrap();
            assert_eq!(dropped, 0);
            assert_eq!(store.last_bd_seq().unwrap(), None);
            store.keep_bd_seq(254).unwrap();
            store.keep_bd_seq(255).unwrap();
            assert_eq!(store.append(&written).unwrap(), 0);
        }
        let (mut store, _) = HeldStore::open(&path, 10).unwrap();
        assert_eq!(store.last_bd_seq().unwrap(), Some(255));
        assert_eq!(store.rows(), 5);
        let read = store.oldest(3).unwrap();
        let strip = |r: &[HeldRow]| -> Vec<HeldRow> {
            r.iter().map(|r| HeldRow { id: 0, ..r.clone() }).collect()
        };
        assert_eq!(strip(&read), written[..3]);
        store.forget_through(read[2].id).unwrap();
        assert_eq!(store.rows(), 2);
        assert_eq!(strip(&store.oldest(10).unwrap()), written[3..]);
    }

    #[test]
    fn past_the_bound_the_oldest_are_dropped_and_counted() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("s");
        let (mut store, _) = HeldStore::open(&path, 3).unwrap();
        let rows: Vec<HeldRow> = (0..5)
            .map(|i: u32| {
                row(
                    "Tags/t",
                    Some(MetricValue::Double(f64::from(i))),
                    u64::from(i),
                )
            })
            .collect();
        assert_eq!(store.append(&rows[..2]).unwrap(), 0);
        assert_eq!(store.append(&rows[2..]).unwrap(), 2);
        let ats: Vec<u64> = store.oldest(10).unwrap().iter().map(|r| r.at).collect();
        assert_eq!(ats, [2, 3, 4]);
        drop(store);
        // A smaller bound at the next start drops the oldest too.
        let (store, dropped) = HeldStore::open(&path, 1).unwrap();
        assert_eq!(dropped, 2);
        assert_eq!(store.oldest(10).unwrap()[0].at, 4);
    }
}
