//! Simulated cells for the demo and the tests: served over real OPC UA
//! (the CNC, the line, the robot of paper 004), or polled over the `@` protocol (moulding units).

pub mod cnc;
pub mod line;
pub mod moulding;
pub mod robot;
pub mod server;

use std::net::SocketAddr;

use opcua::types::StatusCode;

/// Why a simulated cell cannot start or do what a test or the demo asks.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The port cannot be bound.
    #[error("cannot listen on {addr}: {source}")]
    Listen {
        /// The address asked for.
        addr: SocketAddr,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The bound socket has no address.
    #[error("cannot read the listening address: {0}")]
    LocalAddr(#[source] std::io::Error),
    /// The server's key pair cannot be made or is unusable.
    #[error(transparent)]
    Pki(#[from] crate::sources::pki::PkiError),
    /// The OPC UA stack refused to build the server.
    #[error("cannot build the simulated PLC: {0}")]
    Build(String),
    /// A part of the server it has just built is not there.
    #[error("{0} is missing")]
    Missing(&'static str),
    /// A lock was poisoned by a panic.
    #[error("simulator state poisoned")]
    Poisoned,
    /// The server refused to update a value.
    #[error("cannot update {what}: {status}")]
    Update {
        /// What was updated.
        what: String,
        /// The server's status.
        status: StatusCode,
    },
    /// The server has no decoy namespace.
    #[error("this server has no decoy namespace")]
    NoDecoy,
    /// No such variable.
    #[error("no variable {name}")]
    NoVariable {
        /// The name asked for.
        name: String,
    },
    /// A variable of that name exists.
    #[error("{name} exists already")]
    Exists {
        /// The name.
        name: String,
    },
    /// Not a PMC address (`X0.06`).
    #[error(transparent)]
    Address(#[from] cellwatch_models::signal::AddressError),
    /// An address that is not an input of the simulated CNC.
    #[error("{signal} is not an input of the simulated CNC")]
    NotInput {
        /// The address.
        signal: cellwatch_models::signal::Signal,
    },
    /// An address that is neither an input nor a register of the
    /// simulated CNC.
    #[error("{signal} is not a variable of the simulated CNC")]
    NotVariable {
        /// The address.
        signal: cellwatch_models::signal::Signal,
    },
    /// The robot's charts do not parse (each problem on its own line).
    #[error("{}", problems.join("\n"))]
    Charts {
        /// The problems, `file:line:col: message`.
        problems: Vec<String>,
    },
    /// A step name that is not `CHART.STEP`.
    #[error("'{name}' is not CHART.STEP")]
    NotStepName {
        /// The name given.
        name: String,
    },
    /// No chart of that name.
    #[error("no chart {chart}")]
    NoChart {
        /// The chart named.
        chart: String,
    },
    /// No step of that name.
    #[error("no step {name}")]
    NoStep {
        /// The step named (`CHART.STEP`).
        name: String,
    },
}
