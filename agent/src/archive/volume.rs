//! A Zenoh storage backend on SQLite that keeps every sample: the volume
//! behind the plant archive's storages.
//!
//! Zenoh's storage manager hands a backend each sample put under a
//! storage's key expression; a backend declaring [`History::All`] is given
//! them all and keeps them all (as Zenoh's InfluxDB backends do), so an
//! alarm's every event stays, not only its last. A query with a `_time`
//! range (Zenoh's time DSL: `_time=[now(-1d)..]`) is answered with every
//! sample of the range, oldest first; a query without one with the latest
//! sample of each key. Samples older than the storage's `retention` are
//! removed as new ones arrive.
//!
//! One SQLite file per storage, `<dir>/<storage>.sqlite`, in WAL mode. A
//! delete is not applied: the archive keeps what was signed and sent.
//!
//! Configuration (the router's `plugins.storage_manager`):
//!
//! ```json5
//! volumes: { sqlite: { dir: "/var/lib/cellwatch/archive" } },
//! storages: {
//!   alarms: { key_expr: "cellwatch/*/alarms/**", volume: { id: "sqlite", retention: "90d" } },
//! }
//! ```

use std::path::PathBuf;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use async_trait::async_trait;
use rusqlite::{params, Connection, OptionalExtension};
use zenoh::bytes::{Encoding, ZBytes};
use zenoh::key_expr::OwnedKeyExpr;
use zenoh::query::{Parameters, TimeBound, ZenohParameters};
use zenoh::time::{Timestamp, TimestampId, NTP64};
use zenoh_backend_traits::config::{StorageConfig, VolumeConfig};
use zenoh_backend_traits::{
    Capability, History, Persistence, Storage, StorageInsertionResult, StoredData, Volume,
    VolumeInstance,
};
use zenoh_plugin_trait::{plugin_long_version, plugin_version, Plugin};

/// The volume's name in the storage manager's configuration.
pub(crate) const VOLUME: &str = "sqlite";

/// How long a storage keeps its samples when its configuration says not.
pub(crate) const DEFAULT_RETENTION: Duration = Duration::from_secs(90 * 24 * 3600);

/// At most this many samples of one key answer one query (the newest of
/// the range): a reply is held in memory whole.
pub(crate) const MOST_PER_QUERY: usize = 100_000;

/// How often a storage removes what is past its retention.
const PRUNE_EVERY: Duration = Duration::from_secs(60);

/// What keeps a volume or a storage from starting.
#[derive(Debug, thiserror::Error)]
pub(crate) enum VolumeError {
    /// The volume's configuration has no `dir`.
    #[error("volume `{VOLUME}`: `dir` (the folder of its SQLite files) is required")]
    NoDir,
    /// A setting of the volume or a storage does not read.
    #[error("{place}: `{key}` {problem}")]
    Setting {
        /// The volume or storage.
        place: String,
        /// The setting.
        key: &'static str,
        /// What is wrong with it.
        problem: String,
    },
    /// SQLite refused.
    #[error("storage `{storage}` ({path}): {source}")]
    Sqlite {
        /// The storage.
        storage: String,
        /// Its file.
        path: PathBuf,
        /// SQLite's error.
        source: rusqlite::Error,
    },
    /// A stored timestamp's id does not read (the file was written by
    /// something else).
    #[error("storage `{storage}`: a stored timestamp id of {len} bytes does not read")]
    BadId {
        /// The storage.
        storage: String,
        /// Its length.
        len: usize,
    },
}

/// The backend, linked into `cellwatch router` and declared to the
/// storage manager under [`VOLUME`].
#[derive(Debug)]
pub(crate) struct SqliteVolume {
    dir: PathBuf,
    config: VolumeConfig,
}

impl Plugin for SqliteVolume {
    type StartArgs = VolumeConfig;
    type Instance = VolumeInstance;

    const DEFAULT_NAME: &'static str = VOLUME;
    const PLUGIN_VERSION: &'static str = plugin_version!();
    const PLUGIN_LONG_VERSION: &'static str = plugin_long_version!();

    fn start(_: &str, config: &VolumeConfig) -> zenoh::Result<VolumeInstance> {
        let rest = config.rest.into_serde_map();
        let dir = match rest.get("dir") {
            Some(serde_json::Value::String(dir)) if !dir.is_empty() => PathBuf::from(dir),
            Some(_) => {
                return Err(VolumeError::Setting {
                    place: format!("volume `{VOLUME}`"),
                    key: "dir",
                    problem: "must be a folder's path (a string)".into(),
                }
                .into())
            }
            None => return Err(VolumeError::NoDir.into()),
        };
        std::fs::create_dir_all(&dir).map_err(|e| VolumeError::Setting {
            place: format!("volume `{VOLUME}`"),
            key: "dir",
            problem: format!("{}: {e}", dir.display()),
        })?;
        Ok(Box::new(SqliteVolume {
            dir,
            config: config.clone(),
        }))
    }
}

#[async_trait]
impl Volume for SqliteVolume {
    fn get_admin_status(&self) -> zenoh_util::ffi::JsonValue {
        self.config.to_json_value().into()
    }

    fn get_capability(&self) -> Capability {
        Capability {
            persistence: Persistence::Durable,
            history: History::All,
        }
    }

    async fn create_storage(&self, config: StorageConfig) -> zenoh::Result<Box<dyn Storage>> {
        let retention = retention(&config)?;
        let path = self.dir.join(format!("{}.sqlite", config.name));
        let storage = SqliteStorage::open(config, path, retention)?;
        Ok(Box::new(storage))
    }
}

/// The storage's `retention` (`volume: { id: "sqlite", retention: "90d" }`),
/// [`DEFAULT_RETENTION`] when not given.
fn retention(config: &StorageConfig) -> Result<Duration, VolumeError> {
    let bad = |problem: String| VolumeError::Setting {
        place: format!("storage `{}`", config.name),
        key: "retention",
        problem,
    };
    match config.volume_cfg.into_serde_value().get("retention") {
        None => Ok(DEFAULT_RETENTION),
        Some(serde_json::Value::String(text)) => {
            let text = text.as_str();
            let d = humantime::parse_duration(text)
                .map_err(|e| bad(format!("`{text}` is not a duration (90d, 720h): {e}")))?;
            if d.is_zero() {
                return Err(bad("must be longer than nothing".into()));
            }
            Ok(d)
        }
        Some(other) => Err(bad(format!(
            "must be a duration such as \"90d\", not {other}"
        ))),
    }
}

/// One storage: its SQLite file.
struct SqliteStorage {
    config: StorageConfig,
    path: PathBuf,
    // The storage manager calls one storage at a time (behind its own
    // lock); the mutex makes the connection shareable, never contended.
    db: std::sync::Mutex<Connection>,
    retention: Duration,
    pruned: Option<SystemTime>,
}

/// A Zenoh timestamp's 64-bit NTP time as an SQLite integer that sorts as
/// the time does: the top bit flipped maps the unsigned range onto the
/// signed one in order.
fn ordered(t: NTP64) -> i64 {
    (t.as_u64() ^ (1 << 63)) as i64
}

fn unordered(v: i64) -> NTP64 {
    NTP64((v as u64) ^ (1 << 63))
}

fn ntp(t: SystemTime) -> NTP64 {
    NTP64::from(t.duration_since(UNIX_EPOCH).unwrap_or_default())
}

impl SqliteStorage {
    fn open(
        config: StorageConfig,
        path: PathBuf,
        retention: Duration,
    ) -> Result<SqliteStorage, VolumeError> {
        let fail = |source| VolumeError::Sqlite {
            storage: config.name.clone(),
            path: path.clone(),
            source,
        };
        let db = Connection::open(&path).map_err(fail)?;
        db.execute_batch(
            "PRAGMA journal_mode = WAL;
             PRAGMA synchronous = NORMAL;
             CREATE TABLE IF NOT EXISTS samples (
                 key TEXT NOT NULL,
                 time INTEGER NOT NULL,
                 id BLOB NOT NULL,
                 encoding TEXT NOT NULL,
                 payload BLOB NOT NULL,
                 PRIMARY KEY (key, time, id)
             ) WITHOUT ROWID;
             CREATE INDEX IF NOT EXISTS samples_by_time ON samples (time);",
        )
        .map_err(fail)?;
        Ok(SqliteStorage {
            config,
            path,
            db: std::sync::Mutex::new(db),
            retention,
            pruned: None,
        })
    }

    fn db(&self) -> std::sync::MutexGuard<'_, Connection> {
        self.db
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    fn fail(&self, source: rusqlite::Error) -> VolumeError {
        VolumeError::Sqlite {
            storage: self.config.name.clone(),
            path: self.path.clone(),
            source,
        }
    }

    fn timestamp(&self, time: i64, id: &[u8]) -> Result<Timestamp, VolumeError> {
        let id = TimestampId::try_from(id).map_err(|_| VolumeError::BadId {
            storage: self.config.name.clone(),
            len: id.len(),
        })?;
        Ok(Timestamp::new(unordered(time), id))
    }

    /// Removes what is past retention, at most once every [`PRUNE_EVERY`]
    /// of the samples' own time.
    fn prune(&mut self, now: SystemTime) -> Result<(), VolumeError> {
        if let Some(last) = self.pruned {
            if now.duration_since(last).unwrap_or_default() < PRUNE_EVERY {
                return Ok(());
            }
        }
        self.pruned = Some(now);
        let Some(horizon) = now.checked_sub(self.retention) else {
            return Ok(());
        };
        let removed = self
            .db()
            .execute(
                "DELETE FROM samples WHERE time < ?1",
                params![ordered(ntp(horizon))],
            )
            .map_err(|e| self.fail(e))?;
        if removed > 0 {
            tracing::info!(
                storage = %self.config.name,
                removed,
                "archive: samples past retention removed"
            );
        }
        Ok(())
    }

    fn rows(
        &self,
        key: &str,
        from: Option<(i64, bool)>,
        to: Option<(i64, bool)>,
    ) -> Result<Vec<StoredData>, VolumeError> {
        // Bounds as SQL: inclusive or not, each optional.
        let low = match from {
            Some((_, true)) => "time >= ?2",
            Some((_, false)) => "time > ?2",
            None => "?2 IS NULL",
        };
        let high = match to {
            Some((_, true)) => "time <= ?3",
            Some((_, false)) => "time < ?3",
            None => "?3 IS NULL",
        };
        let sql = format!(
            "SELECT time, id, encoding, payload FROM (
                 SELECT time, id, encoding, payload FROM samples
                 WHERE key = ?1 AND {low} AND {high}
                 ORDER BY time DESC LIMIT ?4)
             ORDER BY time"
        );
        let db = self.db();
        let mut stmt = db.prepare_cached(&sql).map_err(|e| self.fail(e))?;
        let rows = stmt
            .query_map(
                params![
                    key,
                    from.map(|(t, _)| t),
                    to.map(|(t, _)| t),
                    MOST_PER_QUERY as i64
                ],
                |r| {
                    Ok((
                        r.get::<_, i64>(0)?,
                        r.get::<_, Vec<u8>>(1)?,
                        r.get::<_, String>(2)?,
                        r.get::<_, Vec<u8>>(3)?,
                    ))
                },
            )
            .map_err(|e| self.fail(e))?
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| self.fail(e))?;
        rows.into_iter()
            .map(|(time, id, encoding, payload)| {
                Ok(StoredData {
                    payload: ZBytes::from(payload),
                    encoding: Encoding::from(encoding),
                    timestamp: self.timestamp(time, &id)?,
                })
            })
            .collect()
    }

    fn latest(&self, key: &str) -> Result<Vec<StoredData>, VolumeError> {
        let row = self
            .db()
            .query_row(
                "SELECT time, id, encoding, payload FROM samples WHERE key = ?1
                 ORDER BY time DESC LIMIT 1",
                params![key],
                |r| {
                    Ok((
                        r.get::<_, i64>(0)?,
                        r.get::<_, Vec<u8>>(1)?,
                        r.get::<_, String>(2)?,
                        r.get::<_, Vec<u8>>(3)?,
                    ))
                },
            )
            .optional()
            .map_err(|e| self.fail(e))?;
        row.map(|(time, id, encoding, payload)| {
            Ok(StoredData {
                payload: ZBytes::from(payload),
                encoding: Encoding::from(encoding),
                timestamp: self.timestamp(time, &id)?,
            })
        })
        .into_iter()
        .collect()
    }
}

/// The key as stored: a key equal to the storage's `strip_prefix` is the
/// empty string.
fn stored_key(key: &Option<OwnedKeyExpr>) -> &str {
    key.as_ref().map_or("", |k| k.as_str())
}

fn bound(b: &TimeBound<SystemTime>) -> Option<(i64, bool)> {
    match b {
        TimeBound::Inclusive(t) => Some((ordered(ntp(*t)), true)),
        TimeBound::Exclusive(t) => Some((ordered(ntp(*t)), false)),
        TimeBound::Unbounded => None,
    }
}

#[async_trait]
impl Storage for SqliteStorage {
    fn get_admin_status(&self) -> zenoh_util::ffi::JsonValue {
        let mut status = self.config.to_json_value();
        if let Some(map) = status.as_object_mut() {
            map.insert("file".into(), self.path.display().to_string().into());
            map.insert(
                "retention".into(),
                humantime::format_duration(self.retention)
                    .to_string()
                    .into(),
            );
        }
        status.into()
    }

    async fn put(
        &mut self,
        key: Option<OwnedKeyExpr>,
        payload: ZBytes,
        encoding: Encoding,
        timestamp: Timestamp,
    ) -> zenoh::Result<StorageInsertionResult> {
        let id = timestamp.get_id();
        let inserted = self
            .db()
            .prepare_cached(
                "INSERT OR IGNORE INTO samples (key, time, id, encoding, payload)
                 VALUES (?1, ?2, ?3, ?4, ?5)",
            )
            .and_then(|mut stmt| {
                stmt.execute(params![
                    stored_key(&key),
                    ordered(*timestamp.get_time()),
                    &id.to_le_bytes()[..id.size()],
                    encoding.to_string(),
                    payload.to_bytes().as_ref(),
                ])
            })
            .map_err(|e| self.fail(e))?;
        self.prune(timestamp.get_time().to_system_time())?;
        Ok(if inserted == 0 {
            // The same sample again (same key and timestamp): kept once.
            StorageInsertionResult::Outdated
        } else {
            StorageInsertionResult::Inserted
        })
    }

    async fn delete(
        &mut self,
        key: Option<OwnedKeyExpr>,
        _timestamp: Timestamp,
    ) -> zenoh::Result<StorageInsertionResult> {
        tracing::debug!(
            storage = %self.config.name,
            key = stored_key(&key),
            "archive: a delete is not applied (the archive keeps what was sent)"
        );
        Ok(StorageInsertionResult::Outdated)
    }

    async fn get(
        &mut self,
        key: Option<OwnedKeyExpr>,
        parameters: &str,
    ) -> zenoh::Result<Vec<StoredData>> {
        let key = stored_key(&key);
        match Parameters::from(parameters).time_range() {
            None => Ok(self.latest(key)?),
            Some(range) => {
                let range = range?.resolve_at(SystemTime::now());
                Ok(self.rows(key, bound(&range.start), bound(&range.end))?)
            }
        }
    }

    async fn get_all_entries(&self) -> zenoh::Result<Vec<(Option<OwnedKeyExpr>, Timestamp)>> {
        let db = self.db();
        let mut stmt = db
            .prepare_cached(
                "SELECT key, time, id FROM samples s WHERE time =
                     (SELECT MAX(time) FROM samples WHERE key = s.key)",
            )
            .map_err(|e| self.fail(e))?;
        let rows = stmt
            .query_map([], |r| {
                Ok((
                    r.get::<_, String>(0)?,
                    r.get::<_, i64>(1)?,
                    r.get::<_, Vec<u8>>(2)?,
                ))
            })
            .map_err(|e| self.fail(e))?
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| self.fail(e))?;
        let mut entries = Vec::with_capacity(rows.len());
        let mut seen = std::collections::HashSet::new();
        for (key, time, id) in rows {
            if !seen.insert(key.clone()) {
                continue;
            }
            let key = if key.is_empty() {
                None
            } else {
                Some(OwnedKeyExpr::try_from(key)?)
            };
            entries.push((key, self.timestamp(time, &id)?));
        }
        Ok(entries)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stored_time_sorts_as_the_time_does() {
        let times = [0u64, 1, (1 << 63) - 1, 1 << 63, u64::MAX];
        for pair in times.windows(2) {
            assert!(
                ordered(NTP64(pair[0])) < ordered(NTP64(pair[1])),
                "{pair:?}"
            );
            assert_eq!(unordered(ordered(NTP64(pair[0]))), NTP64(pair[0]));
        }
    }
}
