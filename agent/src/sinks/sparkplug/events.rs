//! What the Sparkplug edge node says and counts: one type per event, whose
//! `emit` writes its log line and bumps its metric together
//! (`cellwatch_sparkplug_*`, registered in `metrics/sparkplug.rs`).

use super::host::HostSaid;
use crate::metrics::SparkplugMetrics;

/// Something the edge node did or met.
#[derive(Debug)]
pub(super) enum SparkplugEvent<'a> {
    /// The broker took the node's session (`bd_seq` its birth/death
    /// sequence number).
    Connected {
        /// The broker, `host:port`.
        broker: &'a str,
        /// The session's bdSeq.
        bd_seq: u64,
    },
    /// The session was lost or could not be made.
    Disconnected {
        /// The broker, `host:port`.
        broker: &'a str,
        /// Why.
        why: &'a str,
        /// Attempts that failed in a row since the node was last connected
        /// (or started), this one included.
        failures: u32,
    },
    /// A message was handed to the session.
    Published {
        /// Its kind (`nbirth`, `dbirth`, `ddata`, `ddeath`, `ndeath`).
        kind: &'static str,
    },
    /// A message could not be handed to the session.
    Failed {
        /// Its kind.
        kind: &'static str,
        /// Why.
        why: &'a str,
    },
    /// The node and its device are born again.
    Rebirth {
        /// What asked for it.
        why: &'static str,
    },
    /// An NCMD or DCMD that is not acted on.
    CommandIgnored {
        /// Its topic.
        topic: &'a str,
    },
    /// Held changes were dropped past `sparkplug.max_held`.
    Dropped {
        /// How many.
        count: u64,
    },
    /// The primary host application's `STATE` was heard.
    PrimaryHost {
        /// Its id.
        host: &'a str,
        /// What it means: online, offline, or stale (ignored).
        heard: HostSaid,
    },
    /// The primary host went offline during the node's Sparkplug session:
    /// the node said its NDEATH and disconnects.
    HostOffline {
        /// The session's bdSeq.
        bd_seq: u64,
    },
    /// The cell's PLC link is down: the device dies (DDEATH at `seq`).
    DeviceDeath {
        /// The DDEATH's sequence number.
        seq: u64,
    },
    /// The store of held changes could not be written or read.
    StoreFailed {
        /// Why.
        why: &'a str,
    },
    /// Held changes read back from the store name metrics this run does
    /// not declare; they are dropped.
    Undeclared {
        /// How many.
        count: u64,
    },
}

impl SparkplugEvent<'_> {
    /// Logs the event and counts it.
    pub(super) fn emit(self, metrics: &SparkplugMetrics) {
        match self {
            SparkplugEvent::Connected { broker, bd_seq } => {
                metrics.connected.set(1);
                metrics.sessions.inc();
                tracing::info!(broker, bd_seq, "sparkplug: connected to the MQTT broker");
            }
            SparkplugEvent::Disconnected {
                broker,
                why,
                failures,
            } => {
                if metrics.connected.get() == 1 {
                    tracing::warn!(broker, "sparkplug: MQTT session lost: {why}");
                } else if failures == 1 {
                    // Said once until it connects: a wrong certificate or
                    // password is seen at once, not every few seconds.
                    tracing::warn!(
                        broker,
                        "sparkplug: cannot connect to the MQTT broker: {why} (trying again, said once until it connects)"
                    );
                } else {
                    tracing::debug!(broker, failures, "sparkplug: cannot connect: {why}");
                }
                metrics.connected.set(0);
            }
            SparkplugEvent::Published { kind } => {
                metrics.message(kind, true);
                tracing::trace!(kind, "sparkplug: published");
            }
            SparkplugEvent::Failed { kind, why } => {
                metrics.message(kind, false);
                tracing::warn!(kind, "sparkplug: cannot publish: {why}");
            }
            SparkplugEvent::Rebirth { why } => {
                tracing::info!("sparkplug: rebirth ({why})");
            }
            SparkplugEvent::CommandIgnored { topic } => {
                metrics.commands_ignored.inc();
                tracing::info!(
                    topic,
                    "sparkplug: command not taken: commands travel on the signed bus"
                );
            }
            SparkplugEvent::Dropped { count } => {
                metrics.held_dropped.inc_by(count);
                tracing::warn!(
                    count,
                    "sparkplug: held changes dropped, the oldest, past sparkplug.max_held"
                );
            }
            SparkplugEvent::PrimaryHost { host, heard } => {
                metrics.host_state(heard.as_str());
                if heard == HostSaid::Stale {
                    tracing::info!(host, "sparkplug: primary host STATE older than the last one (or unreadable), ignored");
                } else {
                    tracing::info!(
                        host,
                        state = heard.as_str(),
                        "sparkplug: primary host state"
                    );
                }
            }
            SparkplugEvent::HostOffline { bd_seq } => {
                tracing::info!(
                    bd_seq,
                    "sparkplug: the primary host is offline: NDEATH, disconnecting to connect again"
                );
            }
            SparkplugEvent::DeviceDeath { seq } => {
                tracing::info!(
                    seq,
                    "sparkplug: the PLC link is down: DDEATH, DBIRTH when it is back"
                );
            }
            SparkplugEvent::StoreFailed { why } => {
                tracing::warn!("sparkplug: the store of held changes: {why}");
            }
            SparkplugEvent::Undeclared { count } => {
                metrics.held_dropped.inc_by(count);
                tracing::warn!(
                    count,
                    "sparkplug: held changes of metrics this run does not declare, dropped"
                );
            }
        }
    }
}
