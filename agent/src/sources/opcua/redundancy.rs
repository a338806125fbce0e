//! Non-transparent server redundancy (OPC UA Part 4, 6.6.2): a cell's set of
//! servers (`opcua.endpoint` and `opcua.redundant`), each saying in its
//! `ServiceLevel` how well it can serve (200–255 healthy, 2–199 degraded,
//! 1 no data, 0 maintenance). The source reads from the server with the
//! highest level (`choose`, asked of every server over a short session of
//! its own before each connection), watches the level of the one it reads
//! from (`watch`), and moves when that one drops (its connection is lost)
//! or degrades below a healthy level while another says more.
//!
//! A move is a connection lost and another made: the engine's
//! communication alarm, one occurrence (its off-delay outlasts a move),
//! and fresh values from the new server, so no process alarm comes of it.

use std::sync::Arc;
use std::time::Duration;

use opcua::client::Session;
use opcua::types::{DataValue, NodeId, ReadValueId, TimestampsToReturn, Variant};
use tokio::sync::Notify;

use crate::sources::opcua::config::OpcUaConfig;

/// A `ServiceLevel` below this is a degraded server (Part 4).
pub(super) const HEALTHY: u8 = 200;

/// How often the level of the server read from is read.
const WATCH_EVERY: Duration = Duration::from_secs(1);

/// How long a server of the set may take to say its level.
const ASK_WITHIN: Duration = Duration::from_secs(5);

/// `Server_ServiceLevel`.
const SERVICE_LEVEL: u32 = 2267;

/// The `ServiceLevel` in a read result, if it says one.
fn level_of(value: Option<DataValue>) -> Option<u8> {
    let value = value?;
    if value.status.is_some_and(|s| !s.is_good()) {
        return None;
    }
    match value.value? {
        Variant::Byte(b) => Some(b),
        _ => None,
    }
}

/// The `ServiceLevel` `session`'s server says now.
pub(super) async fn level(session: &Session) -> Option<u8> {
    let read = session
        .read(
            &[ReadValueId::from(NodeId::new(0, SERVICE_LEVEL))],
            TimestampsToReturn::Neither,
            0.0,
        )
        .await
        .ok()?;
    level_of(read.into_iter().next())
}

/// Each server's `ServiceLevel`, in the set's order, asked at once over a
/// short session each; `None`: no answer within [`ASK_WITHIN`].
pub(super) async fn levels(cell: &str, config: &OpcUaConfig) -> Vec<Option<u8>> {
    let asks = config.servers().into_iter().map(|server| {
        let config = config.at(server);
        // The cell's own application name: its certificate says it, and a
        // server checks the two agree.
        let name = cell.to_string();
        async move {
            let ask = async {
                let (session, task) = match super::connect_once(&name, &config).await {
                    Ok(s) => s,
                    Err(e) => {
                        tracing::debug!(server = %config.endpoint, error = %e, "no ServiceLevel");
                        return None;
                    }
                };
                let l = level(&session).await;
                tracing::debug!(server = %config.endpoint, level = ?l, "ServiceLevel");
                let _ = tokio::time::timeout(Duration::from_secs(1), session.disconnect()).await;
                task.abort();
                l
            };
            tokio::time::timeout(ASK_WITHIN, ask).await.ok().flatten()
        }
    });
    futures_util::future::join_all(asks).await
}

/// The server to read from: the highest level said; on a tie the one read
/// from now, then the set's order. When none says anything, the one after
/// `current` (each is tried in turn).
pub(super) fn choose(levels: &[Option<u8>], current: usize) -> usize {
    let best = levels.iter().flatten().copied().max();
    match best {
        None => (current + 1) % levels.len().max(1),
        Some(b) if levels.get(current).copied().flatten() == Some(b) => current,
        Some(b) => levels.iter().position(|l| *l == Some(b)).unwrap_or(0),
    }
}

/// Watches the level of the server read from (`active`): when it is below
/// [`HEALTHY`] and another server of the set says more, `move_on` is
/// notified (and the watch ends).
pub(super) async fn watch(
    session: Arc<Session>,
    cell: String,
    config: OpcUaConfig,
    active: usize,
    move_on: Arc<Notify>,
) {
    loop {
        tokio::time::sleep(WATCH_EVERY).await;
        let Some(now) = level(&session).await else {
            // No answer: the session's own supervision says whether the
            // connection is lost.
            continue;
        };
        if now >= HEALTHY {
            continue;
        }
        let all = levels(&cell, &config).await;
        let better = all
            .iter()
            .enumerate()
            .any(|(i, l)| i != active && l.is_some_and(|l| l > now));
        if better {
            tracing::warn!(
                server = %config.servers()[active],
                service_level = now,
                "OPC UA server degraded: moving to the best of its redundant set"
            );
            move_on.notify_one();
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_highest_level_wins_ties_stay_and_silence_tries_the_next() {
        assert_eq!(choose(&[Some(255), Some(200)], 1), 0);
        assert_eq!(choose(&[Some(255), Some(255)], 1), 1);
        assert_eq!(choose(&[Some(50), None, Some(210)], 0), 2);
        assert_eq!(choose(&[None, None], 0), 1);
        assert_eq!(choose(&[None, None], 1), 0);
        assert_eq!(choose(&[Some(0), None], 1), 0);
    }

    #[test]
    fn a_level_is_a_good_byte() {
        assert_eq!(level_of(Some(DataValue::new_now(230u8))), Some(230));
        assert_eq!(level_of(Some(DataValue::new_now(230u16))), None);
        assert_eq!(level_of(None), None);
    }
}
