//! The simulated body-shop line (paper 001), served live over OPC UA.
//!
//! The same deterministic simulator that writes run logs
//! ([`cellwatch_models::timer::line`]) drives live tags here: a run's
//! changes are played in wall-clock time into a simulated PLC, changes of
//! one instant written together with one source timestamp. When a run ends
//! the next seed follows. A fault can be injected in the first run.

use std::net::SocketAddr;
use std::time::Duration;

use cellwatch_models::timer::line::{self, Fault};

use super::server::{SimOptions, SimServer};
use super::SimError;

/// Cycles per station in one played run (about 6 hours of line time).
const CYCLES: usize = 500;

/// A running simulated line.
#[derive(Clone)]
pub struct SimulatedLine {
    server: SimServer,
}

impl SimulatedLine {
    /// Serves the line's 94 signals, at their initial values.
    ///
    /// # Errors
    /// The port cannot be bound or the server cannot be built.
    pub async fn start(options: &SimOptions) -> Result<SimulatedLine, SimError> {
        let (run, _) = line::run(1, 1, None);
        let variables: Vec<(String, bool)> = run
            .signals
            .iter()
            .cloned()
            .zip(run.initial.iter().copied())
            .collect();
        let server = SimServer::start(
            options,
            "line",
            "cellwatch simulated body-shop line",
            &variables,
        )
        .await?;
        Ok(SimulatedLine { server })
    }

    /// The endpoint URL clients connect to.
    pub fn endpoint(&self) -> String {
        self.server.endpoint()
    }

    /// The address the server listens on.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr()
    }

    /// The namespace index of the tags.
    pub fn namespace(&self) -> u16 {
        self.server.namespace()
    }

    /// Plays runs from `seed` on, forever; `fault` is injected in the first
    /// run and announced through `note` when its motion is commanded.
    pub async fn play(&self, seed: u64, fault: Option<Fault>, note: impl Fn(String)) {
        let mut seed = seed;
        let mut fault = fault;
        loop {
            let (run, injected) = line::run(seed, CYCLES, fault.take());
            let start = tokio::time::Instant::now();
            let start_wall = chrono::Utc::now();
            let initial: Vec<(String, bool)> = run
                .signals
                .iter()
                .cloned()
                .zip(run.initial.iter().copied())
                .collect();
            if let Err(e) = self.server.set(&initial) {
                tracing::error!(error = %e, "simulated line");
            }
            let mut announced = injected.is_none();
            let mut i = 0;
            while i < run.changes.len() {
                let at = run.changes[i].at;
                if !announced {
                    if let Some(f) = &injected {
                        if at >= f.command_at {
                            note(format!("{:?} motion injected: the motion ending at {} (commanded at {} ms)", f.kind, f.sensor, f.command_at));
                            announced = true;
                        }
                    }
                }
                tokio::time::sleep_until(start + Duration::from_millis(at)).await;
                let mut batch = Vec::new();
                while i < run.changes.len() && run.changes[i].at == at {
                    let c = run.changes[i];
                    batch.push((run.signals[c.signal].clone(), c.value));
                    i += 1;
                }
                // Stamped with when it happened, however late the scheduler
                // wakes this task.
                let happened = start_wall + chrono::Duration::milliseconds(at as i64);
                if let Err(e) = self.server.set_at(&batch, happened.into()) {
                    tracing::error!(error = %e, "simulated line");
                }
            }
            seed += 1;
        }
    }

    /// Stops the server.
    pub fn stop(&self) {
        self.server.stop();
    }
}
