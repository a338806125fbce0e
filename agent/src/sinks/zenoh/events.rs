//! What the Zenoh sink says and counts: one type per event, whose `emit`
//! writes its log line and bumps its metric together
//! (`cellwatch_zenoh_publish_errors_total`).

use crate::metrics::Metrics;

/// Something the sink met on the bus.
#[derive(Debug)]
pub(super) enum ZenohEvent<'a> {
    /// Zenoh refused an alarm's publisher: its events are not put.
    PublisherRefused {
        /// The alarm.
        alarm: &'a str,
        /// Why.
        error: &'a zenoh::Error,
    },
    /// A put failed.
    PutFailed {
        /// Its key.
        key: &'a str,
        /// What it carried: an alarm's id, `state`, or a recording's alarm.
        what: &'a str,
        /// Why.
        error: &'a zenoh::Error,
    },
    /// The liveliness token could not be undeclared when the sink closed
    /// (the session's end takes it away).
    TokenNotUndeclared {
        /// Why.
        error: &'a zenoh::Error,
    },
}

impl ZenohEvent<'_> {
    /// Logs the event and counts it.
    pub(super) fn emit(self, metrics: &Metrics) {
        match self {
            ZenohEvent::PublisherRefused { alarm, error } => {
                tracing::error!(alarm, error = %error, "cannot declare the alarm publisher");
                metrics.zenoh_publish_errors.inc();
            }
            ZenohEvent::PutFailed { key, what, error } => {
                tracing::error!(key, what, error = %error, "publication failed");
                metrics.zenoh_publish_errors.inc();
            }
            ZenohEvent::TokenNotUndeclared { error } => {
                tracing::warn!(error = %error, "cannot undeclare the liveliness token");
            }
        }
    }
}
