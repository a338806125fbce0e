//! What a reload hands the cell loop ([`Reload`]), shared by the loop
//! (`mod.rs`, which waits for one) and its taking over (`reload.rs`).

use std::time::Duration;

use cellwatch_models::engine::CellEngine;
use tokio::sync::{mpsc, oneshot};

use super::{forcing::Forcing, timers::Timers};
use crate::sources::{SourceEvent, WriteSender};

/// What takes over, and who hears that it has.
pub struct Reload {
    /// Built from the new configuration.
    pub engine: CellEngine,
    /// The new configuration's charts and switches.
    pub forcing: Forcing,
    /// Its timed transitions.
    pub timers: Timers,
    /// Its longest shelf.
    pub max_shelve: Duration,
    /// Its operators (`commands.operators_file`, read again).
    pub keys: crate::operator::OperatorKeys,
    /// The plant operators list they come from, if they do.
    pub keys_version: Option<u64>,
    /// A source of its own when the tags or the source's settings changed:
    /// the loop reads it from the new engine on, the old one is stopped
    /// by the agent afterwards.
    pub source: Option<NewSource>,
    /// Told once the new engine runs: the alarms it carried over; or why
    /// it was not taken.
    pub done: oneshot::Sender<Result<usize, ReloadBusy>>,
}

/// A source started for a reload, as the loop takes it.
pub struct NewSource {
    /// Its events.
    pub events: mpsc::Receiver<SourceEvent>,
    /// Where its writes go, if it can write.
    pub writer: Option<WriteSender>,
    /// Its delivery allowance (the publishing interval).
    pub allowance: Duration,
}

/// The next reload; pending forever once nobody can send one.
pub(super) async fn next(reloads: &mut Option<mpsc::Receiver<Reload>>) -> Reload {
    let Some(rx) = reloads else {
        return std::future::pending().await;
    };
    match rx.recv().await {
        Some(r) => r,
        None => {
            *reloads = None;
            std::future::pending().await
        }
    }
}

/// An operator's signed `configure` command asks for the configuration to
/// be read again: whoever runs the agent from its file (`cellwatch run`)
/// reads it and hands it over as on SIGHUP, and answers what came of it.
pub struct ReloadAsk {
    /// What came of it, for the operator and the journal: taken (and what
    /// only a restart changes), or why not.
    pub reply: oneshot::Sender<Result<String, NotReloaded>>,
}

/// Why the loop does not take a reload now: a forced transition or stop
/// is under way (its switch and target belong to the running charts).
#[derive(Debug, thiserror::Error)]
#[error("a forced transition or stop is under way: read the configuration again once it has ended")]
pub struct ReloadBusy;

/// Why a configuration read again at an operator's `configure reload` was
/// not taken, as the process that runs the agent said it (the file, and
/// what was wrong with it).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct NotReloaded(pub String);
