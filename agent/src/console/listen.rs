//! The console's bus side: every cell's alarm events and states, its
//! agent's liveliness token, and its snapshot when needed. Everything is
//! believed only if the cell's own agent signed it.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use zenoh::sample::SampleKind;
use zenoh_ext::{AdvancedSubscriberBuilderExt, HistoryConfig, RecoveryConfig};

use super::shared::Shared;
use crate::bus::keys::{cell_of, Service};
use crate::payload::{AlarmPayload, SnapshotPayload, StatePayload};

/// How long the console waits for an agent's snapshot.
const SNAPSHOT_ANSWER: Duration = Duration::from_secs(5);

/// The most sessions remembered as one cell's agent (a restart gives a new
/// one; a flapping agent or a forged token must not grow the map).
const SESSIONS_PER_CELL: usize = 4;

/// How often every agent's snapshot is asked again, whatever happened: a
/// safety net under the events.
const RESYNC_EVERY: Duration = Duration::from_secs(60);

/// Why the console cannot listen to the agents.
#[derive(Debug, thiserror::Error)]
pub(super) enum ListenError {
    /// A subscription to their alarms or states was refused.
    #[error("cannot subscribe to {key}: {source}")]
    Subscribe {
        /// The key expression.
        key: String,
        /// Zenoh's error.
        source: zenoh::Error,
    },
    /// Missed alarm events cannot be listened for.
    #[error("cannot listen for missed alarm events: {0}")]
    Misses(#[source] zenoh::Error),
    /// The subscription to the agents' liveliness tokens was refused.
    #[error("cannot subscribe to the agents' tokens: {0}")]
    Tokens(#[source] zenoh::Error),
}

/// Starts the subscribers and the snapshot task; returns their tasks.
pub(super) async fn start(
    shared: Arc<Shared>,
    root: &str,
    resync: mpsc::UnboundedReceiver<String>,
) -> Result<Vec<JoinHandle<()>>, ListenError> {
    let every = shared.bus.keys("*");
    let session = shared.bus.session().clone();
    let alarms = session
        .declare_subscriber(every.alarms())
        .history(HistoryConfig::default().detect_late_publishers())
        .recovery(RecoveryConfig::default().heartbeat())
        .await
        .map_err(|source| ListenError::Subscribe {
            key: every.alarms(),
            source,
        })?;
    let misses = alarms
        .sample_miss_listener()
        .await
        .map_err(ListenError::Misses)?;
    let states = session
        .declare_subscriber(every.state())
        .history(HistoryConfig::default().detect_late_publishers())
        .await
        .map_err(|source| ListenError::Subscribe {
            key: every.state(),
            source,
        })?;
    let tokens = session
        .liveliness()
        .declare_subscriber(every.agent_token("*"))
        .history(true)
        .await
        .map_err(ListenError::Tokens)?;
    let mut tasks = Vec::new();

    let s = shared.clone();
    tasks.push(tokio::spawn(async move {
        while let Ok(sample) = alarms.recv_async().await {
            let key = sample.key_expr().as_str();
            let Some((a, sealed)) = opened::<AlarmPayload>(&s, &sample.payload().to_bytes(), key)
            else {
                continue;
            };
            let sealed = crate::clock::rfc3339(sealed);
            s.change(|p| p.alarm_event(a, &sealed));
        }
    }));

    let s = shared.clone();
    tasks.push(tokio::spawn(async move {
        while let Ok(sample) = states.recv_async().await {
            let key = sample.key_expr().as_str();
            let Some((state, _)) = opened::<StatePayload>(&s, &sample.payload().to_bytes(), key)
            else {
                continue;
            };
            s.change(|p| p.state(state).into_iter().collect());
        }
    }));

    // Which agent's session is which cell's, from the tokens' keys: a
    // miss is reported by the publisher's session.
    let sessions: Arc<std::sync::Mutex<HashMap<String, String>>> = Arc::default();
    let s = shared.clone();
    let root_owned = root.to_string();
    let known = sessions.clone();
    tasks.push(tokio::spawn(async move {
        while let Ok(sample) = tokens.recv_async().await {
            let key = sample.key_expr().as_str();
            let Some(cell) = cell_of(&root_owned, key).map(str::to_string) else {
                continue;
            };
            // Tokens are not signed: one of a cell outside the trust file
            // (where a router's access control is off) is ignored.
            let trusted = s.plant.lock().is_ok_and(|p| p.cell(&cell).is_some());
            if !trusted {
                tracing::debug!(
                    key,
                    "a liveliness token of a cell outside the trust file: ignored"
                );
                continue;
            }
            let zid = key.rsplit('/').next().unwrap_or_default().to_string();
            let up = sample.kind() == SampleKind::Put;
            if let Ok(mut known) = known.lock() {
                if up {
                    let theirs: Vec<String> = known
                        .iter()
                        .filter(|(_, c)| **c == cell)
                        .map(|(z, _)| z.clone())
                        .collect();
                    if theirs.len() >= SESSIONS_PER_CELL {
                        for z in theirs {
                            known.remove(&z);
                        }
                    }
                    known.insert(zid, cell.clone());
                } else {
                    known.remove(&zid);
                }
            }
            if up {
                // An agent that (re)starts has restored its alarms.
                let _ = s.resync.send(cell.clone());
            }
            s.change(|p| p.agent(&cell, up).into_iter().collect());
        }
    }));

    let s = shared.clone();
    tasks.push(tokio::spawn(async move {
        while let Ok(miss) = misses.recv_async().await {
            let zid = miss.source().zid().to_string();
            let cell = sessions.lock().ok().and_then(|k| k.get(&zid).cloned());
            tracing::warn!(session = %zid, missed = miss.nb(), cell = ?cell, "alarm events missed: asking the agent's snapshot");
            match cell {
                Some(cell) => {
                    let _ = s.resync.send(cell);
                }
                None => {
                    let _ = s.resync.send("*".into());
                }
            }
        }
    }));

    tasks.push(tokio::spawn(snapshots(shared, resync)));
    Ok(tasks)
}

/// Opens a put its cell's agent sealed for `key` and parses its body,
/// with when it was sealed (ms since the epoch, the agent's clock); `None`
/// (logged) when not believed or not of its sealer's cell.
fn opened<T: serde::de::DeserializeOwned + HasCell>(
    s: &Shared,
    bytes: &[u8],
    key: &str,
) -> Option<(T, u64)> {
    let opened = match s.bus.open_put(bytes, key) {
        Ok(o) => o,
        Err(why) => {
            tracing::error!(key, why = %why, "not believed: ignored");
            return None;
        }
    };
    match serde_json::from_str::<T>(&opened.body) {
        Ok(v) if v.cell() == opened.cell => Some((v, opened.at)),
        Ok(v) => {
            tracing::error!(key, cell = v.cell(), sealed_by = %opened.cell, "a payload for another cell than its sealer's: ignored");
            None
        }
        Err(e) => {
            tracing::warn!(key, error = %e, "not the expected payload: ignored");
            None
        }
    }
}

/// A payload that names its cell.
trait HasCell {
    fn cell(&self) -> &str;
}

impl HasCell for AlarmPayload {
    fn cell(&self) -> &str {
        &self.cell
    }
}

impl HasCell for StatePayload {
    fn cell(&self) -> &str {
        &self.cell
    }
}

/// Asks every agent's snapshot at once, then each cell's when asked
/// (`*`: every cell), and every agent's again every [`RESYNC_EVERY`].
///
/// The cells asked while a snapshot is under way are taken together, each
/// once: an agent whose token flaps does not queue a snapshot per flap
/// ahead of the other cells.
async fn snapshots(s: Arc<Shared>, mut resync: mpsc::UnboundedReceiver<String>) {
    let mut every = tokio::time::interval(RESYNC_EVERY);
    let mut pending = std::collections::BTreeSet::new();
    loop {
        if pending.is_empty() {
            tokio::select! {
                _ = every.tick() => { pending.insert("*".to_string()); }
                cell = resync.recv() => match cell {
                    Some(cell) => { pending.insert(cell); }
                    None => return,
                },
            }
        }
        while let Ok(cell) = resync.try_recv() {
            pending.insert(cell);
        }
        let cell = if pending.remove("*") {
            pending.clear();
            "*".to_string()
        } else {
            match pending.pop_first() {
                Some(cell) => cell,
                None => continue,
            }
        };
        if cell == "*" {
            match s
                .bus
                .ask_every("*", Service::Snapshot, SNAPSHOT_ANSWER)
                .await
            {
                Ok((answers, _)) => {
                    for a in answers {
                        take_snapshot(&s, &a.cell, a.answer);
                    }
                }
                Err(e) => tracing::warn!(error = %e, "cannot ask the agents' snapshots"),
            }
        } else {
            let answer = s
                .bus
                .ask(&cell, Service::Snapshot, "", None, SNAPSHOT_ANSWER)
                .await;
            take_snapshot(&s, &cell, answer);
        }
    }
}

fn take_snapshot(s: &Shared, cell: &str, answer: Result<String, impl std::fmt::Display>) {
    let text = match answer {
        Ok(text) => text,
        Err(e) => {
            tracing::warn!(cell, error = %e, "no snapshot");
            return;
        }
    };
    match serde_json::from_str::<SnapshotPayload>(&text) {
        Ok(snap) if snap.cell == cell => s.change(|p| p.snapshot(snap)),
        Ok(snap) => {
            tracing::error!(cell, other = %snap.cell, "a snapshot of another cell: ignored");
        }
        Err(e) => tracing::warn!(cell, error = %e, "not a snapshot: ignored"),
    }
}
