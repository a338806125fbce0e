//! The metrics of the Sparkplug B edge node (`[sparkplug]`): messages
//! published and failed by kind, commands from MQTT not taken, changes
//! held while they cannot be published and those dropped past the bound,
//! whether the broker holds the node's session and how many it took, and
//! the primary host's `STATE` messages by what they meant. Registered by
//! [`super::Metrics::new`] for every cell (at 0 without `[sparkplug]`);
//! counted by the sink's events (`sinks/sparkplug/events.rs`).

use prometheus::{IntCounter, IntCounterVec, IntGauge, Registry};

use super::labels::opts;

/// The kinds of Sparkplug message the node publishes, as the `kind` label
/// says them.
pub const SPARKPLUG_KINDS: [&str; 5] = ["nbirth", "dbirth", "ddata", "ddeath", "ndeath"];

/// The Sparkplug edge node's figures.
#[derive(Clone)]
pub struct SparkplugMetrics {
    /// Messages by kind and result (`published`, `failed`).
    messages: IntCounterVec,
    /// NCMD and DCMD messages not acted on (only a rebirth is).
    pub commands_ignored: IntCounter,
    /// Changes waiting to be published.
    pub held: IntGauge,
    /// Changes dropped because more than `sparkplug.max_held` waited.
    pub held_dropped: IntCounter,
    /// 1 while the broker holds the node's session.
    pub connected: IntGauge,
    /// MQTT sessions the broker took.
    pub sessions: IntCounter,
    /// The primary host's `STATE` messages by what they meant.
    host_states: IntCounterVec,
}

impl SparkplugMetrics {
    /// Registers them for `cell` in `registry`.
    pub(super) fn register(registry: &Registry, cell: &str) -> SparkplugMetrics {
        let messages = IntCounterVec::new(
            opts(
                "cellwatch_sparkplug_messages_total",
                "Sparkplug B messages of the edge node by kind (nbirth, dbirth, ddata, ddeath, ndeath) and result (published: handed to the MQTT session; failed).",
                cell,
            ),
            &["kind", "result"],
        )
        .expect("valid metric");
        for kind in SPARKPLUG_KINDS {
            for result in ["published", "failed"] {
                messages.with_label_values(&[kind, result]).inc_by(0);
            }
        }
        let commands_ignored = IntCounter::with_opts(opts(
            "cellwatch_sparkplug_commands_ignored_total",
            "NCMD and DCMD messages the edge node did not act on: only Node Control/Rebirth is taken from MQTT (commands travel on the signed bus).",
            cell,
        ))
        .expect("valid metric");
        let held = IntGauge::with_opts(opts(
            "cellwatch_sparkplug_held",
            "Changes of the cell's Sparkplug metrics waiting to be published (while the broker or the primary host is away).",
            cell,
        ))
        .expect("valid metric");
        let held_dropped = IntCounter::with_opts(opts(
            "cellwatch_sparkplug_held_dropped_total",
            "Held changes dropped, the oldest first, because more than sparkplug.max_held waited (the next birth carries every current value).",
            cell,
        ))
        .expect("valid metric");
        let connected = IntGauge::with_opts(opts(
            "cellwatch_sparkplug_connected",
            "1 while the MQTT broker holds the Sparkplug edge node's session.",
            cell,
        ))
        .expect("valid metric");
        let sessions = IntCounter::with_opts(opts(
            "cellwatch_sparkplug_sessions_total",
            "MQTT sessions the broker took for the Sparkplug edge node (each with its own bdSeq).",
            cell,
        ))
        .expect("valid metric");
        let host_states = IntCounterVec::new(
            opts(
                "cellwatch_sparkplug_primary_host_states_total",
                "STATE messages of the primary host application by what they meant: online, offline, or stale (older than the last one, or unreadable: ignored).",
                cell,
            ),
            &["state"],
        )
        .expect("valid metric");
        for state in ["online", "offline", "stale"] {
            host_states.with_label_values(&[state]).inc_by(0);
        }
        registry
            .register(Box::new(messages.clone()))
            .expect("unique metric");
        registry
            .register(Box::new(sessions.clone()))
            .expect("unique metric");
        registry
            .register(Box::new(host_states.clone()))
            .expect("unique metric");
        registry
            .register(Box::new(commands_ignored.clone()))
            .expect("unique metric");
        for g in [&held, &connected] {
            registry
                .register(Box::new(g.clone()))
                .expect("unique metric");
        }
        registry
            .register(Box::new(held_dropped.clone()))
            .expect("unique metric");
        SparkplugMetrics {
            messages,
            commands_ignored,
            held,
            held_dropped,
            connected,
            sessions,
            host_states,
        }
    }

    /// The primary host's `STATE` was heard, meaning `state`.
    pub fn host_state(&self, state: &str) {
        self.host_states.with_label_values(&[state]).inc();
    }

    /// A message of `kind` was published (`ok`) or failed.
    pub fn message(&self, kind: &str, ok: bool) {
        self.messages
            .with_label_values(&[kind, if ok { "published" } else { "failed" }])
            .inc();
    }
}
