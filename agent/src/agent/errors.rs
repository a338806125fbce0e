//! Why an agent cannot start, cannot go on, or cannot take a
//! configuration read again.

use std::net::SocketAddr;

use crate::bus::envelope::KeyFileError;
use crate::bus::ZenohError;
use crate::cell::compile::CompileError;
use crate::journal::JournalError;
use crate::operator::KeysError;
use crate::sources::SourceError;

/// Why an agent cannot start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// The checks do not fit the cell.
    #[error(transparent)]
    Compile(#[from] CompileError),
    /// The operator secrets file is unusable.
    #[error(transparent)]
    Keys(#[from] KeysError),
    /// The journal cannot be opened.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// Zenoh refused the session or a declaration.
    #[error(transparent)]
    Zenoh(#[from] ZenohError),
    /// The agent's signing key, or a private key it uses, is unusable
    /// (unreadable, not a key, or readable by others).
    #[error(transparent)]
    Key(#[from] KeyFileError),
    /// The metrics port cannot be bound.
    #[error("cannot serve metrics on {addr}: {source}")]
    Metrics {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The Alertmanager's TLS files are unusable.
    #[error(transparent)]
    Alertmanager(#[from] crate::sinks::alertmanager::TlsError),
    /// The Sparkplug edge node's TLS or password files are unusable.
    #[error(transparent)]
    Sparkplug(#[from] crate::sinks::sparkplug::SparkplugError),
    /// The alarm server cannot start (its users file, address or PKI).
    #[error(transparent)]
    AlarmServer(#[from] crate::services::alarm_server::AlarmServerError),
    /// The cell loop's thread cannot be started.
    #[error("cannot start the cell loop's thread: {0}")]
    Loop(std::io::Error),
}

impl StartError {
    /// Whether the configuration (or a file it names) is at fault, rather
    /// than the machine.
    pub fn is_input(&self) -> bool {
        matches!(
            self,
            StartError::Compile(_)
                | StartError::Alertmanager(_)
                | StartError::Sparkplug(_)
                | StartError::AlarmServer(crate::services::alarm_server::AlarmServerError::Users(
                    _
                ))
                | StartError::Keys(_)
                | StartError::Key(_)
                | StartError::Zenoh(ZenohError::Insecure { .. } | ZenohError::Key(_))
        )
    }
}

/// Why an agent could not go on by itself ([`Agent::wait`]).
#[derive(Debug, thiserror::Error)]
pub enum Ended {
    /// Its source could not run.
    #[error("the source cannot run: {0}")]
    Source(SourceError),
    /// Its source ended.
    #[error("the source stopped")]
    SourceStopped,
    /// Its cell loop panicked (the panic's message); the loop closed its
    /// sinks first.
    #[error("the cell loop panicked: {0}")]
    LoopPanicked(String),
    /// Its cell loop ended without being told to.
    #[error("the cell loop stopped")]
    LoopStopped,
}

/// Why a configuration read again was not taken.
#[derive(Debug, thiserror::Error)]
pub enum ReloadError {
    /// Its checks do not compile: the running configuration goes on.
    #[error(transparent)]
    Compile(#[from] CompileError),
    /// It changes what only a restart changes, and nothing else could be
    /// taken without it (the tags: the checks are compiled against them).
    #[error(
        "{0} changed: restart the agent to take the new configuration (the running one goes on)"
    )]
    Restart(String),
    /// The loop has ended.
    #[error("{0}")]
    Refused(String),
    /// The loop would not take it now.
    #[error(transparent)]
    Busy(#[from] crate::cell::swap::ReloadBusy),
    /// The operators file or the alarm server's users file it names is
    /// unusable.
    #[error("{0}")]
    File(String),
}
