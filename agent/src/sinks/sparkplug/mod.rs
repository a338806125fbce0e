//! The cell as a Sparkplug B edge node (`[sparkplug]`, off by default):
//! its machine state, alarms, parts produced, the current shift's OEE
//! (with `[oee]`) and exported tags as the metrics of one device under the
//! node, on an MQTT broker, for a plant's
//! unified namespace (Ignition, HiveMQ, EMQX and the historians that read
//! them).
//!
//! The sink ([`SparkplugSink`]) only writes each step's changes (and the
//! OEE figures the OEE sink, before it in the loop, computed on a tick)
//! into the shared [`book::MetricBook`] and wakes the session; it never waits for
//! the network. The session ([`session::Session`], a task of its own) owns
//! the MQTT client: the node's will (NDEATH with its bdSeq), the births
//! (NBIRTH, DBIRTH), the data (DDATA, sequence 0–255), the device's death
//! (DDEATH) while the cell's PLC link is down and its birth again when it
//! is back, a rebirth when a host asks
//! (NCMD `Node Control/Rebirth`) and, with a primary host, publishing only
//! while it says it is online; when it says offline, NDEATH and a new
//! connection. Changes that cannot be published are held on disk beside
//! the journal, bounded, and sent as history after the next birth, after a
//! restart too; bdSeq is kept there as well. Other commands from MQTT are
//! never taken: they travel on the signed bus.
//!
//! - `config.rs`: the `[sparkplug]` table, validated.
//! - `book.rs`: the metrics, their aliases and values, the held changes,
//!   the device alive or dead; `book/oee.rs`: the OEE metrics.
//! - `session.rs`: the MQTT session.
//! - `host.rs`: the primary host's `STATE`, judged by its timestamps.
//! - `store.rs`: the held changes and bdSeq on disk.
//! - `files.rs`: the password and TLS files, read (and checked).
//! - `value.rs`: a metric's value.
//! - `topics.rs`: the topics.
//! - `tahu/`: the Eclipse Tahu payload (generated from its `.proto`).
//! - `events.rs`: what it logs and counts.
//! - `shared.rs`: what the sink and the session share.

pub(crate) mod book;
pub mod config;
mod events;
mod files;
pub(crate) mod host;
pub(crate) mod session;
mod shared;
pub(crate) mod store;
pub(crate) mod tahu;
pub(crate) mod topics;
mod value;

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use tokio::sync::Notify;

use self::book::{declared, MetricBook};
use self::config::SparkplugConfig;
use self::events::SparkplugEvent;
pub(crate) use self::files::check;
use self::shared::Shared;
pub(crate) use self::shared::SparkplugError;
use self::store::{store_path, HeldStore};
use crate::metrics::Metrics;
use crate::sinks::Sink;
use crate::step::CellStep;
use crate::step::OeeWatch;

/// The sink for the cell loop.
pub(crate) struct SparkplugSink {
    shared: Arc<Shared>,
    metrics: Arc<Metrics>,
    /// The OEE sink's figures, read after each step it handled first.
    oee: Option<OeeWatch>,
}

/// What the edge node reads of its cell's configuration.
#[derive(Debug, Clone)]
pub struct SparkplugCell<'a> {
    /// The exported tags: index and name (device metrics).
    pub exported: Vec<(usize, String)>,
    /// Whether the cell counts parts.
    pub counts_parts: bool,
    /// The journal's file: the held changes are kept beside it.
    pub journal: &'a std::path::Path,
}

/// The sink for the cell loop and the session to run beside it; the
/// device declares the alarms of the engine's `catalogue` from the start,
/// and the OEE metrics when `oee` watches the OEE sink.
///
/// # Errors
/// A TLS or password file cannot be read or used, or the store of held
/// changes beside the journal cannot be opened.
pub(crate) fn start(
    cell: &SparkplugCell<'_>,
    config: &SparkplugConfig,
    catalogue: &[cellwatch_models::engine::CatalogueEntry],
    oee: Option<OeeWatch>,
    metrics: Arc<Metrics>,
) -> Result<(SparkplugSink, session::Session), SparkplugError> {
    let tags = &cell.exported;
    let counts_parts = cell.counts_parts;
    let (store, dropped) = HeldStore::open(&store_path(cell.journal), config.max_held)?;
    if dropped > 0 {
        SparkplugEvent::Dropped { count: dropped }.emit(&metrics.sparkplug);
    }
    let stored = store.rows();
    let shared = Arc::new(Shared {
        book: Mutex::new(MetricBook::new(
            &declared(catalogue),
            tags,
            counts_parts,
            oee.is_some(),
            config.max_held,
        )),
        store: Mutex::new(store),
        stored: AtomicUsize::new(stored),
        wake: Notify::new(),
        closed: AtomicBool::new(false),
    });
    metrics.sparkplug.held.set(stored as i64);
    let session = session::Session::new(config, shared.clone(), metrics.clone())?;
    Ok((
        SparkplugSink {
            shared,
            metrics,
            oee,
        },
        session,
    ))
}

impl Sink for SparkplugSink {
    fn name(&self) -> &'static str {
        "sparkplug"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        let (changed, dropped) = {
            let mut book = self.shared.book();
            let mut changed = book.apply(step);
            if let Some(oee) = self
                .oee
                .as_mut()
                .filter(|w| w.has_changed().unwrap_or(false))
            {
                if let Some(now) = &*oee.borrow_and_update() {
                    changed |= book.oee(now);
                }
            }
            (changed, book.take_dropped())
        };
        let held = self.shared.held();
        if changed {
            self.shared.wake.notify_one();
        }
        let m = &self.metrics.sparkplug;
        m.held.set(held as i64);
        if dropped > 0 {
            SparkplugEvent::Dropped { count: dropped }.emit(m);
        }
        async {}.boxed()
    }

    fn close(self: Box<Self>) -> BoxFuture<'static, ()> {
        self.shared.closed.store(true, Ordering::Release);
        self.shared.wake.notify_one();
        async {}.boxed()
    }
}
