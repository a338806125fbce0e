//! What the Sparkplug edge node says and counts: one type per event, whose
//! `emit` writes its log line and bumps its metric together
//! (`cellwatch_sparkplug_*`, registered in `metrics/sparkplug.rs`).

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
    },
    /// A message was handed to the session.
    Published {
        /// Its kind (`nbirth`, `dbirth`, `ddata`, `ndeath`).
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
    /// The primary host application came online or went offline.
    PrimaryHost {
        /// Its id.
        host: &'a str,
        /// Whether it is online.
        online: bool,
    },
}

impl SparkplugEvent<'_> {
    /// Logs the event and counts it.
    pub(super) fn emit(self, metrics: &SparkplugMetrics) {
        match self {
            SparkplugEvent::Connected { broker, bd_seq } => {
                metrics.connected.set(1);
                tracing::info!(broker, bd_seq, "sparkplug: connected to the MQTT broker");
            }
            SparkplugEvent::Disconnected { broker, why } => {
                if metrics.connected.get() == 1 {
                    tracing::warn!(broker, "sparkplug: MQTT session lost: {why}");
                } else {
                    tracing::debug!(broker, "sparkplug: cannot connect: {why}");
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
                    "sparkplug: held changes dropped past sparkplug.max_held"
                );
            }
            SparkplugEvent::PrimaryHost { host, online } => {
                tracing::info!(host, online, "sparkplug: primary host state");
            }
        }
    }
}
