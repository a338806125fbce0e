//! What the console's parts share: the plant behind its lock, the channel
//! of changes the pages follow (each with the cell it concerns, so a page
//! is sent only its reader's cells), the bus client, the operators'
//! public permissions, and the cells to snapshot again.

use std::sync::{Arc, Mutex};

use tokio::sync::broadcast;

use super::access::Scope;
use super::plant::{Change, Plant};
use crate::client::BusClient;

/// Why the console could not start.
#[derive(Debug, thiserror::Error)]
pub enum ConsoleError {
    /// A file it needs is missing or wrong (the trust file, the operators
    /// file, the HTTPS certificate).
    #[error("{0}")]
    Input(String),
    /// The bus or the listening socket could not be had.
    #[error("{0}")]
    Runtime(String),
}

/// How many changes a page may fall behind before it is sent everything
/// again.
pub(super) const CHANGES_QUEUED: usize = 4096;

/// What every part of the console shares.
pub(super) struct Shared {
    pub(super) plant: Mutex<Plant>,
    pub(super) changes: broadcast::Sender<Arc<Routed>>,
    pub(super) bus: BusClient,
    /// The operators (name, public key, actions), for the page to offer
    /// only what each may do.
    pub(super) operators: Vec<(String, String, Vec<crate::operator::Action>)>,
    /// Cells to snapshot again.
    pub(super) resync: tokio::sync::mpsc::UnboundedSender<String>,
    /// The file of what the plant deployed (`plant.deployed`), read each
    /// time the Agents page asks.
    pub(super) deployed: Option<std::path::PathBuf>,
}

impl Shared {
    /// Applies a change to the plant and tells the pages, under one lock,
    /// so that a page that starts sees each change once: in its first
    /// view or after it.
    pub(super) fn change(&self, apply: impl FnOnce(&mut Plant) -> Vec<Change>) {
        let Ok(mut plant) = self.plant.lock() else {
            return;
        };
        for change in apply(&mut plant) {
            let cell = match &change {
                Change::Alarm { alarm } => alarm.cell.clone(),
                Change::Cell { cell } => cell.cell.clone(),
            };
            if let Ok(json) = serde_json::to_string(&change) {
                let _ = self.changes.send(Arc::new(Routed { cell, json }));
            }
        }
    }

    /// Everything `scope` may read now, and the changes after it.
    pub(super) fn view(&self, scope: &Scope) -> (String, broadcast::Receiver<Arc<Routed>>) {
        let Ok(plant) = self.plant.lock() else {
            return (String::from("{}"), self.changes.subscribe());
        };
        let mut view = plant.view();
        view.cells.retain(|c| scope.covers(&c.cell));
        view.alarms.retain(|a| scope.covers(&a.cell));
        let areas: std::collections::BTreeSet<&str> = view
            .cells
            .iter()
            .filter_map(|c| c.area.as_deref())
            .collect();
        view.areas.retain(|a| areas.contains(a));
        let view = serde_json::to_string(&view).unwrap_or_default();
        (view, self.changes.subscribe())
    }
}

/// A change as the pages are sent it, with the cell it concerns.
pub(super) struct Routed {
    /// The cell.
    pub(super) cell: String,
    /// The change, JSON.
    pub(super) json: String,
}
