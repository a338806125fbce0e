//! `cellwatch console`: the operators' web console for a whole plant.
//!
//! A process of its own that joins the bus like any other client, with its
//! own certificate, and believes only what the plant trust file verifies:
//! - [`plant`]: the cells and the alarms to show, kept from the agents'
//!   signed alarm events, states and snapshots;
//! - `listen`: the bus side — subscribers to every cell's alarms and state
//!   and to the agents' liveliness tokens, and each agent's snapshot when
//!   it (re)appears, when events were missed, and every minute;
//! - `http`: the pages (one HTML shell, one script, one style sheet, all
//!   in the binary), a live stream of changes (server-sent events), the
//!   agents' history and snapshots asked on the page's behalf, and
//!   operators' commands, signed in the browser, forwarded as they are.
//!
//! Nothing of the plant is served without a plant identity ([`access`]:
//! a client certificate from the plant CA, or an operator signed in with
//! their own key), and only the cells it may read; every request passes
//! the door's checks and bounds (`gate`).
//!
//! The console holds no operator key: it cannot act on its own, and its
//! own session sends nothing under a cell's prefix
//! ([`crate::bus::open_console`]). Its configuration: [`config`].

mod access;
mod api;
mod api_error;
pub mod config;
mod gate;
mod http;
mod listen;
pub(crate) mod plant;
mod shared;
mod web;

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};

use tokio::sync::broadcast;

use crate::bus::envelope::Trust;
use crate::client::BusClient;
use crate::operator::OperatorKeys;
pub use config::{ConsoleConfig, HttpTls};
use plant::Plant;
pub use shared::ConsoleError;
use shared::{Shared, CHANGES_QUEUED};

/// A running console.
pub struct Console {
    addr: SocketAddr,
    tls: bool,
    tasks: Vec<tokio::task::JoinHandle<()>>,
    stop: tokio::sync::watch::Sender<bool>,
}

impl Console {
    /// Starts the console: opens its bus session and serves its pages.
    ///
    /// # Errors
    /// A file it needs is wrong ([`ConsoleError::Input`]), or the bus or
    /// the address cannot be had.
    pub async fn start(cfg: &ConsoleConfig) -> Result<Console, ConsoleError> {
        if let Some(tls) = &cfg.bus.tls {
            crate::bus::envelope::check_private(&tls.key)
                .map_err(|e| ConsoleError::Input(format!("bus.tls: {e}")))?;
        }
        let trust = Trust::load(&cfg.trust).map_err(|e| ConsoleError::Input(e.to_string()))?;
        let session = crate::bus::open_console(&cfg.bus)
            .await
            .map_err(|e| ConsoleError::Runtime(e.to_string()))?;
        Console::start_on(cfg, session, trust).await
    }

    /// Starts the console on a session opened elsewhere (the demo's).
    ///
    /// # Errors
    /// As [`Console::start`].
    pub async fn start_on(
        cfg: &ConsoleConfig,
        session: zenoh::Session,
        trust: Trust,
    ) -> Result<Console, ConsoleError> {
        let operators = match &cfg.operators_file {
            Some(path) => OperatorKeys::load(path)
                .map_err(|e| ConsoleError::Input(e.to_string()))?
                .entries(),
            None => Vec::new(),
        };
        let (tls, certificate_names) = match &cfg.tls {
            Some(t) => {
                let (acceptor, names) = http::tls_acceptor(t)?;
                (Some(acceptor), names)
            }
            None => (None, Vec::new()),
        };
        let cells: std::collections::BTreeSet<String> = trust.cells().map(str::to_string).collect();
        let readers = access::Readers::resolve(cfg.readers.as_ref(), &cfg.areas, &cells)
            .map_err(|e| ConsoleError::Input(e.to_string()))?;
        let listener = tokio::net::TcpListener::bind(cfg.listen)
            .await
            .map_err(|e| ConsoleError::Runtime(format!("cannot listen on {}: {e}", cfg.listen)))?;
        let addr = listener
            .local_addr()
            .map_err(|e| ConsoleError::Runtime(e.to_string()))?;
        let plant = Plant::new(trust.cells(), &cfg.areas, cfg.max_alarms);
        let bus = BusClient::on(session, trust, &cfg.root);
        let (resync, resync_rx) = tokio::sync::mpsc::unbounded_channel();
        let shared = Arc::new(Shared {
            plant: Mutex::new(plant),
            changes: broadcast::channel(CHANGES_QUEUED).0,
            bus,
            operators,
            resync,
            deployed: cfg.deployed.clone(),
        });
        let (stop, stopped) = tokio::sync::watch::channel(false);
        let mut tasks = listen::start(shared.clone(), &cfg.root, resync_rx)
            .await
            .map_err(|e| ConsoleError::Runtime(e.to_string()))?;
        let gate = Arc::new(gate::Gate::new(
            gate::names_of(addr, &certificate_names, &cfg.names),
            readers,
            access::Sessions::new(cfg.session),
            cells.iter().map(String::as_str),
        ));
        let secure = tls.is_some();
        tasks.push(tokio::spawn(http::serve(
            listener, tls, shared, gate, stopped,
        )));
        tracing::info!(%addr, tls = secure, "console serving");
        Ok(Console {
            addr,
            tls: secure,
            tasks,
            stop,
        })
    }

    /// The address it serves on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Its URL (`https://…` unless plain HTTP).
    pub fn url(&self) -> String {
        let scheme = if self.tls { "https" } else { "http" };
        let host = if self.addr.ip().is_unspecified() {
            "127.0.0.1".to_string()
        } else {
            self.addr.ip().to_string()
        };
        format!("{scheme}://{host}:{}/", self.addr.port())
    }

    /// Stops serving and leaves the bus.
    pub async fn stop(self) {
        let _ = self.stop.send(true);
        for t in self.tasks {
            t.abort();
            let _ = t.await;
        }
    }
}
