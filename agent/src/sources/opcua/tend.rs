//! The monitored items of a subscription in place, tended without a
//! reconnect: failed ones (`items`) are created again when due, and every
//! `opcua.verify_interval` all of them are checked against what the
//! server's nodes hold (`Read`, a chunk at a time):
//!
//! - a node the server no longer has (`BadNodeIdUnknown`) while its item
//!   said nothing: its tags are bad, and the item is created again with
//!   backoff until the node is back;
//! - a node that holds another value than its item last said, and whose
//!   item then says nothing for a few publishing and sampling intervals:
//!   the item is deaf (the server deleted the node and added it again and
//!   told the old item nothing). What it missed is a gap, said before the
//!   item is created again; the new one says the node's value.
//!
//! A value within an item's absolute deadband of what it last said is no
//! change (the server rightly reports none); an item with a percent
//! deadband (of a range the server holds) is checked for its node only.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use opcua::client::Session;
use opcua::client::{services::DeleteMonitoredItems, UARequest};
use opcua::types::{ReadValueId, StatusCode, TimestampsToReturn};

use super::delivery::Shared;
use super::items::{is_gone, print};
use super::requests::Requests;
use super::subscription::{bad, create, Heard, Monitored, Uses, MAX_ITEMS_PER_CALL, READ_CHUNK};
use crate::sources::opcua::config::OpcUaConfig;
use crate::sources::{SourceEvent, SourceSender};
use crate::tags::Deadband;

/// Chunks read per turn of the supervisor: it fills gaps in between.
const CHUNKS_PER_TURN: usize = 10;

/// What the tending works on.
pub(super) struct Tended<'a> {
    pub(super) session: &'a Session,
    pub(super) sub: u32,
    pub(super) config: &'a OpcUaConfig,
    pub(super) uses: &'a Uses,
    pub(super) nodes: &'a Monitored,
    pub(super) shared: &'a Shared,
    pub(super) heard: &'a Heard,
    pub(super) tx: &'a SourceSender,
    /// Where the requests are counted.
    pub(super) requests: &'a Requests,
}

/// Where the verification stands.
pub(super) struct Tending {
    /// When the next round starts.
    next_round: Instant,
    /// The next node of a round under way.
    cursor: Option<usize>,
    /// Items whose node held another value than they said: each with how
    /// many times it had spoken then.
    suspects: Vec<(usize, u32)>,
    /// When the suspects are judged.
    judge_at: Option<Instant>,
    /// Nodes read per call: [`READ_CHUNK`], halved while the server says
    /// it is too many.
    chunk: usize,
    /// A failed read was said (once per subscription; then at debug).
    said: bool,
}

impl Tending {
    /// The first round one interval from now.
    pub(super) fn new(config: &OpcUaConfig) -> Tending {
        Tending {
            next_round: Instant::now() + config.verify_interval,
            cursor: None,
            suspects: Vec::new(),
            judge_at: None,
            chunk: READ_CHUNK,
            said: false,
        }
    }

    /// Does what is due: failed items created again, a turn of the
    /// verification, the suspects judged. When there is next something
    /// to do.
    pub(super) async fn tend(&mut self, t: &Tended<'_>) -> Instant {
        let now = Instant::now();
        renew_due(t, now).await;
        if self.judge_at.is_some_and(|at| at <= now) {
            self.judge(t).await;
        }
        // A status change named no item: a round now.
        if t.heard.doubted.swap(false, Ordering::Relaxed) {
            self.next_round = self.next_round.min(now);
        }
        // A round starts once the last one's suspects are judged.
        if self.cursor.is_none() && self.judge_at.is_none() && now >= self.next_round {
            self.cursor = Some(0);
            self.suspects.clear();
        }
        if let Some(from) = self.cursor {
            self.cursor = self.verify(t, from).await;
            if self.cursor.is_none() {
                self.next_round = Instant::now() + t.config.verify_interval;
                if !self.suspects.is_empty() {
                    self.judge_at = Some(Instant::now() + grace(t));
                }
            }
        }
        if self.cursor.is_some() {
            return Instant::now();
        }
        let items = t.shared.items.lock().unwrap_or_else(|e| e.into_inner());
        [Some(self.next_round), self.judge_at, items.next_due()]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(self.next_round)
    }

    /// Reads up to [`CHUNKS_PER_TURN`] chunks of nodes from `from`; where
    /// the round goes on, if it does.
    async fn verify(&mut self, t: &Tended<'_>, from: usize) -> Option<usize> {
        let chunk = self.chunk;
        let end = (from + chunk * CHUNKS_PER_TURN).min(t.nodes.len());
        for at in (from..end).step_by(chunk) {
            let part: Vec<_> = t.nodes.nodes(at..(at + chunk).min(end)).collect();
            let ids: Vec<ReadValueId> = part
                .iter()
                .map(|(_, n, _)| ReadValueId::from(n.clone()))
                .collect();
            let values = t.session.read(&ids, TimestampsToReturn::Neither, 0.0).await;
            t.requests.answered("Read", &values);
            let values = match values {
                Ok(values) => values,
                Err(e) if e.status() == StatusCode::BadTooManyOperations && chunk > 1 => {
                    // The server's `MaxNodesPerRead` is lower: on from here
                    // with half.
                    self.chunk = chunk / 2;
                    return Some(at);
                }
                Err(e) => {
                    // The session's keep-alive judges the connection; the
                    // next round tries again.
                    if std::mem::replace(&mut self.said, true) {
                        tracing::debug!(error = %e, "cannot verify the monitored items");
                    } else {
                        tracing::warn!(error = %e, "cannot read the monitored nodes back to verify their items: a node the server deletes and adds again without a word is not found until it can");
                    }
                    return None;
                }
            };
            let mut gone = Vec::new();
            {
                let mut items = t.shared.items.lock().unwrap_or_else(|e| e.into_inner());
                let now = Instant::now();
                for (v, (i, node, tags)) in values.iter().zip(&part) {
                    if items.is_failed(*i) {
                        continue;
                    }
                    if let Some(status) = v.status.filter(|s| is_gone(*s)) {
                        tracing::warn!(%node, %status, "a monitored node is gone and the server said nothing: its tags are bad until it is back");
                        items.fail(*i, status, now);
                        gone.extend(tags.iter().map(|&t| t as usize));
                        continue;
                    }
                    let deadband = match t.uses[tags[0] as usize].deadband {
                        None => None,
                        Some(Deadband::Absolute(d)) => Some(d),
                        // Its range is the server's: the node is checked,
                        // not its value.
                        Some(Deadband::Percent(_)) => continue,
                    };
                    let Some(said) = items.said(*i) else {
                        continue;
                    };
                    if print(v).differs(said.value, deadband) {
                        self.suspects.push((*i, said.spoke));
                    }
                }
            }
            if !gone.is_empty() {
                let _ = t.tx.send(bad(&gone)).await;
                t.shared.failed.notify_one();
            }
        }
        tracing::debug!(
            from,
            end,
            suspects = self.suspects.len(),
            "monitored items verified"
        );
        (end < t.nodes.len()).then_some(end)
    }

    /// The suspects that said nothing since they were read are deaf: said
    /// as a gap, and created again.
    async fn judge(&mut self, t: &Tended<'_>) {
        self.judge_at = None;
        let suspects = std::mem::take(&mut self.suspects);
        tracing::debug!(
            suspects = suspects.len(),
            "judging monitored items that said nothing"
        );
        if !t.shared.lock().flowing() || t.heard.silent_for().is_zero() {
            // Publishes are held back (a missing one being asked for, a
            // cell loop behind): silence proves nothing yet. Judged again
            // a grace later, when what was held has come (a missing
            // publish is asked for a few times at most, then given up).
            self.suspects = suspects;
            self.judge_at = Some(Instant::now() + grace(t));
            return;
        }
        let deaf: Vec<usize> = {
            let items = t.shared.items.lock().unwrap_or_else(|e| e.into_inner());
            suspects
                .into_iter()
                .filter(|&(i, spoke)| {
                    !items.is_failed(i) && items.said(i).is_some_and(|s| s.spoke == spoke)
                })
                .map(|(i, _)| i)
                .collect()
        };
        if deaf.is_empty() {
            return;
        }
        let mut tags = Vec::new();
        let mut names = Vec::new();
        for &i in &deaf {
            if let Some((node, of)) = t.nodes.node(i) {
                tracing::warn!(%node, "the node holds another value than its monitored item said, and the item says nothing: the server no longer tells it; created again");
                if names.len() < 5 {
                    names.push(node.to_string());
                }
                tags.extend(of.iter().map(|&t| t as usize));
            }
        }
        if deaf.len() > names.len() {
            names.push("...".into());
        }
        let _ = t
            .tx
            .send(SourceEvent::Gap {
                tags: Some(tags),
                values: 0,
                why: format!(
                    "the server stopped reporting {} to its monitored item{} (deleted and added again?): changes meanwhile may be lost",
                    names.join(", "),
                    if deaf.len() == 1 { "" } else { "s" }
                ),
            })
            .await;
        let now = Instant::now();
        {
            let mut items = t.shared.items.lock().unwrap_or_else(|e| e.into_inner());
            for i in deaf {
                items.renew(i, now);
            }
        }
        renew_due(t, now).await;
    }
}

/// How long an item that is heard has to say a change its node holds: the
/// slowest sampling, three publishing intervals, and a second for the
/// network.
fn grace(t: &Tended<'_>) -> Duration {
    t.uses.slowest(t.config.sampling_interval)
        + t.config.publishing_interval * 3
        + Duration::from_secs(1)
}

/// Creates again the failed items that are due; deletes the items they
/// replace. One refused again waits twice as long.
async fn renew_due(t: &Tended<'_>, now: Instant) {
    let due = t
        .shared
        .items
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .take_due(now);
    if due.is_empty() {
        return;
    }
    let part: Vec<_> = due
        .iter()
        .filter_map(|&(i, _)| t.nodes.node(i).map(|(id, tags)| (i, id, tags)))
        .collect();
    for chunk in part.chunks(MAX_ITEMS_PER_CALL) {
        let results = match create(t.session, t.sub, t.config, t.uses, chunk, t.requests).await {
            Ok(r) => r,
            Err(e) => {
                tracing::debug!(error = %e, "cannot create monitored items again: later");
                let mut items = t.shared.items.lock().unwrap_or_else(|e| e.into_inner());
                for (i, _, _) in chunk {
                    items.fail(*i, e.status(), Instant::now());
                }
                continue;
            }
        };
        let mut replaced = Vec::new();
        {
            let mut items = t.shared.items.lock().unwrap_or_else(|e| e.into_inner());
            let now = Instant::now();
            for (r, (i, node, _)) in results.iter().zip(chunk) {
                if r.status_code.is_good() {
                    tracing::info!(%node, "monitored again");
                    replaced.extend(items.created(*i, r.monitored_item_id));
                } else {
                    tracing::debug!(%node, status = %r.status_code, "monitored item refused again");
                    items.fail(*i, r.status_code, now);
                }
            }
        }
        if !replaced.is_empty() {
            // The old items, which may still be on the server: an error
            // (the server deleted them itself) changes nothing.
            let deleted = DeleteMonitoredItems::new(t.sub, t.session)
                .items_to_delete(replaced)
                .send(t.session.channel())
                .await;
            t.requests.answered("DeleteMonitoredItems", &deleted);
        }
    }
}
