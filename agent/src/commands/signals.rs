//! The signals that stop a command cleanly: Ctrl-C (SIGINT) and SIGTERM
//! (what systemd, Docker and Kubernetes send).

use super::Failure;

/// The signals that stop a command cleanly: Ctrl-C (SIGINT) and SIGTERM
/// (what systemd, Docker and Kubernetes send). Listened to from the moment
/// they are made, so that one sent while the agent starts is not lost.
pub(crate) struct StopSignals {
    interrupt: tokio::signal::unix::Signal,
    terminate: tokio::signal::unix::Signal,
}

impl StopSignals {
    /// Starts listening (the signals no longer end the process by
    /// themselves).
    ///
    /// # Errors
    /// The system refuses the handlers.
    pub(crate) fn listen() -> Result<StopSignals, Failure> {
        use tokio::signal::unix::{signal, SignalKind};
        let listen = |kind| {
            signal(kind)
                .map_err(|e| Failure::Runtime(format!("cannot listen for stop signals: {e}")))
        };
        Ok(StopSignals {
            interrupt: listen(SignalKind::interrupt())?,
            terminate: listen(SignalKind::terminate())?,
        })
    }

    /// The next stop signal, by name.
    pub(crate) async fn recv(&mut self) -> &'static str {
        tokio::select! {
            _ = self.interrupt.recv() => "SIGINT",
            _ = self.terminate.recv() => "SIGTERM",
        }
    }
}

/// SIGHUP: read the configuration again (`cellwatch run`; systemd's
/// `systemctl reload`). Listened to from the moment it is made: a SIGHUP no
/// longer ends the process.
pub(crate) struct Hangups(tokio::signal::unix::Signal);

impl Hangups {
    /// Starts listening.
    ///
    /// # Errors
    /// The system refuses the handler.
    pub(crate) fn listen() -> Result<Hangups, Failure> {
        use tokio::signal::unix::{signal, SignalKind};
        signal(SignalKind::hangup())
            .map(Hangups)
            .map_err(|e| Failure::Runtime(format!("cannot listen for SIGHUP: {e}")))
    }

    /// The next SIGHUP.
    pub(crate) async fn recv(&mut self) {
        let _ = self.0.recv().await;
    }
}

/// The next Ctrl-C or SIGTERM, by name (Ctrl-C only where the handlers
/// cannot be set).
pub(crate) async fn stop_requested() -> &'static str {
    match StopSignals::listen() {
        Ok(mut signals) => signals.recv().await,
        Err(_) => {
            let _ = tokio::signal::ctrl_c().await;
            "SIGINT"
        }
    }
}
