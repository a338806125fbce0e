//! What the plant run's rooms share: its setup, a cell, a process of its
//! own, the bounds of its waits.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::{Child, Command};
use std::time::Duration;

use crate::alarms::Generator;
use crate::cell::Load;
use crate::load::LoadServer;

/// How a plant run is set up.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The `cellwatch` binary.
    pub agent: PathBuf,
    /// The plant's folder and everything the run writes.
    pub workdir: PathBuf,
    /// Simulated cells.
    pub cells: usize,
    /// Routers.
    pub routers: usize,
    /// Each cell's noise load.
    pub load: Load,
    /// How long the whole plant is measured.
    pub seconds: Duration,
    /// A limit switch opens this often in each cell, held half as long.
    pub fault_every: Duration,
    /// Prometheus, if installed.
    pub prometheus: Option<PathBuf>,
}

/// Cells per area of the inventory.
pub(super) const CELLS_PER_AREA: usize = 10;

/// How long the lone agent is measured.
pub(super) const ALONE: Duration = Duration::from_secs(60);

/// How long the plant is given to be whole again after a router is killed.
pub(super) const BACK_WITHIN: Duration = Duration::from_secs(120);

/// One cell: its server, its agent, its faults.
pub(super) struct Cell {
    pub(super) id: String,
    pub(super) server: LoadServer,
    pub(super) metrics: SocketAddr,
    /// Its configuration as deployed, the plant's paths made this host's.
    pub(super) config: PathBuf,
    pub(super) agent: Option<Process>,
    pub(super) generator: Option<Generator>,
}

impl Cell {
    pub(super) fn generator_faults(&self) -> usize {
        self.generator.as_ref().map_or(0, Generator::faults)
    }
}

/// A child process killed when dropped (a run that fails leaves nothing).
pub(super) struct Process {
    pub(super) name: String,
    pub(super) child: Child,
}

impl Process {
    pub(super) fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Stops it as a service manager would (SIGTERM), and waits.
    pub(super) fn stop(mut self) {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.pid().to_string())
            .status();
        let _ = self.child.wait();
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

impl std::fmt::Debug for Process {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({})", self.name, self.child.id())
    }
}
