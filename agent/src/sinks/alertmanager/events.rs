//! What the Alertmanager sink and its pusher say and count: one type per
//! event, whose `emit` writes its log line and sets its metrics together
//! (`cellwatch_alertmanager_*`).

use crate::metrics::Metrics;

/// Something the sink or the pusher did or met.
#[derive(Debug)]
pub(super) enum AlertmanagerEvent<'a> {
    /// A step changed the book of alerts.
    Booked {
        /// Alarms that are active alerts now.
        active: usize,
        /// Alert changes not yet accepted by every Alertmanager.
        unsent: usize,
    },
    /// An Alertmanager accepted a batch.
    Sent {
        /// Alert changes not yet accepted by every Alertmanager, after it.
        unsent: usize,
    },
    /// A batch did not reach an Alertmanager; it is sent again.
    SendFailed {
        /// The Alertmanager.
        url: &'a str,
        /// Why.
        why: &'a str,
    },
}

impl AlertmanagerEvent<'_> {
    /// Logs the event and counts it.
    pub(super) fn emit(self, metrics: &Metrics) {
        match self {
            AlertmanagerEvent::Booked { active, unsent } => {
                metrics.alertmanager_alerts.set(active as i64);
                metrics.alertmanager_unsent.set(unsent as i64);
            }
            AlertmanagerEvent::Sent { unsent } => {
                metrics.alertmanager_sent(true);
                metrics.alertmanager_unsent.set(unsent as i64);
            }
            AlertmanagerEvent::SendFailed { url, why } => {
                metrics.alertmanager_sent(false);
                tracing::warn!(alertmanager = %url, %why, "cannot send alerts; retrying");
            }
        }
    }
}
