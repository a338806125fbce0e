//! One module per command; each takes its parsed arguments and the output
//! streams, and returns [`Failure`] on error. `bus/` is the bus client (every
//! command that talks to agents over Zenoh).

pub(crate) mod agent;
pub(crate) mod archive;
pub(crate) mod audit;
pub(crate) mod bus;
pub(crate) mod console;
#[cfg(feature = "simulators")]
pub(crate) mod demo;
pub(crate) mod discover;
pub(crate) mod explain;
pub(crate) mod hash_password;
pub(crate) mod inputs;
pub(crate) mod journal;
pub(crate) mod keygen;
pub(crate) mod mad;

pub(crate) mod man;
pub(crate) mod pki;
pub(crate) mod plant;
pub(crate) mod report;
pub(crate) mod router;
pub(crate) mod sf;
pub(crate) mod sfc;
pub(crate) mod signals;
#[cfg(feature = "simulators")]
pub(crate) mod simulate;
pub(crate) mod systemd;
pub(crate) mod timers;
pub(crate) mod trust_server;

/// Why a command failed. Each error is sorted into one of the two by the
/// code that knows what failed; there is no blanket conversion.
#[derive(Debug)]
pub(crate) enum Failure {
    /// The user's input is wrong: exit status 2.
    Input(String),
    /// Something failed while running: exit status 1.
    Runtime(String),
}

impl Failure {
    /// Bad input: a file, flag or value the user gave.
    pub(crate) fn input(e: impl std::fmt::Display) -> Failure {
        Failure::Input(e.to_string())
    }

    /// A failure while running.
    pub(crate) fn runtime(e: impl std::fmt::Display) -> Failure {
        Failure::Runtime(e.to_string())
    }

    /// Writing the command's output failed (a closed pipe, a full disk).
    pub(crate) fn output(e: std::io::Error) -> Failure {
        Failure::Runtime(format!("cannot write output: {e}"))
    }
}
