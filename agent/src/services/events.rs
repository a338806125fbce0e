//! What the query services say and count: one type per event, whose
//! `emit` writes its log line and bumps its metric together
//! (`cellwatch_requests_refused_total`, `cellwatch_zenoh_publish_errors_total`).

use crate::metrics::Metrics;

/// Something a query service did or met.
#[derive(Debug)]
pub(super) enum ServiceEvent<'a> {
    /// A query was refused: counted, never logged (a client may send many).
    Refused {
        /// The service asked (`history`, `snapshot`, `command`, ...).
        service: &'a str,
        /// Why: one of [`crate::metrics::REFUSED`]'s reasons for it.
        reason: &'a str,
    },
    /// An answer could not be sent.
    ReplyFailed {
        /// Why.
        error: &'a zenoh::Error,
    },
}

impl ServiceEvent<'_> {
    /// Logs the event and counts it.
    pub(super) fn emit(self, metrics: &Metrics) {
        match self {
            ServiceEvent::Refused { service, reason } => metrics.refused(service, reason),
            ServiceEvent::ReplyFailed { error } => {
                tracing::warn!(error = %error, "reply failed");
                metrics.zenoh_publish_errors.inc();
            }
        }
    }
}
